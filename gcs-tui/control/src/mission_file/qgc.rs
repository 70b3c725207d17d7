//! `QGC WPL 110`, the MAVLink waypoint file MAVProxy's `wp save`,
//! QGroundControl and Mission Planner read and write: a header line, then
//! one tab-separated line per mission item, `SEQ CURRENT FRAME COMMAND
//! PARAM1 PARAM2 PARAM3 PARAM4 X Y Z AUTOCONTINUE`. Item 0 is home (as
//! ArduPilot keeps it); MECH reads it only as `origin home`.
//!
//! Frames (`docs/commands.md`, *Mission files*):
//! - MECH writes `MAV_FRAME_LOCAL_ENU` (4): x east, y north, z up, metres
//!   from the arena origin, which is MECH's own frame (REP 103) unchanged;
//!   with a geographic origin it writes `MAV_FRAME_GLOBAL_RELATIVE_ALT`
//!   (3): latitude, longitude and height above that origin, which
//!   ArduPilot and PX4 fly.
//! - MECH reads LOCAL_ENU (4) as is and `MAV_FRAME_LOCAL_NED` (1) turned
//!   into ENU (x north, y east, z down there). Global frames (0 and 5:
//!   altitude above mean sea level; 3 and 6: above home) only with an
//!   origin that places the arena on the Earth: `origin LAT,LON[,ALT]`, or
//!   `origin home` for the file's item 0. Terrain-relative frames (10, 11)
//!   and the others are refused.
//!
//! The geographic mapping is a local tangent plane on a sphere of the
//! Earth's mean radius (equirectangular about the origin): x = R cos(lat0)
//! (lon - lon0), y = R (lat - lat0). Over an arena of a kilometre it is
//! off by well under a centimetre.
//!
//! Waypoints are `MAV_CMD_NAV_WAYPOINT` (16) items (`NAV_SPLINE_WAYPOINT`,
//! 82, read as one too). A loop is a `MAV_CMD_DO_JUMP` (177) to the first
//! waypoint repeated forever (-1), as ArduPilot's own looping missions end.
//! Arrival times have no place in the format: writing drops them (and says
//! so). A cluster waypoint's heading is the item's yaw (param 4, degrees
//! clockwise from north as MAVLink angles are; NaN for none).

use mech_proto::Waypoint;

use super::{MissionFileError, MissionPlan};
use crate::cluster::ClusterWaypoint;

/// The first line of a file, as every writer of the format begins it.
pub const HEADER: &str = "QGC WPL 110";
/// What a file of any QGC WPL version begins with.
pub(super) const HEADER_PREFIX: &str = "QGC WPL";

/// The Earth's mean radius, m: the sphere the geographic mapping uses.
pub const EARTH_RADIUS: f64 = 6_371_000.0;

/// `MAV_FRAME_*` numbers this file reads or writes.
mod frame {
    pub const GLOBAL: u32 = 0;
    pub const LOCAL_NED: u32 = 1;
    pub const MISSION: u32 = 2;
    pub const GLOBAL_RELATIVE_ALT: u32 = 3;
    pub const LOCAL_ENU: u32 = 4;
    pub const GLOBAL_INT: u32 = 5;
    pub const GLOBAL_RELATIVE_ALT_INT: u32 = 6;
    pub const GLOBAL_TERRAIN_ALT: u32 = 10;
    pub const GLOBAL_TERRAIN_ALT_INT: u32 = 11;
}

/// `MAV_CMD_*` numbers this file reads or writes.
mod command {
    pub const NAV_WAYPOINT: u32 = 16;
    pub const NAV_SPLINE_WAYPOINT: u32 = 82;
    pub const DO_JUMP: u32 = 177;
}

/// Where the arena's origin is on the Earth: latitude and longitude in
/// degrees, altitude in metres above mean sea level.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoOrigin {
    pub lat: f64,
    pub lon: f64,
    pub alt: f64,
}

/// How a file's global coordinates are placed in the arena.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Origin {
    /// The arena's origin is here.
    Geo(GeoOrigin),
    /// The arena's origin is the file's home (item 0).
    Home,
}

impl GeoOrigin {
    /// Arena metres (east, north) of a latitude and longitude.
    fn to_local(self, lat: f64, lon: f64) -> (f64, f64) {
        let dlon = (lon - self.lon + 540.0).rem_euclid(360.0) - 180.0;
        let x = EARTH_RADIUS * self.lat.to_radians().cos() * dlon.to_radians();
        let y = EARTH_RADIUS * (lat - self.lat).to_radians();
        (x, y)
    }

    /// Latitude and longitude of arena metres (east, north).
    fn to_global(self, x: f64, y: f64) -> (f64, f64) {
        let lat = self.lat + (y / EARTH_RADIUS).to_degrees();
        let lon = self.lon + (x / (EARTH_RADIUS * self.lat.to_radians().cos())).to_degrees();
        (lat, (lon + 540.0).rem_euclid(360.0) - 180.0)
    }
}

/// One line of the file.
#[derive(Debug, Clone, Copy)]
struct Item {
    /// Line in the file (1-based), for errors.
    line: usize,
    seq: u32,
    frame: u32,
    command: u32,
    params: [f64; 4],
    x: f64,
    y: f64,
    z: f64,
}

fn at(line: usize, message: impl Into<String>) -> MissionFileError {
    MissionFileError::AtLine {
        line,
        message: message.into(),
    }
}

fn parse_item(line: usize, text: &str) -> Result<Item, MissionFileError> {
    let fields: Vec<&str> = text.split_whitespace().collect();
    if fields.len() != 12 {
        return Err(at(
            line,
            format!(
                "{} values: a QGC WPL 110 item has 12 (SEQ CURRENT FRAME COMMAND \
                 PARAM1..4 X Y Z AUTOCONTINUE)",
                fields.len()
            ),
        ));
    }
    let int = |i: usize, what: &str| {
        fields[i].parse::<u32>().map_err(|_| {
            at(
                line,
                format!("{what} {:?} is not a whole number", fields[i]),
            )
        })
    };
    let real = |i: usize, what: &str| {
        fields[i]
            .parse::<f64>()
            .map_err(|_| at(line, format!("{what} {:?} is not a number", fields[i])))
    };
    Ok(Item {
        line,
        seq: int(0, "SEQ")?,
        frame: int(2, "FRAME")?,
        command: int(3, "COMMAND")?,
        params: [
            real(4, "PARAM1")?,
            real(5, "PARAM2")?,
            real(6, "PARAM3")?,
            real(7, "PARAM4")?,
        ],
        x: real(8, "X")?,
        y: real(9, "Y")?,
        z: real(10, "Z")?,
    })
}

/// The name of a MAVLink command, for notes.
fn command_name(c: u32) -> &'static str {
    match c {
        16 => "NAV_WAYPOINT",
        17 => "NAV_LOITER_UNLIM",
        18 => "NAV_LOITER_TURNS",
        19 => "NAV_LOITER_TIME",
        20 => "NAV_RETURN_TO_LAUNCH",
        21 => "NAV_LAND",
        22 => "NAV_TAKEOFF",
        82 => "NAV_SPLINE_WAYPOINT",
        93 => "NAV_DELAY",
        177 => "DO_JUMP",
        178 => "DO_CHANGE_SPEED",
        183 => "DO_SET_SERVO",
        _ => "another command",
    }
}

fn frame_name(f: u32) -> &'static str {
    match f {
        frame::GLOBAL => "MAV_FRAME_GLOBAL: latitude, longitude, altitude above mean sea level",
        frame::GLOBAL_INT => {
            "MAV_FRAME_GLOBAL_INT: latitude, longitude, altitude above mean sea level"
        }
        frame::GLOBAL_RELATIVE_ALT => {
            "MAV_FRAME_GLOBAL_RELATIVE_ALT: latitude, longitude, altitude above home"
        }
        frame::GLOBAL_RELATIVE_ALT_INT => {
            "MAV_FRAME_GLOBAL_RELATIVE_ALT_INT: latitude, longitude, altitude above home"
        }
        frame::GLOBAL_TERRAIN_ALT | frame::GLOBAL_TERRAIN_ALT_INT => {
            "MAV_FRAME_GLOBAL_TERRAIN_ALT: latitude, longitude, altitude above terrain"
        }
        frame::LOCAL_NED => "MAV_FRAME_LOCAL_NED",
        frame::LOCAL_ENU => "MAV_FRAME_LOCAL_ENU",
        frame::MISSION => "MAV_FRAME_MISSION (no position)",
        _ => "a frame that places no waypoint",
    }
}

/// Reads a QGC WPL 110 file (see the module's doc for frames and
/// origins); `cluster`: as a cluster's waypoints (yaw as heading).
pub fn read(
    text: &str,
    origin: Option<Origin>,
    cluster: bool,
) -> Result<(MissionPlan, Vec<String>), MissionFileError> {
    let items = items(text)?;
    let home = items.iter().find(|i| i.seq == 0).copied();
    let geo = geo_origin(origin, home)?;
    let body: Vec<Item> = items.into_iter().filter(|i| i.seq != 0).collect();
    let w = walk(&body, geo)?;
    let mut notes = Vec::new();
    if !w.skipped.is_empty() {
        notes.push(format!("skipped, not waypoints: {}", w.skipped.join(", ")));
    }
    if w.holds > 0 {
        notes.push(format!(
            "{} hold time(s) (param 1) not kept: a MECH waypoint is passed, not held",
            w.holds
        ));
    }
    let plan = if cluster {
        MissionPlan::Cluster {
            waypoints: w.group,
            looped: w.looped,
        }
    } else {
        MissionPlan::Robot {
            waypoints: w.robot,
            looped: w.looped,
        }
    };
    Ok((plan, notes))
}

/// The items of a file, after its header line; comments and blank lines
/// left out.
fn items(text: &str) -> Result<Vec<Item>, MissionFileError> {
    let mut lines = text.lines().enumerate().map(|(i, l)| (i + 1, l.trim()));
    let header = lines
        .by_ref()
        .find(|(_, l)| !l.is_empty())
        .map(|(n, l)| (n, l.to_string()));
    match header {
        Some((_, h)) if h == HEADER => {}
        Some((n, h)) => {
            return Err(at(
                n,
                format!(
                    "{h:?}: this station reads {HEADER:?} files (MAVProxy's wp save, QGroundControl)"
                ),
            ));
        }
        None => return Err(MissionFileError::Invalid("an empty file".into())),
    }
    let mut items = Vec::new();
    for (n, l) in lines {
        if l.is_empty() || l.starts_with('#') {
            continue;
        }
        items.push(parse_item(n, l)?);
    }
    Ok(items)
}

/// Where the file's latitudes and longitudes are measured from: the
/// origin given, or the file's home (item 0) for `origin home`.
fn geo_origin(
    origin: Option<Origin>,
    home: Option<Item>,
) -> Result<Option<GeoOrigin>, MissionFileError> {
    Ok(match origin {
        None => None,
        Some(Origin::Geo(g)) => Some(g),
        Some(Origin::Home) => {
            let h = home.ok_or_else(|| {
                MissionFileError::Invalid("`origin home`: the file has no home (item 0)".into())
            })?;
            if !matches!(h.frame, frame::GLOBAL | frame::GLOBAL_INT) || (h.x == 0.0 && h.y == 0.0) {
                return Err(at(
                    h.line,
                    "`origin home`: the file's home is not a latitude and longitude",
                ));
            }
            Some(GeoOrigin {
                lat: h.x,
                lon: h.y,
                alt: h.z,
            })
        }
    })
}

/// What a file's items (home left out) make: the waypoints for a robot and
/// for a cluster, whether the mission loops, and what was left out.
#[derive(Debug, Default)]
struct Walked {
    robot: Vec<Waypoint>,
    group: Vec<ClusterWaypoint>,
    looped: bool,
    /// Items that are not waypoints, described.
    skipped: Vec<String>,
    /// Waypoints with a hold time (not kept).
    holds: usize,
}

/// Walks the items in order: waypoints placed, one closing `DO_JUMP` to
/// the first waypoint as a loop, anything else skipped.
fn walk(body: &[Item], geo: Option<GeoOrigin>) -> Result<Walked, MissionFileError> {
    let mut w = Walked::default();
    let mut first_seq = None;
    for (k, item) in body.iter().enumerate() {
        match item.command {
            command::NAV_WAYPOINT | command::NAV_SPLINE_WAYPOINT => {
                let (x, y, z) = place(item, geo)?;
                first_seq.get_or_insert(item.seq);
                if item.params[0] > 0.0 {
                    w.holds += 1;
                }
                w.robot.push(Waypoint {
                    x,
                    y,
                    z,
                    time: None,
                });
                let yaw = item.params[3];
                w.group.push(ClusterWaypoint {
                    x,
                    y,
                    heading: yaw
                        .is_finite()
                        .then(|| crate::geometry::wrap_angle((90.0 - yaw).to_radians())),
                });
            }
            command::DO_JUMP => {
                let last = k + 1 == body.len();
                let forever = item.params[1] == -1.0;
                let to_first = first_seq.is_some_and(|f| f64::from(f) == item.params[0]);
                if !(last && forever && to_first) {
                    return Err(at(
                        item.line,
                        format!(
                            "DO_JUMP to item {} repeated {} times: a MECH mission loops \
                             from its first waypoint forever or not at all (a last \
                             DO_JUMP to the first waypoint, repeat -1)",
                            item.params[0], item.params[1]
                        ),
                    ));
                }
                w.looped = true;
            }
            c => w
                .skipped
                .push(format!("item {} ({c}, {})", item.seq, command_name(c))),
        }
    }
    Ok(w)
}

/// A waypoint item's place in the arena (x east, y north, z up, m).
fn place(item: &Item, geo: Option<GeoOrigin>) -> Result<(f64, f64, f64), MissionFileError> {
    let global = |relative: bool| {
        let Some(g) = geo else {
            return Err(at(
                item.line,
                format!(
                    "item {} is in frame {} ({}), and MECH's waypoints are metres in \
                     the arena: say where the arena is with `origin LAT,LON[,ALT]`, or \
                     `origin home` for the file's home (item 0)",
                    item.seq,
                    item.frame,
                    frame_name(item.frame)
                ),
            ));
        };
        let (x, y) = g.to_local(item.x, item.y);
        let z = if relative { item.z } else { item.z - g.alt };
        Ok((x, y, z))
    };
    match item.frame {
        frame::LOCAL_ENU => Ok((item.x, item.y, item.z)),
        frame::LOCAL_NED => Ok((item.y, item.x, -item.z)),
        frame::GLOBAL | frame::GLOBAL_INT => global(false),
        frame::GLOBAL_RELATIVE_ALT | frame::GLOBAL_RELATIVE_ALT_INT => global(true),
        f => Err(at(
            item.line,
            format!(
                "item {} is in frame {f} ({}): MECH reads waypoints in LOCAL_ENU (4), \
                 LOCAL_NED (1) and, with an origin, the global frames 0, 3, 5 and 6",
                item.seq,
                frame_name(f)
            ),
        )),
    }
}

/// Writes `plan` as QGC WPL 110: in LOCAL_ENU, or around `origin` in
/// GLOBAL_RELATIVE_ALT. Returns the text and notes on what the format
/// could not carry.
pub fn write(plan: &MissionPlan, origin: Option<GeoOrigin>) -> (String, Vec<String>) {
    let mut out = format!("{HEADER}\n");
    let line = |seq: usize, frame: u32, command: u32, params: [f64; 4], xyz: [f64; 3]| {
        format!(
            "{seq}\t0\t{frame}\t{command}\t{:.6}\t{:.6}\t{:.6}\t{:.6}\t{:.9}\t{:.9}\t{:.6}\t1\n",
            params[0], params[1], params[2], params[3], xyz[0], xyz[1], xyz[2]
        )
    };
    let (frame, home) = match origin {
        Some(g) => (
            frame::GLOBAL_RELATIVE_ALT,
            (frame::GLOBAL, [g.lat, g.lon, g.alt]),
        ),
        None => (frame::LOCAL_ENU, (frame::LOCAL_ENU, [0.0; 3])),
    };
    out.push_str(&line(0, home.0, command::NAV_WAYPOINT, [0.0; 4], home.1));
    let position = |x: f64, y: f64, z: f64| match origin {
        Some(g) => {
            let (lat, lon) = g.to_global(x, y);
            [lat, lon, z]
        }
        None => [x, y, z],
    };
    let mut notes = Vec::new();
    let n = match plan {
        MissionPlan::Robot { waypoints, .. } => {
            for (i, w) in waypoints.iter().enumerate() {
                let params = [0.0, 0.0, 0.0, f64::NAN];
                out.push_str(&line(
                    i + 1,
                    frame,
                    command::NAV_WAYPOINT,
                    params,
                    position(w.x, w.y, w.z),
                ));
            }
            let timed = waypoints.iter().filter(|w| w.time.is_some()).count();
            if timed > 0 {
                notes.push(format!(
                    "{timed} arrival time(s) not written: QGC WPL 110 has no place for them \
                     (MECH's .toml format keeps them)"
                ));
            }
            waypoints.len()
        }
        MissionPlan::Cluster { waypoints, .. } => {
            for (i, w) in waypoints.iter().enumerate() {
                let yaw = w
                    .heading
                    .map_or(f64::NAN, |h| (90.0 - h.to_degrees()).rem_euclid(360.0));
                let params = [0.0, 0.0, 0.0, yaw];
                out.push_str(&line(
                    i + 1,
                    frame,
                    command::NAV_WAYPOINT,
                    params,
                    position(w.x, w.y, 0.0),
                ));
            }
            waypoints.len()
        }
    };
    if plan.looped() {
        out.push_str(&line(
            n + 1,
            frame::MISSION,
            command::DO_JUMP,
            [1.0, -1.0, 0.0, 0.0],
            [0.0; 3],
        ));
    }
    (out, notes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wp(x: f64, y: f64, z: f64, time: Option<f64>) -> Waypoint {
        Waypoint { x, y, z, time }
    }

    fn close(a: &MissionPlan, b: &MissionPlan, tol: f64) {
        match (a, b) {
            (
                MissionPlan::Robot {
                    waypoints: p,
                    looped: l,
                },
                MissionPlan::Robot {
                    waypoints: q,
                    looped: m,
                },
            ) => {
                assert_eq!(l, m);
                assert_eq!(p.len(), q.len());
                for (u, v) in p.iter().zip(q) {
                    assert!(
                        (u.x - v.x).abs() < tol
                            && (u.y - v.y).abs() < tol
                            && (u.z - v.z).abs() < tol,
                        "{u:?} {v:?}"
                    );
                }
            }
            (
                MissionPlan::Cluster {
                    waypoints: p,
                    looped: l,
                },
                MissionPlan::Cluster {
                    waypoints: q,
                    looped: m,
                },
            ) => {
                assert_eq!(l, m);
                assert_eq!(p.len(), q.len());
                for (u, v) in p.iter().zip(q) {
                    assert!(
                        (u.x - v.x).abs() < tol && (u.y - v.y).abs() < tol,
                        "{u:?} {v:?}"
                    );
                    match (u.heading, v.heading) {
                        (None, None) => {}
                        (Some(h), Some(k)) => assert!((h - k).abs() < 1e-6, "{h} {k}"),
                        other => panic!("{other:?}"),
                    }
                }
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn local_enu_round_trips_and_drops_times_saying_so() {
        let plan = MissionPlan::Robot {
            waypoints: vec![wp(1.0, 2.0, 0.0, None), wp(-0.25, 1.125, 0.5, Some(12.0))],
            looped: true,
        };
        let (text, notes) = write(&plan, None);
        assert!(text.starts_with("QGC WPL 110\n0\t0\t4\t16\t"), "{text}");
        assert!(
            text.contains("\n3\t0\t2\t177\t1.000000\t-1.000000\t"),
            "{text}"
        );
        assert!(
            notes[0].contains("1 arrival time(s) not written"),
            "{notes:?}"
        );
        let (back, notes) = read(&text, None, false).unwrap();
        assert!(notes.is_empty(), "{notes:?}");
        let without_times = MissionPlan::Robot {
            waypoints: vec![wp(1.0, 2.0, 0.0, None), wp(-0.25, 1.125, 0.5, None)],
            looped: true,
        };
        assert_eq!(back, without_times);
    }

    #[test]
    fn a_cluster_keeps_its_headings_as_yaw_clockwise_from_north() {
        let plan = MissionPlan::Cluster {
            waypoints: vec![
                ClusterWaypoint {
                    x: 0.5,
                    y: 0.5,
                    heading: Some(0.0),
                },
                ClusterWaypoint {
                    x: 1.5,
                    y: 0.5,
                    heading: Some(std::f64::consts::FRAC_PI_2),
                },
                ClusterWaypoint {
                    x: 1.5,
                    y: 1.5,
                    heading: None,
                },
            ],
            looped: false,
        };
        let (text, _) = write(&plan, None);
        // East (heading 0) is yaw 90, north is yaw 0, none is NaN.
        let yaws: Vec<&str> = text
            .lines()
            .skip(2)
            .map(|l| l.split('\t').nth(7).unwrap())
            .collect();
        assert_eq!(yaws, ["90.000000", "0.000000", "NaN"]);
        close(&read(&text, None, true).unwrap().0, &plan, 1e-8);
    }

    #[test]
    fn global_frames_need_an_origin_and_round_trip_with_one() {
        let origin = GeoOrigin {
            lat: 52.0,
            lon: 4.37,
            alt: 3.0,
        };
        let plan = MissionPlan::Robot {
            waypoints: vec![wp(10.0, 20.0, 1.5, None), wp(-100.0, 250.0, 0.0, None)],
            looped: false,
        };
        let (text, _) = write(&plan, Some(origin));
        assert!(text.contains("\n1\t0\t3\t16\t"), "frame 3: {text}");
        let refused = read(&text, None, false).unwrap_err().to_string();
        assert!(
            refused.contains("frame 3 (MAV_FRAME_GLOBAL_RELATIVE_ALT")
                && refused.contains("origin LAT,LON"),
            "{refused}"
        );
        close(
            &read(&text, Some(Origin::Geo(origin)), false).unwrap().0,
            &plan,
            1e-4,
        );
        close(
            &read(&text, Some(Origin::Home), false).unwrap().0,
            &plan,
            1e-4,
        );
        // 100 m north is 100 / R radians of latitude.
        let (lat, lon) = origin.to_global(0.0, 100.0);
        assert!((lat - 52.0 - (100.0 / EARTH_RADIUS).to_degrees()).abs() < 1e-12);
        assert!((lon - 4.37).abs() < 1e-12);
    }

    #[test]
    fn local_ned_is_turned_into_enu_and_other_frames_are_refused() {
        let ned = "QGC WPL 110\n0\t1\t1\t16\t0\t0\t0\t0\t0\t0\t0\t1\n1\t0\t1\t16\t0\t0\t0\t0\t3.0\t1.0\t-2.0\t1\n";
        let (plan, _) = read(ned, None, false).unwrap();
        assert_eq!(
            plan,
            MissionPlan::Robot {
                waypoints: vec![wp(1.0, 3.0, 2.0, None)],
                looped: false
            }
        );
        let terrain = "QGC WPL 110\n1\t0\t10\t16\t0\t0\t0\t0\t52\t4\t20\t1\n";
        let e = read(
            terrain,
            Some(Origin::Geo(GeoOrigin {
                lat: 52.0,
                lon: 4.0,
                alt: 0.0,
            })),
            false,
        )
        .unwrap_err();
        assert_eq!(
            e,
            at(
                2,
                "item 1 is in frame 10 (MAV_FRAME_GLOBAL_TERRAIN_ALT: latitude, longitude, altitude above terrain): MECH reads waypoints in LOCAL_ENU (4), LOCAL_NED (1) and, with an origin, the global frames 0, 3, 5 and 6"
            )
        );
        assert!(
            read("QGC WPL 100\n", None, false)
                .unwrap_err()
                .to_string()
                .contains("reads \"QGC WPL 110\"")
        );
        let short = "QGC WPL 110\n1\t0\t4\t16\t0\t0\n";
        assert!(
            read(short, None, false)
                .unwrap_err()
                .to_string()
                .starts_with("line 2: 6 values")
        );
    }

    #[test]
    fn a_jump_that_is_not_a_loop_from_the_first_waypoint_is_refused() {
        let twice = "QGC WPL 110\n1\t0\t4\t16\t0\t0\t0\t0\t1\t1\t0\t1\n2\t0\t4\t16\t0\t0\t0\t0\t2\t1\t0\t1\n3\t0\t0\t177\t1\t2\t0\t0\t0\t0\t0\t1\n";
        let e = read(twice, None, false).unwrap_err().to_string();
        assert!(
            e.contains("line 4: DO_JUMP to item 1 repeated 2 times"),
            "{e}"
        );
    }
}
