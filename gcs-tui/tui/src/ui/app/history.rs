//! The last minute of every robot, as the detail view's plots and the
//! fleet table's trends draw it: a bounded ring of samples per robot, taken
//! from the snapshots the TUI receives anyway (every [`SAMPLE_PERIOD`] at
//! most, on the App's clock, or on a replay's), and the missions this TUI
//! sent, whose path gives the cross-track error. Nothing here asks the
//! station for anything.

use std::collections::{HashMap, VecDeque};
use std::time::Instant;

use mech_proto::{VelocitySource, Waypoint};

use crate::ui::series::Series;
use crate::ui::view::RobotView;

/// How far back the plots reach, s.
pub const HISTORY_SECONDS: f64 = 60.0;
/// The least time between two samples of a robot, s: 240 samples a
/// minute, about 10 KB per robot.
pub const SAMPLE_PERIOD: f64 = 0.25;
/// Samples kept per robot.
const SAMPLES: usize = (HISTORY_SECONDS / SAMPLE_PERIOD) as usize + 1;
/// The baseline of the speed measured from positions, s: long enough that
/// a few centimetres of position noise are a few cm/s.
const GROUND_SPEED_BASELINE: f64 = 1.0;

/// One robot at one time. `f32` (and NaN for unknown) keeps a fleet's
/// minute small.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sample {
    /// Seconds on the history's clock.
    pub t: f64,
    pub x: f32,
    pub y: f32,
    pub heading_deg: f32,
    /// The speed the robot reports (measured by encoders or following from
    /// its commands: [`RobotHistory::measured`]), m/s.
    pub speed: f32,
    /// Battery, %.
    pub battery: f32,
    /// Loss, %.
    pub loss: f32,
    /// Round trip, ms.
    pub rtt: f32,
    /// Messages per second from and to the robot.
    pub rx: f32,
    pub tx: f32,
    /// Signed distance from the path of the mission this TUI sent, m (left
    /// of the direction of travel positive); NaN without one.
    pub xte: f32,
}

/// The value of `series` in sample `s` (the ground speed is not a
/// sample's: [`RobotHistory::points`] works it out from positions).
fn value(series: Series, s: &Sample) -> f32 {
    match series {
        Series::Speed => s.speed,
        Series::GroundSpeed => f32::NAN,
        Series::Heading => s.heading_deg,
        Series::Battery => s.battery,
        Series::Loss => s.loss,
        Series::Rtt => s.rtt,
        Series::Rx => s.rx,
        Series::Tx => s.tx,
        Series::CrossTrack => s.xte,
    }
}

/// One robot's minute.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct RobotHistory {
    pub samples: VecDeque<Sample>,
    /// Whether its reported speed is measured (wheel encoders), as of the
    /// last sample.
    pub measured: bool,
}

impl RobotHistory {
    /// `(seconds before now, value)` of `series`, oldest first; unknown
    /// values left out.
    pub fn points(&self, series: Series, now: f64) -> Vec<(f64, f64)> {
        if series == Series::GroundSpeed {
            return self.ground_speed(now);
        }
        self.samples
            .iter()
            .filter_map(|s| {
                let v = value(series, s);
                v.is_finite().then_some((s.t - now, f64::from(v)))
            })
            .collect()
    }

    /// Distance travelled over the last [`GROUND_SPEED_BASELINE`] before
    /// each sample, over that time.
    fn ground_speed(&self, now: f64) -> Vec<(f64, f64)> {
        let mut out = Vec::new();
        let mut back = 0;
        for (i, s) in self.samples.iter().enumerate() {
            while back + 1 < i && s.t - self.samples[back + 1].t >= GROUND_SPEED_BASELINE {
                back += 1;
            }
            let b = &self.samples[back];
            let dt = s.t - b.t;
            if dt >= GROUND_SPEED_BASELINE * 0.9 {
                let d = f64::from(s.x - b.x).hypot(f64::from(s.y - b.y));
                out.push((s.t - now, d / dt));
            }
        }
        out
    }
}

/// A mission this TUI sent: where the robot was, and the waypoints.
#[derive(Debug, Clone, PartialEq)]
struct SentPath {
    from: (f64, f64),
    waypoints: Vec<(f64, f64)>,
}

/// Every robot's minute, and the missions sent from here.
#[derive(Debug, Clone)]
pub struct History {
    /// Time 0 of the live clock.
    start: Instant,
    robots: HashMap<String, RobotHistory>,
    /// When the last samples were taken.
    last: Option<f64>,
    /// The clock samples are on now (live or a replay's).
    pub now: f64,
    sent: HashMap<String, SentPath>,
}

impl History {
    pub fn new(start: Instant) -> History {
        History {
            start,
            robots: HashMap::new(),
            last: None,
            now: 0.0,
            sent: HashMap::new(),
        }
    }

    /// One robot's minute.
    pub fn robot(&self, name: &str) -> Option<&RobotHistory> {
        self.robots.get(name)
    }

    /// Seconds on the live clock at `now`.
    pub fn live_time(&self, now: Instant) -> f64 {
        now.saturating_duration_since(self.start).as_secs_f64()
    }

    /// Takes a sample of every robot at `t` (at most every
    /// [`SAMPLE_PERIOD`]), drops what is older than [`HISTORY_SECONDS`] and
    /// the robots that are gone. A clock that went back (a replay sought
    /// backwards) starts every history again.
    pub fn record(&mut self, t: f64, robots: &[RobotView]) {
        if self.last.is_some_and(|l| t < l) {
            self.robots.clear();
            self.last = None;
        }
        self.now = t;
        if self.last.is_some_and(|l| t - l < SAMPLE_PERIOD) {
            return;
        }
        self.last = Some(t);
        self.robots
            .retain(|name, _| robots.iter().any(|r| &r.name == name));
        for r in robots {
            let xte = self
                .sent
                .get(&r.name)
                .and_then(|p| cross_track(p, r))
                .map_or(f32::NAN, |d| d as f32);
            let q = &r.quality;
            let known = |v: Option<f64>| v.map_or(f32::NAN, |v| v as f32);
            let sample = Sample {
                t,
                x: r.telemetry.pose.x as f32,
                y: r.telemetry.pose.y as f32,
                heading_deg: r.heading_deg() as f32,
                speed: r.speed() as f32,
                battery: known(r.telemetry.battery.map(|b| b * 100.0)),
                loss: known(q.loss.map(|l| l * 100.0)),
                rtt: known(q.rtt.map(|d| d.as_secs_f64() * 1e3)),
                rx: known(q.measured().then_some(q.rx_hz)),
                tx: known(q.measured().then_some(q.tx_hz)),
                xte,
            };
            let h = self.robots.entry(r.name.clone()).or_default();
            h.measured = r.telemetry.velocity_source == VelocitySource::Measured;
            h.samples.push_back(sample);
            while h.samples.len() > SAMPLES
                || h.samples.front().is_some_and(|s| t - s.t > HISTORY_SECONDS)
            {
                h.samples.pop_front();
            }
        }
    }

    /// This TUI sent `waypoints` to `robots` (each from where it is now):
    /// their cross-track error is measured against that path from now on.
    pub fn mission_sent(&mut self, robots: &[RobotView], waypoints: &[Waypoint]) {
        for r in robots {
            self.sent.insert(
                r.name.clone(),
                SentPath {
                    from: (r.telemetry.pose.x, r.telemetry.pose.y),
                    waypoints: waypoints.iter().map(|w| (w.x, w.y)).collect(),
                },
            );
        }
    }

    /// Whether the cross-track error of `robot` can be measured: this TUI
    /// knows the path of the mission it runs.
    pub fn knows_path(&self, robot: &str) -> bool {
        self.sent.contains_key(robot)
    }
}

/// Signed distance of `r` from the leg of `path` it is on (from the
/// waypoint before `next` to `next`, the first leg from where it was when
/// the mission was sent), left of travel positive; `None` when the robot
/// runs no mission of that length, or has arrived.
fn cross_track(path: &SentPath, r: &RobotView) -> Option<f64> {
    let m = r.telemetry.mission?;
    let n = path.waypoints.len();
    if m.total as usize != n || m.next as usize >= n {
        return None;
    }
    let next = m.next as usize;
    let a = if next == 0 {
        path.from
    } else {
        path.waypoints[next - 1]
    };
    let b = path.waypoints[next];
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len = dx.hypot(dy);
    let (px, py) = (r.telemetry.pose.x - a.0, r.telemetry.pose.y - a.1);
    if len < 1e-9 {
        return Some(px.hypot(py));
    }
    Some((dx * py - dy * px) / len)
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_proto::MissionProgress;

    fn robot(x: f64, y: f64) -> RobotView {
        RobotView::at("robot_1", 1, "diff-drive", x, y, 0.0)
    }

    #[test]
    fn samples_are_spaced_bounded_to_a_minute_and_restart_when_time_goes_back() {
        let mut h = History::new(Instant::now());
        for i in 0..2000 {
            h.record(f64::from(i) * 0.05, &[robot(0.0, 0.0)]);
        }
        let r = h.robot("robot_1").unwrap();
        let n = r.samples.len();
        assert!((200..=SAMPLES).contains(&n), "{n}");
        let span = r.samples.back().unwrap().t - r.samples.front().unwrap().t;
        assert!(
            span <= HISTORY_SECONDS && span > HISTORY_SECONDS - 1.0,
            "{span}"
        );
        h.record(10.0, &[robot(0.0, 0.0)]);
        assert_eq!(h.robot("robot_1").unwrap().samples.len(), 1);
        h.record(11.0, &[]);
        assert!(h.robot("robot_1").is_none(), "gone robots are dropped");
    }

    #[test]
    fn ground_speed_is_distance_over_the_last_second() {
        let mut h = History::new(Instant::now());
        for i in 0..=20 {
            let t = f64::from(i) * 0.25;
            h.record(t, &[robot(0.3 * t, 0.0)]);
        }
        let pts = h.robot("robot_1").unwrap().points(Series::GroundSpeed, 5.0);
        assert!(!pts.is_empty());
        for (_, v) in &pts {
            assert!((v - 0.3).abs() < 1e-5, "{v}");
        }
        assert_eq!(pts.last().unwrap().0, 0.0);
    }

    #[test]
    fn cross_track_is_the_signed_distance_from_the_leg_being_flown() {
        let mut h = History::new(Instant::now());
        let mut r = robot(0.0, 0.0);
        let w = |x, y| Waypoint {
            x,
            y,
            z: 0.0,
            time: None,
        };
        h.mission_sent(std::slice::from_ref(&r), &[w(2.0, 0.0), w(2.0, 2.0)]);
        r.telemetry.pose.x = 1.0;
        r.telemetry.pose.y = 0.25;
        r.telemetry.mission = Some(MissionProgress {
            id: 1,
            next: 0,
            total: 2,
        });
        h.record(0.0, std::slice::from_ref(&r));
        r.telemetry.pose.x = 2.1;
        r.telemetry.pose.y = 1.0;
        r.telemetry.mission = Some(MissionProgress {
            id: 1,
            next: 1,
            total: 2,
        });
        h.record(1.0, std::slice::from_ref(&r));
        let xte = h.robot("robot_1").unwrap().points(Series::CrossTrack, 1.0);
        // Left of the first leg (east), right of the second (north).
        assert_eq!(xte.len(), 2);
        assert!(
            (xte[0].1 - 0.25).abs() < 1e-6 && (xte[1].1 + 0.1).abs() < 1e-6,
            "{xte:?}"
        );
        r.telemetry.mission = Some(MissionProgress {
            id: 1,
            next: 2,
            total: 2,
        });
        h.record(2.0, std::slice::from_ref(&r));
        assert_eq!(
            h.robot("robot_1")
                .unwrap()
                .points(Series::CrossTrack, 2.0)
                .len(),
            2,
            "arrived: no more cross-track"
        );
        assert!(h.knows_path("robot_1") && !h.knows_path("robot_2"));
    }
}
