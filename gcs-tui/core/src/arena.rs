//! The arena: the `[arena]` section of the station's configuration (or the
//! file it names), checked with a message per mistake that says where it
//! is, and turned into the [`Arena`] message each robot's safety layer
//! enforces (`docs/safety.md`).
//!
//! ```toml
//! [arena]
//! boundary = [[0, 0], [3.9, 0], [3.9, 2.8], [0, 2.8]]   # m, map frame
//! keep_out = [[[1.8, 1.2], [2.1, 1.2], [2.1, 1.5], [1.8, 1.5]]]
//! slow_zones = [{ polygon = [[0, 0], [1, 0], [1, 1], [0, 1]], max_speed = 0.1 }]
//! margin = 0.1                                           # m
//! # or, instead of the above: file = "arena.toml" (same keys, top level)
//! ```

use std::ops::Range;
use std::path::{Path, PathBuf};

use mech_proto::{
    Arena, Body, MAX_BOUNDARY_VERTICES, MAX_KEEP_OUTS, MAX_POLYGON_VERTICES, MAX_SLOW_ZONES, Point,
    SlowZone, check_polygon,
};
use serde::Deserialize;
use toml::Spanned;

use crate::config::ConfigError;

/// A polygon as written: `[[x, y], ...]`, with where it was written.
pub type PolygonToml = Spanned<Vec<[f64; 2]>>;

/// One `slow_zones` entry.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SlowZoneToml {
    pub polygon: PolygonToml,
    /// m/s.
    pub max_speed: Spanned<f64>,
}

/// The `[arena]` section, or an arena file's top level.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ArenaConfig {
    /// Another TOML file holding the arena (relative to the configuration
    /// file); the section then holds nothing else.
    #[serde(default)]
    pub file: Option<PathBuf>,
    #[serde(default)]
    pub boundary: Option<PolygonToml>,
    #[serde(default)]
    pub keep_out: Vec<PolygonToml>,
    #[serde(default)]
    pub slow_zones: Vec<SlowZoneToml>,
    /// Clearance kept from every edge and between robots, m.
    #[serde(default = "default_margin")]
    pub margin: Spanned<f64>,
}

fn default_margin() -> Spanned<f64> {
    Spanned::new(0..0, DEFAULT_MARGIN)
}

/// Margin when none is written, m.
pub const DEFAULT_MARGIN: f64 = 0.1;

/// A mistake in an arena: what, where in the arena (`keep_out[2]`), and
/// where in the text when known.
#[derive(Debug, Clone, PartialEq)]
pub struct ArenaMistake {
    pub path: String,
    pub message: String,
    pub span: Option<Range<usize>>,
}

impl ArenaMistake {
    fn new(path: impl Into<String>, span: Range<usize>, message: impl Into<String>) -> Self {
        ArenaMistake {
            path: path.into(),
            message: message.into(),
            span: (!span.is_empty()).then_some(span),
        }
    }

    /// `file:line:column: arena.path: message`, the line and column found
    /// in `text` (the file the span refers to).
    pub fn locate(&self, file: &str, text: &str) -> String {
        match &self.span {
            Some(s) => {
                let (line, column) = line_column(text, s.start);
                format!("{file}:{line}:{column}: {}: {}", self.path, self.message)
            }
            None => format!("{file}: {}: {}", self.path, self.message),
        }
    }
}

/// 1-based line and column of byte `offset` in `text`.
fn line_column(text: &str, offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.matches('\n').count() + 1;
    let column = before
        .rfind('\n')
        .map_or(before.len(), |i| before.len() - i - 1)
        + 1;
    (line, column)
}

fn points(p: &[[f64; 2]]) -> Vec<Point> {
    p.iter().map(|&[x, y]| Point { x, y }).collect()
}

impl ArenaConfig {
    /// The demo simulator's arena (`mech-gcs --demo`): the 2017 lab's
    /// Pozyx area, 3.9 m x 2.8 m from the origin, the rectangle the
    /// simulated robots are spread over, with the default margin.
    pub fn demo() -> ArenaConfig {
        let corners = vec![[0.0, 0.0], [3.9, 0.0], [3.9, 2.8], [0.0, 2.8]];
        ArenaConfig {
            file: None,
            boundary: Some(Spanned::new(0..0, corners)),
            keep_out: vec![],
            slow_zones: vec![],
            margin: default_margin(),
        }
    }

    /// Parses an arena file (`boundary`, `keep_out`, `slow_zones`,
    /// `margin` at the top level) and checks it; errors say
    /// `file:line:column`.
    pub fn parse_file_text(text: &str, file: &str) -> Result<ArenaConfig, ConfigError> {
        let config: ArenaConfig = toml::from_str(text).map_err(|e| {
            let at = e.span().map_or(String::new(), |s| {
                let (line, column) = line_column(text, s.start);
                format!(":{line}:{column}")
            });
            ConfigError(format!("{file}{at}: {}", e.message().trim()))
        })?;
        if config.file.is_some() {
            return Err(ConfigError(format!(
                "{file}: an arena file cannot name another (`file`)"
            )));
        }
        config
            .validate()
            .map_err(|m| ConfigError(m.locate(file, text)))?;
        Ok(config)
    }

    /// The arena to use: this section, or the file it names read (relative
    /// to `base`, the configuration file's directory) and checked.
    pub fn resolve(&self, base: &Path) -> Result<ArenaConfig, ConfigError> {
        let Some(file) = &self.file else {
            return Ok(self.clone());
        };
        if self.boundary.is_some() || !self.keep_out.is_empty() || !self.slow_zones.is_empty() {
            return Err(ConfigError(
                "[arena]: give either `file` or the arena itself, not both".to_string(),
            ));
        }
        let path = base.join(file);
        let text = std::fs::read_to_string(&path)
            .map_err(|e| ConfigError(format!("[arena] file {}: {e}", path.display())))?;
        ArenaConfig::parse_file_text(&text, &path.display().to_string())
    }

    /// Checks every polygon (vertex count, finite numbers within range,
    /// crossing edges, area), the counts, the speeds and the margin.
    pub fn validate(&self) -> Result<(), ArenaMistake> {
        let margin = *self.margin.get_ref();
        if !(margin.is_finite() && (0.0..=10.0).contains(&margin)) {
            return Err(ArenaMistake::new(
                "arena.margin",
                self.margin.span(),
                format!("{margin} is not a margin in metres (0 to 10)"),
            ));
        }
        let polygon = |p: &PolygonToml, max: usize, path: String| {
            check_polygon(&points(p.get_ref()), max, "polygon")
                .map_err(|e| ArenaMistake::new(path, p.span(), plain(&e)))
        };
        match &self.boundary {
            Some(b) => polygon(b, MAX_BOUNDARY_VERTICES, "arena.boundary".into())?,
            None if self.file.is_none() => {
                return Err(ArenaMistake::new(
                    "arena.boundary",
                    0..0,
                    "missing: the polygon robots stay inside, [[x, y], ...] in metres",
                ));
            }
            None => {}
        }
        if self.keep_out.len() > MAX_KEEP_OUTS {
            let span = self.keep_out[MAX_KEEP_OUTS].span();
            return Err(ArenaMistake::new(
                "arena.keep_out",
                span,
                format!("at most {MAX_KEEP_OUTS} keep-outs"),
            ));
        }
        for (i, k) in self.keep_out.iter().enumerate() {
            polygon(k, MAX_POLYGON_VERTICES, format!("arena.keep_out[{i}]"))?;
        }
        if self.slow_zones.len() > MAX_SLOW_ZONES {
            return Err(ArenaMistake::new(
                "arena.slow_zones",
                self.slow_zones[MAX_SLOW_ZONES].polygon.span(),
                format!("at most {MAX_SLOW_ZONES} slow zones"),
            ));
        }
        for (i, z) in self.slow_zones.iter().enumerate() {
            polygon(
                &z.polygon,
                MAX_POLYGON_VERTICES,
                format!("arena.slow_zones[{i}].polygon"),
            )?;
            let v = *z.max_speed.get_ref();
            if !(v.is_finite() && v >= 0.0) {
                return Err(ArenaMistake::new(
                    format!("arena.slow_zones[{i}].max_speed"),
                    z.max_speed.span(),
                    format!("{v} is not a speed in m/s"),
                ));
            }
        }
        // Whatever else the protocol checks (it never sends what it would
        // refuse).
        Body::Arena(self.to_arena("robot", 1, true))
            .validate()
            .map_err(|e| ArenaMistake::new("arena", 0..0, plain(&e)))
    }

    /// The message for `robot`: this arena, its `id` (new for every change
    /// of the arena or of the robot's switch) and whether the robot's
    /// safety layer is on.
    pub fn to_arena(&self, robot: &str, id: u32, enabled: bool) -> Arena {
        Arena {
            robot: robot.to_string(),
            id,
            enabled,
            boundary: self
                .boundary
                .as_ref()
                .map_or_else(Vec::new, |b| points(b.get_ref())),
            keep_out: self.keep_out.iter().map(|k| points(k.get_ref())).collect(),
            slow_zones: self
                .slow_zones
                .iter()
                .map(|z| SlowZone {
                    polygon: points(z.polygon.get_ref()),
                    max_speed: *z.max_speed.get_ref(),
                })
                .collect(),
            margin: *self.margin.get_ref(),
        }
    }
}

/// A protocol error's text without its "invalid message: " prefix.
fn plain(e: &mech_proto::Error) -> String {
    match e {
        mech_proto::Error::Invalid(m) => m.clone(),
        other => other.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `[arena]` section in a station configuration, as the station
    /// reads it (other sections beside it).
    #[derive(Debug, Deserialize)]
    struct Station {
        arena: ArenaConfig,
    }

    fn section(text: &str) -> Result<ArenaConfig, String> {
        let s: Station = toml::from_str(text).map_err(|e| e.to_string())?;
        s.arena.validate().map_err(|m| m.locate("gcs.toml", text))?;
        Ok(s.arena)
    }

    #[test]
    fn a_section_becomes_the_message_robots_enforce() {
        let a = section(
            "[arena]\nboundary = [[0, 0], [4, 0], [4, 3], [0, 3]]\n\
             keep_out = [[[1, 1], [2, 1], [2, 2]]]\n\
             slow_zones = [{ polygon = [[3, 0], [4, 0], [4, 1], [3, 1]], max_speed = 0.1 }]\n\
             margin = 0.05\n",
        )
        .unwrap();
        let m = a.to_arena("robot_2", 7, true);
        assert_eq!(m.robot, "robot_2");
        assert_eq!((m.id, m.enabled, m.margin), (7, true, 0.05));
        assert_eq!(m.boundary.len(), 4);
        assert_eq!(m.keep_out[0][2], Point { x: 2.0, y: 2.0 });
        assert_eq!(m.slow_zones[0].max_speed, 0.1);
        assert!(Body::Arena(m).validate().is_ok());
    }

    #[test]
    fn each_mistake_says_what_and_where() {
        let e = section("[arena]\nboundary = [[0, 0], [4, 0], [4, 3], [0, 3]]\nkeep_out = [\n  [[1, 1], [2, 2], [2, 1], [1, 2]],\n]\n")
            .unwrap_err();
        assert!(e.starts_with("gcs.toml:4:3: arena.keep_out[0]:"), "{e}");
        assert!(e.contains("edges 0 and 2 cross"), "{e}");
        let e = section("[arena]\nboundary = [[0, 0], [4, 0]]\n").unwrap_err();
        assert!(e.starts_with("gcs.toml:2:12: arena.boundary:"), "{e}");
        assert!(e.contains("2 vertices, at least 3"), "{e}");
        let e = section("[arena]\nboundary = [[0, 0], [4, 0], [4, 3]]\nmargin = -1\n").unwrap_err();
        assert!(e.starts_with("gcs.toml:3:10: arena.margin:"), "{e}");
        let e = section("[arena]\nboundary = [[0, 0], [4, 0], [4, 3]]\nslow_zones = [{ polygon = [[0, 0], [1, 0], [1, 1]], max_speed = -0.1 }]\n").unwrap_err();
        assert!(e.contains("arena.slow_zones[0].max_speed"), "{e}");
        let e = section("[arena]\nmargin = 0.1\n").unwrap_err();
        assert!(e.contains("arena.boundary: missing"), "{e}");
        let e =
            section("[arena]\nboundary = [[0, 0], [4, 0], [4, 3]]\nmargins = 0.1\n").unwrap_err();
        assert!(e.contains("unknown field `margins`"), "{e}");
        let e = section("[arena]\nboundary = [[0, 0], [\"x\", 0], [4, 3]]\n").unwrap_err();
        assert!(e.contains("line 2"), "{e}");
    }

    #[test]
    fn the_demo_arena_is_the_simulators_rectangle() {
        let demo = ArenaConfig::demo();
        assert!(demo.validate().is_ok());
        let m = demo.to_arena("robot_1", 1, true);
        let xs: Vec<f64> = m.boundary.iter().map(|p| p.x).collect();
        let ys: Vec<f64> = m.boundary.iter().map(|p| p.y).collect();
        assert_eq!(xs.iter().cloned().fold(f64::MIN, f64::max), 3.9);
        assert_eq!(ys.iter().cloned().fold(f64::MIN, f64::max), 2.8);
        assert_eq!(m.margin, DEFAULT_MARGIN);
    }

    #[test]
    fn an_arena_can_live_in_a_file_of_its_own() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("arena.toml"),
            "boundary = [[0, 0], [5, 0], [5, 5], [0, 5]]\nmargin = 0.2\n",
        )
        .unwrap();
        let s: Station = toml::from_str("[arena]\nfile = \"arena.toml\"\n").unwrap();
        let a = s.arena.resolve(dir.path()).unwrap();
        assert_eq!(*a.margin.get_ref(), 0.2);
        assert_eq!(a.to_arena("r", 1, true).boundary.len(), 4);
        std::fs::write(dir.path().join("bad.toml"), "boundary = [[0, 0], [5, 0]]\n").unwrap();
        let s: Station = toml::from_str("[arena]\nfile = \"bad.toml\"\n").unwrap();
        let e = s.arena.resolve(dir.path()).unwrap_err().to_string();
        assert!(e.contains("bad.toml:1:12: arena.boundary"), "{e}");
        let s: Station = toml::from_str("[arena]\nfile = \"none.toml\"\n").unwrap();
        assert!(s.arena.resolve(dir.path()).is_err());
        let both: Station =
            toml::from_str("[arena]\nfile = \"arena.toml\"\nboundary = [[0, 0], [1, 0], [1, 1]]\n")
                .unwrap();
        assert!(both.arena.resolve(dir.path()).is_err());
    }
}
