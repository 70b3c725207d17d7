//! Mission files: a robot's or a cluster's waypoints, time constraints and
//! loop, kept on disk by `mission save` and read back by `mission load`.
//! Two formats: MECH's own ([`mech`], TOML, versioned) and the MAVLink
//! waypoint file `QGC WPL 110` ([`qgc`]) that MAVProxy's `wp save` and
//! QGroundControl write. Which one a file is follows its name (`.toml`:
//! MECH's; `.waypoints`, `.txt`: QGC WPL) when writing, and its first line
//! when reading. Where a file may be ([`crate::files`]) depends on who asks.
//! Nothing here talks to the station: these are text in, text out.

pub mod mech;
pub mod qgc;

use std::path::Path;

use mech_proto::Waypoint;

use crate::cluster::ClusterWaypoint;

/// What a mission file holds: one robot's waypoints (each with its
/// optional arrival time), or a cluster's (each with its optional
/// heading). Positions are metres in the arena frame (REP 103: x east, y
/// north, z up), times seconds after the mission starts, headings radians
/// counter-clockwise from +x.
#[derive(Debug, Clone, PartialEq)]
pub enum MissionPlan {
    Robot {
        waypoints: Vec<Waypoint>,
        looped: bool,
    },
    Cluster {
        waypoints: Vec<ClusterWaypoint>,
        looped: bool,
    },
}

impl MissionPlan {
    /// Number of waypoints.
    pub fn len(&self) -> usize {
        match self {
            MissionPlan::Robot { waypoints, .. } => waypoints.len(),
            MissionPlan::Cluster { waypoints, .. } => waypoints.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    pub fn looped(&self) -> bool {
        match self {
            MissionPlan::Robot { looped, .. } | MissionPlan::Cluster { looped, .. } => *looped,
        }
    }

    /// Checks what a mission may hold: at least one waypoint and at most a
    /// mission's worth, finite numbers, arrival times not negative and at
    /// most a day ([`mech_proto::MAX_WAYPOINT_TIME`]), as `waypoint` takes
    /// them.
    pub fn check(&self) -> Result<(), MissionFileError> {
        let bad = |why: String| Err(MissionFileError::Invalid(why));
        if self.is_empty() {
            return bad("no waypoints".into());
        }
        if self.len() > mech_proto::MAX_WAYPOINTS {
            return bad(format!(
                "{} waypoints: a mission holds at most {}",
                self.len(),
                mech_proto::MAX_WAYPOINTS
            ));
        }
        let finite = |i: usize, what: &str, v: f64| {
            if v.is_finite() {
                Ok(())
            } else {
                Err(MissionFileError::Invalid(format!(
                    "waypoint {}: {what} is not a finite number",
                    i + 1
                )))
            }
        };
        match self {
            MissionPlan::Robot { waypoints, .. } => {
                for (i, w) in waypoints.iter().enumerate() {
                    finite(i, "x", w.x)?;
                    finite(i, "y", w.y)?;
                    finite(i, "z", w.z)?;
                    if let Some(t) = w.time {
                        finite(i, "t", t)?;
                        if t < 0.0 {
                            return bad(format!("waypoint {}: t = {t} s is negative", i + 1));
                        }
                        if t > mech_proto::MAX_WAYPOINT_TIME {
                            return bad(format!(
                                "waypoint {}: t = {t} s is more than {} s (a day)",
                                i + 1,
                                mech_proto::MAX_WAYPOINT_TIME
                            ));
                        }
                    }
                }
            }
            MissionPlan::Cluster { waypoints, .. } => {
                for (i, w) in waypoints.iter().enumerate() {
                    finite(i, "x", w.x)?;
                    finite(i, "y", w.y)?;
                    if let Some(h) = w.heading {
                        finite(i, "heading", h)?;
                    }
                }
            }
        }
        Ok(())
    }
}

/// A mission file's format.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// MECH's own TOML ([`mech`]).
    Mech,
    /// `QGC WPL 110` ([`qgc`]).
    QgcWpl,
}

impl Format {
    /// The format a file of this name is written in: `.toml` MECH's,
    /// `.waypoints` or `.txt` QGC WPL 110 (the names QGroundControl and
    /// MAVProxy give them).
    pub fn of_name(path: &Path) -> Result<Format, MissionFileError> {
        match path.extension().and_then(|e| e.to_str()) {
            Some("toml") => Ok(Format::Mech),
            Some("waypoints" | "txt") => Ok(Format::QgcWpl),
            _ => Err(MissionFileError::Invalid(format!(
                "{}: name it .toml (MECH's mission format) or .waypoints / .txt \
                 (QGC WPL 110, as MAVProxy and QGroundControl read it)",
                path.display()
            ))),
        }
    }

    /// The format of a file's text, from its first line.
    pub fn of_text(text: &str) -> Format {
        if text.trim_start().starts_with(qgc::HEADER_PREFIX) {
            Format::QgcWpl
        } else {
            Format::Mech
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Format::Mech => "MECH mission",
            Format::QgcWpl => "QGC WPL 110",
        }
    }
}

/// Why a mission file could not be read, written or used.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum MissionFileError {
    /// The file's content, at a line (1-based) when it is known.
    #[error("line {line}: {message}")]
    AtLine { line: usize, message: String },
    #[error("{0}")]
    Invalid(String),
}

/// Reads a file's text in the format its first line says. `origin` maps
/// a QGC WPL file's global coordinates to the arena (ignored for MECH's
/// format, which is in arena metres); `cluster` reads a QGC WPL file as a
/// cluster's waypoints (yaw as heading) rather than a robot's. Returns the
/// plan and notes on what the format could not carry.
pub fn read(
    text: &str,
    origin: Option<qgc::Origin>,
    cluster: bool,
) -> Result<(MissionPlan, Vec<String>), MissionFileError> {
    let (plan, notes) = match Format::of_text(text) {
        Format::Mech => (mech::read(text)?, Vec::new()),
        Format::QgcWpl => qgc::read(text, origin, cluster)?,
    };
    plan.check()?;
    Ok((plan, notes))
}

/// Writes `plan` in `format`; with `origin`, a QGC WPL file is in global
/// coordinates around it. Returns the text and notes on what the format
/// could not carry.
pub fn write(
    plan: &MissionPlan,
    format: Format,
    origin: Option<qgc::GeoOrigin>,
) -> Result<(String, Vec<String>), MissionFileError> {
    plan.check()?;
    match format {
        Format::Mech => Ok((mech::write(plan), Vec::new())),
        Format::QgcWpl => Ok(qgc::write(plan, origin)),
    }
}
