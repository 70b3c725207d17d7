//! The arena: the `[arena]` section of the station's configuration (or the
//! file it names), checked with a message per mistake that says where it
//! is, the [`ArenaShape`] the station holds (and the map draws, and
//! recordings carry), and the [`Arena`] message each robot's safety layer
//! enforces (`docs/safety.md`).
//!
//! ```toml
//! [arena]
//! boundary = [[0, 0], [3.9, 0], [3.9, 2.8], [0, 2.8]]   # m, map frame
//! keep_out = [[[1.8, 1.2], [2.1, 1.2], [2.1, 1.5], [1.8, 1.5]]]
//! slow_zones = [{ polygon = [[0, 0], [1, 0], [1, 1], [0, 1]], max_speed = 0.1 }]
//! obstacles = [{ x = 3.0, y = 0.5, radius = 0.2 }]       # static discs
//! margin = 0.1                                           # m
//! # or, instead of the above: file = "arena.toml" (same keys, top level)
//! ```
//!
//! A leaf: it depends on the protocol and [`crate::config`] only, so the
//! station's events can carry an [`ArenaShape`].

use std::ops::Range;
use std::path::{Path, PathBuf};

use mech_proto::{
    Arena, Body, Disc, MAX_BOUNDARY_VERTICES, MAX_EXTENT, MAX_KEEP_OUTS, MAX_OBSTACLES,
    MAX_POLYGON_VERTICES, MAX_SLOW_ZONES, Obstacle, Point, SlowZone, check_polygon,
};
use serde::{Deserialize, Serialize};
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

/// One `obstacles` entry: a static disc robots keep clear of (a box put
/// down for an experiment), sent to them with their neighbours.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DiscToml {
    pub x: f64,
    pub y: f64,
    pub radius: f64,
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
    /// Static discs, m.
    #[serde(default)]
    pub obstacles: Vec<Spanned<DiscToml>>,
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
            obstacles: vec![],
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
        if self.boundary.is_some()
            || !self.keep_out.is_empty()
            || !self.slow_zones.is_empty()
            || !self.obstacles.is_empty()
        {
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
        self.validate_obstacles()?;
        // Whatever else the protocol checks (it never sends what it would
        // refuse).
        Body::Arena(self.to_arena("robot", 1, true))
            .validate()
            .map_err(|e| ArenaMistake::new("arena", 0..0, plain(&e)))
    }

    /// The obstacle discs: how many, and each placed and sized.
    fn validate_obstacles(&self) -> Result<(), ArenaMistake> {
        if self.obstacles.len() > MAX_OBSTACLES {
            return Err(ArenaMistake::new(
                "arena.obstacles",
                self.obstacles[MAX_OBSTACLES].span(),
                format!("at most {MAX_OBSTACLES} obstacles"),
            ));
        }
        for (i, o) in self.obstacles.iter().enumerate() {
            let d = o.get_ref();
            let placed = [d.x, d.y]
                .iter()
                .all(|v| v.is_finite() && v.abs() <= MAX_EXTENT);
            let sized = d.radius.is_finite() && (0.0..=MAX_EXTENT).contains(&d.radius);
            if !(placed && sized) {
                return Err(ArenaMistake::new(
                    format!("arena.obstacles[{i}]"),
                    o.span(),
                    "not a disc: x, y and a radius of 0 or more, in metres",
                ));
            }
        }
        Ok(())
    }

    /// The arena as the station holds it.
    pub fn shape(&self) -> ArenaShape {
        ArenaShape {
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
            obstacles: self
                .obstacles
                .iter()
                .map(|o| {
                    let d = o.get_ref();
                    Disc {
                        x: d.x,
                        y: d.y,
                        radius: d.radius,
                    }
                })
                .collect(),
            margin: *self.margin.get_ref(),
        }
    }

    /// The message for `robot`: this arena, its `id` (new for every change
    /// of the arena or of the robot's switch) and whether the robot's
    /// safety layer is on.
    pub fn to_arena(&self, robot: &str, id: u32, enabled: bool) -> Arena {
        self.shape().to_arena(robot, id, enabled)
    }
}

/// An arena as the station holds it, draws it on the map and records it:
/// polygons and discs in metres, map frame (checked when it was read).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ArenaShape {
    /// The polygon robots stay inside.
    pub boundary: Vec<Point>,
    /// Polygons robots stay out of.
    pub keep_out: Vec<Vec<Point>>,
    /// Polygons where robots go no faster than a cap.
    pub slow_zones: Vec<SlowZone>,
    /// Static discs robots keep clear of (sent with the neighbours).
    #[serde(default)]
    pub obstacles: Vec<Disc>,
    /// Clearance kept from every edge and between robots, m.
    pub margin: f64,
}

impl ArenaShape {
    /// The message for `robot` (see [`ArenaConfig::to_arena`]).
    pub fn to_arena(&self, robot: &str, id: u32, enabled: bool) -> Arena {
        Arena {
            robot: robot.to_string(),
            id,
            enabled,
            boundary: self.boundary.clone(),
            keep_out: self.keep_out.clone(),
            slow_zones: self.slow_zones.clone(),
            margin: self.margin,
        }
    }

    /// The message that tells `robot` there is no arena (the station has
    /// none, or it was cleared): nothing to fence in, the default margin.
    pub fn none_for(robot: &str, id: u32, enabled: bool) -> Arena {
        Arena {
            robot: robot.to_string(),
            id,
            enabled,
            boundary: Vec::new(),
            keep_out: Vec::new(),
            slow_zones: Vec::new(),
            margin: DEFAULT_MARGIN,
        }
    }

    /// The static obstacles as the neighbour lists carry them.
    pub fn obstacle_list(&self) -> Vec<Obstacle> {
        self.obstacles.iter().copied().map(Obstacle::Disc).collect()
    }

    /// The smallest rectangle holding the boundary (`min_x, min_y, max_x,
    /// max_y`), `None` without one.
    pub fn bounds(&self) -> Option<[f64; 4]> {
        let first = self.boundary.first()?;
        let mut b = [first.x, first.y, first.x, first.y];
        for p in &self.boundary {
            b = [b[0].min(p.x), b[1].min(p.y), b[2].max(p.x), b[3].max(p.y)];
        }
        Some(b)
    }

    /// `4 vertices, 1 keep-out, 0 slow zones, margin 0.10 m`: what an
    /// operator is told of it.
    pub fn summary(&self) -> String {
        let mut s = format!(
            "{} vertices, {} keep-out{}, {} slow zone{}",
            self.boundary.len(),
            self.keep_out.len(),
            if self.keep_out.len() == 1 { "" } else { "s" },
            self.slow_zones.len(),
            if self.slow_zones.len() == 1 { "" } else { "s" },
        );
        if !self.obstacles.is_empty() {
            s += &format!(", {} obstacle discs", self.obstacles.len());
        }
        if let Some([x0, y0, x1, y1]) = self.bounds() {
            s += &format!(
                ", {:.2} m x {:.2} m from ({x0:.2}, {y0:.2})",
                x1 - x0,
                y1 - y0
            );
        }
        s + &format!(", margin {:.2} m", self.margin)
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
    fn obstacle_discs_are_read_checked_and_listed_for_the_neighbours() {
        let a = section(
            "[arena]\nboundary = [[0, 0], [4, 0], [4, 3], [0, 3]]\n\
             obstacles = [{ x = 1, y = 2, radius = 0.25 }]\n",
        )
        .unwrap();
        let shape = a.shape();
        assert_eq!(
            shape.obstacle_list(),
            vec![Obstacle::Disc(Disc {
                x: 1.0,
                y: 2.0,
                radius: 0.25
            })]
        );
        assert_eq!(shape.bounds(), Some([0.0, 0.0, 4.0, 3.0]));
        assert_eq!(
            shape.summary(),
            "4 vertices, 0 keep-outs, 0 slow zones, 1 obstacle discs, \
             4.00 m x 3.00 m from (0.00, 0.00), margin 0.10 m"
        );
        let e = section(
            "[arena]\nboundary = [[0, 0], [4, 0], [4, 3]]\n\
             obstacles = [{ x = 1, y = 2, radius = -1 }]\n",
        )
        .unwrap_err();
        assert!(e.starts_with("gcs.toml:3:14: arena.obstacles[0]:"), "{e}");
        // As recordings carry it.
        let json = serde_json::to_string(&shape).unwrap();
        assert_eq!(serde_json::from_str::<ArenaShape>(&json).unwrap(), shape);
        let none = ArenaShape::none_for("robot_1", 4, false);
        assert!(none.is_empty() && !none.enabled && none.margin == DEFAULT_MARGIN);
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
