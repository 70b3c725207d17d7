//! Text and configuration forms of the control inputs: formations
//! (`line 0.8`, `custom 0,0.5 0,-0.5`), offsets (`dx,dy`), cluster waypoints
//! (`x,y[,heading]`), cluster definitions in TOML, and the gamepad mapping
//! that turns sticks into a cluster velocity (translate, rotate, scale).
//!
//! The command language and the configuration loader call these, so a
//! formation is written the same way everywhere.

use mech_proto::{ClusterVelocity, Formation, FormationKind, Offset};
use serde::Deserialize;
use thiserror::Error;

use super::cluster::ClusterWaypoint;

/// Spacing used when a formation is written without one, m.
pub const DEFAULT_SPACING: f64 = 1.0;

/// Why a control argument could not be read.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum SpecError {
    #[error("unknown formation {0:?}; formations are line, column, wedge, circle, custom")]
    UnknownFormation(String),
    #[error("expected a spacing in metres (a positive number), found {0:?}")]
    Spacing(String),
    #[error("expected an offset like 0.5,-1.0, found {0:?}")]
    Offset(String),
    #[error("a custom formation needs at least one offset x,y")]
    NoOffsets,
    #[error("expected a cluster waypoint like 2.0,1.0 or 2.0,1.0,90deg, found {0:?}")]
    Waypoint(String),
    #[error("unexpected {0:?} after the formation")]
    Trailing(String),
}

fn number(s: &str) -> Option<f64> {
    s.trim().parse::<f64>().ok().filter(|v| v.is_finite())
}

/// An angle in radians, or in degrees with a `deg` suffix.
fn angle(s: &str) -> Option<f64> {
    match s.strip_suffix("deg") {
        Some(d) => number(d).map(f64::to_radians),
        None => number(s),
    }
}

/// `x,y` in metres.
pub fn parse_offset(s: &str) -> Result<Offset, SpecError> {
    match s
        .split(',')
        .map(number)
        .collect::<Option<Vec<f64>>>()
        .as_deref()
    {
        Some([x, y]) => Ok(Offset { x: *x, y: *y }),
        _ => Err(SpecError::Offset(s.to_string())),
    }
}

/// `x,y` or `x,y,heading` (radians, or degrees with `deg`).
pub fn parse_cluster_waypoint(s: &str) -> Result<ClusterWaypoint, SpecError> {
    let parts: Vec<&str> = s.split(',').collect();
    let bad = || SpecError::Waypoint(s.to_string());
    match parts.as_slice() {
        [x, y] => Ok(ClusterWaypoint {
            x: number(x).ok_or_else(bad)?,
            y: number(y).ok_or_else(bad)?,
            heading: None,
        }),
        [x, y, h] => Ok(ClusterWaypoint {
            x: number(x).ok_or_else(bad)?,
            y: number(y).ok_or_else(bad)?,
            heading: Some(angle(h).ok_or_else(bad)?),
        }),
        _ => Err(bad()),
    }
}

/// A formation from words: `line|column|wedge|circle [SPACING]` or
/// `custom X,Y X,Y ...`.
pub fn parse_formation(words: &[&str]) -> Result<Formation, SpecError> {
    let Some((kind, rest)) = words.split_first() else {
        return Err(SpecError::UnknownFormation(String::new()));
    };
    let kind = formation_kind(kind)?;
    if kind == FormationKind::Custom {
        if rest.is_empty() {
            return Err(SpecError::NoOffsets);
        }
        let offsets = rest
            .iter()
            .map(|w| parse_offset(w))
            .collect::<Result<Vec<_>, _>>()?;
        return Ok(Formation {
            kind,
            spacing: 0.0,
            offsets,
        });
    }
    let spacing = match rest {
        [] => DEFAULT_SPACING,
        [s] => number(s)
            .filter(|v| *v > 0.0)
            .ok_or_else(|| SpecError::Spacing(s.to_string()))?,
        [_, extra, ..] => return Err(SpecError::Trailing(extra.to_string())),
    };
    Ok(Formation {
        kind,
        spacing,
        offsets: Vec::new(),
    })
}

/// The formation kind named `s` ([`FormationKind::as_str`]).
pub fn formation_kind(s: &str) -> Result<FormationKind, SpecError> {
    FormationKind::parse(s).ok_or_else(|| SpecError::UnknownFormation(s.to_string()))
}

/// A cluster as written in the GCS configuration:
///
/// ```toml
/// [[cluster]]
/// name = "c1"
/// members = ["robot_1", "robot_2", "robot_3"]
/// formation = "wedge"       # line, column, wedge, circle, custom
/// spacing = 0.8
/// # offsets = [[0.0, 0.5], [0.0, -0.5], [-0.7, 0.0]]   # for custom
/// ```
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClusterSpec {
    pub name: String,
    pub members: Vec<String>,
    #[serde(default = "default_formation")]
    pub formation: String,
    #[serde(default = "default_spacing")]
    pub spacing: f64,
    #[serde(default)]
    pub offsets: Vec<[f64; 2]>,
}

fn default_formation() -> String {
    "line".to_string()
}

fn default_spacing() -> f64 {
    DEFAULT_SPACING
}

impl ClusterSpec {
    /// The formation this entry describes.
    pub fn formation(&self) -> Result<Formation, SpecError> {
        let kind = formation_kind(&self.formation)?;
        if kind == FormationKind::Custom && self.offsets.is_empty() {
            return Err(SpecError::NoOffsets);
        }
        if kind != FormationKind::Custom && !(self.spacing.is_finite() && self.spacing > 0.0) {
            return Err(SpecError::Spacing(self.spacing.to_string()));
        }
        Ok(Formation {
            kind,
            spacing: self.spacing,
            offsets: self
                .offsets
                .iter()
                .map(|[x, y]| Offset { x: *x, y: *y })
                .collect(),
        })
    }
}

/// Gamepad axes for driving a cluster, each in `[-1, 1]`: left stick
/// translates (up = forward along the cluster heading, left = left), right
/// stick x rotates (left = counter-clockwise), triggers (or shoulder buttons)
/// grow (`grow`) and shrink (`shrink`) the formation.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ClusterSticks {
    pub forward: f64,
    pub left: f64,
    pub turn_left: f64,
    pub grow: f64,
    pub shrink: f64,
}

/// Full-deflection rates of the cluster gamepad mapping.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ClusterStickRates {
    /// m/s
    pub speed: f64,
    /// rad/s
    pub yaw_rate: f64,
    /// 1/s
    pub scale_rate: f64,
    /// Deflection below which an axis reads zero (stick noise).
    pub dead_zone: f64,
}

impl Default for ClusterStickRates {
    fn default() -> Self {
        ClusterStickRates {
            speed: 0.3,
            yaw_rate: 0.5,
            scale_rate: 0.2,
            dead_zone: 0.08,
        }
    }
}

/// Cluster velocity (cluster frame) for a gamepad state.
pub fn cluster_velocity_from_sticks(
    s: &ClusterSticks,
    rates: &ClusterStickRates,
) -> ClusterVelocity {
    let axis = |v: f64| {
        let v = if v.is_finite() {
            v.clamp(-1.0, 1.0)
        } else {
            0.0
        };
        if v.abs() < rates.dead_zone {
            0.0
        } else {
            // Rescale so output starts at zero at the dead-zone edge.
            v.signum() * (v.abs() - rates.dead_zone) / (1.0 - rates.dead_zone)
        }
    };
    ClusterVelocity {
        vx: axis(s.forward) * rates.speed,
        vy: axis(s.left) * rates.speed,
        wz: axis(s.turn_left) * rates.yaw_rate,
        scale_rate: (axis(s.grow.max(0.0)) - axis(s.shrink.max(0.0))) * rates.scale_rate,
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    #[test]
    fn formations_parse_with_and_without_spacing() {
        assert_eq!(
            parse_formation(&["wedge", "0.8"]).unwrap(),
            Formation {
                kind: FormationKind::Wedge,
                spacing: 0.8,
                offsets: vec![]
            }
        );
        assert_eq!(parse_formation(&["line"]).unwrap().spacing, DEFAULT_SPACING);
        let custom = parse_formation(&["custom", "0,0.5", "-1,-0.5"]).unwrap();
        assert_eq!(
            custom.offsets,
            vec![Offset { x: 0.0, y: 0.5 }, Offset { x: -1.0, y: -0.5 }]
        );
        assert_eq!(
            parse_formation(&["blob"]),
            Err(SpecError::UnknownFormation("blob".into()))
        );
        assert_eq!(
            parse_formation(&["line", "-2"]),
            Err(SpecError::Spacing("-2".into()))
        );
        assert_eq!(
            parse_formation(&["line", "1", "2"]),
            Err(SpecError::Trailing("2".into()))
        );
        assert_eq!(parse_formation(&["custom"]), Err(SpecError::NoOffsets));
        assert_eq!(
            parse_formation(&["custom", "1;2"]),
            Err(SpecError::Offset("1;2".into()))
        );
    }

    #[test]
    fn waypoints_take_radians_or_degrees() {
        assert_eq!(
            parse_cluster_waypoint("1,2").unwrap(),
            ClusterWaypoint {
                x: 1.0,
                y: 2.0,
                heading: None
            }
        );
        let w = parse_cluster_waypoint("1,2,90deg").unwrap();
        assert!((w.heading.unwrap() - std::f64::consts::FRAC_PI_2).abs() < 1e-12);
        assert_eq!(
            parse_cluster_waypoint("1,2,0.5").unwrap().heading,
            Some(0.5)
        );
        assert!(parse_cluster_waypoint("1").is_err());
        assert!(parse_cluster_waypoint("1,x").is_err());
        assert!(parse_cluster_waypoint("1,2,3,4").is_err());
    }

    #[test]
    fn cluster_spec_reads_from_toml() {
        #[derive(Deserialize)]
        struct File {
            cluster: Vec<ClusterSpec>,
        }
        let f: File = toml::from_str(
            "[[cluster]]\nname = \"c1\"\nmembers = [\"robot_1\", \"robot_2\"]\n\
             formation = \"custom\"\noffsets = [[0.0, 0.5], [0.0, -0.5]]\n\
             [[cluster]]\nname = \"c2\"\nmembers = [\"robot_3\"]\n",
        )
        .unwrap();
        assert_eq!(f.cluster[0].formation().unwrap().offsets.len(), 2);
        assert_eq!(f.cluster[1].formation().unwrap().kind, FormationKind::Line);
        let bad = ClusterSpec {
            formation: "custom".into(),
            ..f.cluster[1].clone()
        };
        assert_eq!(bad.formation(), Err(SpecError::NoOffsets));
    }

    #[test]
    fn sticks_map_to_cluster_velocity_with_dead_zone() {
        let rates = ClusterStickRates::default();
        let v = cluster_velocity_from_sticks(
            &ClusterSticks {
                forward: 1.0,
                left: 0.05,
                turn_left: -1.0,
                grow: 0.0,
                shrink: 1.0,
            },
            &rates,
        );
        assert!((v.vx - 0.3).abs() < 1e-12);
        assert_eq!(v.vy, 0.0, "inside the dead zone");
        assert!((v.wz + 0.5).abs() < 1e-12);
        assert!((v.scale_rate + 0.2).abs() < 1e-12);
        let nan = cluster_velocity_from_sticks(
            &ClusterSticks {
                forward: f64::NAN,
                ..Default::default()
            },
            &rates,
        );
        assert_eq!(nan.vx, 0.0);
    }
}
