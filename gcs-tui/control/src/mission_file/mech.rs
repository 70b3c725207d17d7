//! MECH's mission file: TOML, versioned by its first key, in arena metres
//! and seconds, with nothing lost (`docs/commands.md`, *Mission files*):
//!
//! ```toml
//! mech_mission = 1     # the format's version
//! kind = "robot"       # or "cluster"
//! loop = false         # start again from the first waypoint after the last
//!
//! [[waypoint]]
//! x = 1.0              # m, arena frame (x east, y north)
//! y = 2.0
//! z = 0.0              # m up (robot missions; default 0)
//! t = 15.0             # s after the mission starts (robot missions; optional)
//! ```
//!
//! A cluster's waypoints have `heading` (rad, counter-clockwise from +x;
//! optional) instead of `z` and `t`. Unknown keys are errors, so a typo is
//! never silently ignored.

use mech_proto::{MAX_WAYPOINT_TIME, Waypoint};
use serde::Deserialize;
use toml::Spanned;

use super::{MissionFileError, MissionPlan};
use crate::cluster::ClusterWaypoint;

/// The format version this station writes and reads.
pub const VERSION: u32 = 1;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct File {
    mech_mission: u32,
    kind: Kind,
    #[serde(default, rename = "loop")]
    looped: bool,
    #[serde(default, rename = "waypoint")]
    waypoints: Vec<Point>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
enum Kind {
    Robot,
    Cluster,
}

/// A waypoint as written: each number with where it is in the text, so a
/// value out of bounds is reported at its line.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct Point {
    x: Spanned<f64>,
    y: Spanned<f64>,
    z: Option<Spanned<f64>>,
    t: Option<Spanned<f64>>,
    heading: Option<Spanned<f64>>,
}

impl Point {
    /// Checks each number the way the command language does: finite, and
    /// an arrival time neither negative nor more than a day
    /// ([`MAX_WAYPOINT_TIME`]); a mistake names waypoint `n` (1-based), the
    /// key and the line.
    fn check(&self, text: &str, n: usize) -> Result<(), MissionFileError> {
        let at = |v: &Spanned<f64>, key: &str, why: String| MissionFileError::AtLine {
            line: line_of(text, v.span().start),
            message: format!("waypoint {n}: `{key}` = {why}"),
        };
        let numbers = [
            ("x", Some(&self.x)),
            ("y", Some(&self.y)),
            ("z", self.z.as_ref()),
            ("t", self.t.as_ref()),
            ("heading", self.heading.as_ref()),
        ];
        for (key, v) in numbers {
            if let Some(v) = v.filter(|v| !v.get_ref().is_finite()) {
                return Err(at(v, key, format!("{}: not a finite number", v.get_ref())));
            }
        }
        if let Some(t) = &self.t {
            let secs = *t.get_ref();
            if secs < 0.0 {
                return Err(at(
                    t,
                    "t",
                    format!("{secs} s: an arrival time is not negative"),
                ));
            }
            if secs > MAX_WAYPOINT_TIME {
                return Err(at(
                    t,
                    "t",
                    format!(
                        "{secs} s: an arrival time is at most {MAX_WAYPOINT_TIME} s (a day) \
                         after the mission starts"
                    ),
                ));
            }
        }
        Ok(())
    }
}

/// The line (1-based) of byte `offset` in `text`.
fn line_of(text: &str, offset: usize) -> usize {
    text.get(..offset.min(text.len()))
        .unwrap_or(text)
        .matches('\n')
        .count()
        + 1
}

/// Reads a MECH mission file.
pub fn read(text: &str) -> Result<MissionPlan, MissionFileError> {
    let file: File = toml::from_str(text).map_err(|e| toml_error(text, &e))?;
    if file.mech_mission != VERSION {
        return Err(MissionFileError::Invalid(format!(
            "mech_mission = {}: this station reads version {VERSION} of the mission format",
            file.mech_mission
        )));
    }
    let only = |i: usize, key: &str, kind: &str| {
        Err(MissionFileError::Invalid(format!(
            "waypoint {}: `{key}` is for {kind} missions, and this is a {} mission",
            i + 1,
            match file.kind {
                Kind::Robot => "robot",
                Kind::Cluster => "cluster",
            }
        )))
    };
    Ok(match file.kind {
        Kind::Robot => {
            let mut waypoints = Vec::with_capacity(file.waypoints.len());
            for (i, p) in file.waypoints.iter().enumerate() {
                if p.heading.is_some() {
                    return only(i, "heading", "cluster");
                }
                p.check(text, i + 1)?;
                waypoints.push(Waypoint {
                    x: *p.x.get_ref(),
                    y: *p.y.get_ref(),
                    z: p.z.as_ref().map_or(0.0, |z| *z.get_ref()),
                    time: p.t.as_ref().map(|t| *t.get_ref()),
                });
            }
            MissionPlan::Robot {
                waypoints,
                looped: file.looped,
            }
        }
        Kind::Cluster => {
            let mut waypoints = Vec::with_capacity(file.waypoints.len());
            for (i, p) in file.waypoints.iter().enumerate() {
                if p.z.is_some() {
                    return only(i, "z", "robot");
                }
                if p.t.is_some() {
                    return only(i, "t", "robot");
                }
                p.check(text, i + 1)?;
                waypoints.push(ClusterWaypoint {
                    x: *p.x.get_ref(),
                    y: *p.y.get_ref(),
                    heading: p.heading.as_ref().map(|h| *h.get_ref()),
                });
            }
            MissionPlan::Cluster {
                waypoints,
                looped: file.looped,
            }
        }
    })
}

/// A TOML error at the line it points at.
fn toml_error(text: &str, e: &toml::de::Error) -> MissionFileError {
    match e.span() {
        Some(span) => MissionFileError::AtLine {
            line: line_of(text, span.start),
            message: e.message().to_string(),
        },
        None => MissionFileError::Invalid(e.message().to_string()),
    }
}

/// Writes `plan` as a MECH mission file. Numbers are written so that they
/// read back exactly (`{:?}` of an `f64` is its shortest round-trip form).
pub fn write(plan: &MissionPlan) -> String {
    let mut out = String::from(
        "# A MECH mission (docs/commands.md, \"Mission files\"): metres in the arena\n\
         # frame (x east, y north, z up), times in s after the mission starts,\n\
         # headings in rad counter-clockwise from +x.\n",
    );
    let (kind, looped) = match plan {
        MissionPlan::Robot { looped, .. } => ("robot", *looped),
        MissionPlan::Cluster { looped, .. } => ("cluster", *looped),
    };
    out.push_str(&format!(
        "mech_mission = {VERSION}\nkind = \"{kind}\"\nloop = {looped}\n"
    ));
    match plan {
        MissionPlan::Robot { waypoints, .. } => {
            for w in waypoints {
                out.push_str(&format!(
                    "\n[[waypoint]]\nx = {:?}\ny = {:?}\nz = {:?}\n",
                    w.x, w.y, w.z
                ));
                if let Some(t) = w.time {
                    out.push_str(&format!("t = {t:?}\n"));
                }
            }
        }
        MissionPlan::Cluster { waypoints, .. } => {
            for w in waypoints {
                out.push_str(&format!("\n[[waypoint]]\nx = {:?}\ny = {:?}\n", w.x, w.y));
                if let Some(h) = w.heading {
                    out.push_str(&format!("heading = {h:?}\n"));
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn robot_plan() -> MissionPlan {
        MissionPlan::Robot {
            waypoints: vec![
                Waypoint {
                    x: 1.0,
                    y: 2.0,
                    z: 0.0,
                    time: None,
                },
                Waypoint {
                    x: -0.1 + 0.2,
                    y: 1e-7,
                    z: 1.5,
                    time: Some(15.25),
                },
            ],
            looped: true,
        }
    }

    #[test]
    fn a_robot_and_a_cluster_mission_read_back_exactly() {
        let robot = robot_plan();
        assert_eq!(read(&write(&robot)).unwrap(), robot);
        let cluster = MissionPlan::Cluster {
            waypoints: vec![
                ClusterWaypoint {
                    x: 0.5,
                    y: 0.5,
                    heading: Some(std::f64::consts::FRAC_PI_2),
                },
                ClusterWaypoint {
                    x: 1.5,
                    y: 0.5,
                    heading: None,
                },
            ],
            looped: false,
        };
        assert_eq!(read(&write(&cluster)).unwrap(), cluster);
    }

    #[test]
    fn the_documented_example_reads_and_integers_are_metres_too() {
        let text = "mech_mission = 1\nkind = \"robot\"\n\n[[waypoint]]\nx = 1\ny = 2\nt = 15\n";
        let plan = read(text).unwrap();
        assert_eq!(
            plan,
            MissionPlan::Robot {
                waypoints: vec![Waypoint {
                    x: 1.0,
                    y: 2.0,
                    z: 0.0,
                    time: Some(15.0)
                }],
                looped: false
            }
        );
    }

    /// The limits `waypoint` puts on a point hold for a file too: the
    /// message names the line, the waypoint and the key.
    #[test]
    fn times_beyond_a_day_negative_times_and_non_finite_numbers_are_refused_at_their_line() {
        let file = |last: &str| {
            format!(
                "mech_mission = 1\nkind = \"robot\"\n\n[[waypoint]]\nx = 1\ny = 2\nt = 10\n\n\
                 [[waypoint]]\nx = 3\ny = 2\n{last}\n"
            )
        };
        let refused = |last: &str| match read(&file(last)).unwrap_err() {
            MissionFileError::AtLine { line, message } => (line, message),
            other => panic!("{last}: {other:?}"),
        };
        let (line, message) = refused("t = 1e20");
        assert_eq!(line, 12, "{message}");
        assert!(
            message.starts_with("waypoint 2: `t` = 100000000000000000000 s"),
            "{message}"
        );
        assert!(message.contains("at most 86400 s (a day)"), "{message}");
        let (line, message) = refused("t = -1.5");
        assert_eq!(line, 12, "{message}");
        assert!(message.contains("waypoint 2: `t` = -1.5 s"), "{message}");
        assert!(message.contains("not negative"), "{message}");
        let (line, message) = refused("z = nan");
        assert_eq!(line, 12, "{message}");
        assert!(
            message.contains("waypoint 2: `z` = NaN: not a finite number"),
            "{message}"
        );
        assert_eq!(
            read(&file("t = 86400")).unwrap().len(),
            2,
            "a day is the limit, not past it"
        );
        let cluster = "mech_mission = 1\nkind = \"cluster\"\n[[waypoint]]\nx = inf\ny = 2\n";
        match read(cluster).unwrap_err() {
            MissionFileError::AtLine { line, message } => {
                assert_eq!(line, 4, "{message}");
                assert!(message.contains("waypoint 1: `x` = inf"), "{message}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn typos_other_versions_and_misplaced_keys_are_refused_with_where() {
        let typo = "mech_mission = 1\nkind = \"robot\"\n\n[[waypoint]]\nx = 1\ny = 2\ntime = 3\n";
        match read(typo).unwrap_err() {
            MissionFileError::AtLine { line, message } => {
                assert!(line >= 4, "{line}: {message}");
                assert!(message.contains("time"), "{message}");
            }
            other => panic!("{other:?}"),
        }
        let newer = "mech_mission = 2\nkind = \"robot\"\n";
        assert!(read(newer).unwrap_err().to_string().contains("version 1"));
        let heading =
            "mech_mission = 1\nkind = \"robot\"\n[[waypoint]]\nx = 1\ny = 2\nheading = 1\n";
        let e = read(heading).unwrap_err().to_string();
        assert!(e.contains("`heading` is for cluster missions"), "{e}");
        let z = "mech_mission = 1\nkind = \"cluster\"\n[[waypoint]]\nx = 1\ny = 2\nz = 1\n";
        assert!(
            read(z)
                .unwrap_err()
                .to_string()
                .contains("`z` is for robot")
        );
        let no_version = "kind = \"robot\"\n";
        assert!(
            read(no_version)
                .unwrap_err()
                .to_string()
                .contains("mech_mission")
        );
    }
}
