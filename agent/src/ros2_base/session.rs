//! What the agent knows of its ROS 2 base, without I/O: samples heard go
//! in (odometry, transforms, battery, other writers on the base's
//! `cmd_vel`), and out come the pose and velocity for the agent core, the
//! `cmd_vel` to publish, whether the outputs must be held, and reports for
//! the operator. The vehicle ([`super::vehicle`]) moves the samples; tests
//! drive this directly.
//!
//! - Odometry: the pose (in the odometry's frame, or composed with
//!   `map_frame` -> that frame from the transforms) placed in the arena by
//!   the configured origin; the body twist as the measured velocity. A
//!   sample with a non-finite value or an orientation that is not a
//!   rotation is refused, counted and reported (at most every
//!   [`REPEAT`]), and the outputs are held for a second.
//! - Silence: no odometry for `odom_timeout` (from the start, or since the
//!   last) is reported once, naming the topic, and holds the outputs until
//!   odometry returns.
//! - Another writer on the base's `cmd_vel` (two controllers fighting for
//!   one base) is reported once per episode and holds the outputs while it
//!   is heard (and [`INTRUDER_QUIET`] after).

use std::time::Duration;

use mech_proto::{Pose, Telemetry};
use mech_ros2_dds::msgs::geometry::{Quaternion, Twist as RosTwist, Vector3};
use mech_ros2_dds::msgs::nav::{Odometry, TfMessage};
use mech_ros2_dds::msgs::sensor::BatteryState;

use super::config::Ros2Config;
use crate::runtime::Report;

/// The shortest time between two reports of refused samples.
pub const REPEAT: Duration = Duration::from_secs(5);

/// How long after the last sample of another writer on `cmd_vel` the
/// outputs stay held.
pub const INTRUDER_QUIET: Duration = Duration::from_secs(1);

/// A rotation's quaternion is within this of unit length.
const UNIT: f64 = 0.05;

/// A planar rigid transform: where a frame's origin is, and its heading.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Planar {
    pub x: f64,
    pub y: f64,
    pub heading: f64,
}

impl Planar {
    /// `self` then `inner`: a pose given in the frame `self` places.
    pub fn then(self, inner: Planar) -> Planar {
        let (s, c) = self.heading.sin_cos();
        Planar {
            x: self.x + c * inner.x - s * inner.y,
            y: self.y + s * inner.x + c * inner.y,
            heading: wrap(self.heading + inner.heading),
        }
    }

    fn from(position: &Vector3, rotation: &Quaternion) -> Option<Planar> {
        let values = [
            position.x, position.y, position.z, rotation.x, rotation.y, rotation.z, rotation.w,
        ];
        if !values.iter().all(|v| v.is_finite()) || (rotation.norm() - 1.0).abs() > UNIT {
            return None;
        }
        Some(Planar {
            x: position.x,
            y: position.y,
            heading: rotation.yaw(),
        })
    }
}

fn wrap(a: f64) -> f64 {
    a.sin().atan2(a.cos())
}

fn frame(name: &str) -> &str {
    name.trim_start_matches('/')
}

/// What the session counted of the samples it refused.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct BaseCounters {
    pub odometry: u64,
    pub odometry_refused: u64,
    pub battery_refused: u64,
    /// Samples of another writer on the base's `cmd_vel`.
    pub foreign_cmd_vel: u64,
}

/// Whether the odometry comes: when it last did, and whether its silence
/// was reported.
#[derive(Debug, Clone, Copy, Default)]
struct Silence {
    /// When the session started (the first check), for a base never heard.
    started: Option<Duration>,
    last_odometry: Option<Duration>,
    /// Reported lost and not back yet.
    lost: bool,
}

/// A localised robot's `map_frame` -> odometry frame.
#[derive(Debug, Clone, Default)]
struct Localisation {
    /// Empty: the odometry's own frame is the map.
    map_frame: String,
    map_to_odom: Option<Planar>,
    /// The odometry's own frame (its header's), once heard.
    odom_frame: Option<String>,
    /// Reported as waiting for `map_to_odom`.
    waiting: bool,
}

/// Another writer on the base's `cmd_vel`.
#[derive(Debug, Clone, Copy, Default)]
struct Intruder {
    last_heard: Option<Duration>,
    reported: bool,
}

/// The state of the base; see the module docs.
#[derive(Debug, Clone)]
pub struct BaseSession {
    odom_topic: String,
    cmd_vel_topic: String,
    origin: Planar,
    timeout: Duration,
    silence: Silence,
    map: Localisation,
    /// The newest pose not yet taken, arena frame.
    pose: Option<Pose>,
    /// The newest body twist and when it came.
    twist: Option<(mech_proto::Twist, Duration)>,
    battery: Option<f64>,
    last_refusal_report: Option<Duration>,
    intruder: Intruder,
    pub counters: BaseCounters,
}

impl BaseSession {
    pub fn new(config: &Ros2Config) -> BaseSession {
        BaseSession {
            odom_topic: config.resolve(&config.odom),
            cmd_vel_topic: config.resolve(&config.cmd_vel),
            origin: Planar {
                x: config.origin.x,
                y: config.origin.y,
                heading: config.origin.heading,
            },
            timeout: config.odom_timeout(),
            silence: Silence::default(),
            map: Localisation {
                map_frame: frame(&config.map_frame).to_string(),
                ..Localisation::default()
            },
            pose: None,
            twist: None,
            battery: None,
            last_refusal_report: None,
            intruder: Intruder::default(),
            counters: BaseCounters::default(),
        }
    }

    /// Takes in one odometry sample heard at `now`. `Err` says why it was
    /// refused (the outputs are then held for a second by the vehicle).
    pub fn odometry(&mut self, o: &Odometry, now: Duration) -> Result<Option<Report>, String> {
        let p = &o.pose.pose;
        let position = Vector3 {
            x: p.position.x,
            y: p.position.y,
            z: p.position.z,
        };
        let t = &o.twist.twist;
        let twist_ok = [t.linear.x, t.linear.y, t.linear.z, t.angular.z]
            .iter()
            .all(|v| v.is_finite());
        let Some(local) = Planar::from(&position, &p.orientation).filter(|_| twist_ok) else {
            self.counters.odometry_refused += 1;
            return Err(format!(
                "odometry on {} refused: not finite, or its orientation is not a rotation ({} refused)",
                self.odom_topic, self.counters.odometry_refused
            ));
        };
        self.counters.odometry += 1;
        self.silence.last_odometry = Some(now);
        self.map.odom_frame = Some(frame(&o.header.frame_id).to_string());
        self.twist = Some((
            mech_proto::Twist {
                vx: t.linear.x,
                vy: t.linear.y,
                vz: t.linear.z,
                wz: t.angular.z,
            },
            now,
        ));
        let placed = if self.map.map_frame.is_empty() {
            Some(self.origin.then(local))
        } else {
            self.map
                .map_to_odom
                .map(|m| self.origin.then(m).then(local))
        };
        let mut report = None;
        match placed {
            Some(pose) => {
                self.map.waiting = false;
                self.pose = Some(Pose {
                    x: pose.x,
                    y: pose.y,
                    z: position.z,
                    heading: pose.heading,
                });
            }
            None if !self.map.waiting => {
                self.map.waiting = true;
                report = Some(Report::warn(format!(
                    "waiting for {} -> {} on the transforms: no pose until then",
                    self.map.map_frame,
                    self.map.odom_frame.as_deref().unwrap_or("odom")
                )));
            }
            None => {}
        }
        Ok(report)
    }

    /// Takes in the transforms: `map_frame` -> the odometry's frame, if
    /// among them.
    pub fn transforms(&mut self, tf: &TfMessage) {
        if self.map.map_frame.is_empty() {
            return;
        }
        let odom = self.map.odom_frame.as_deref().unwrap_or("odom");
        for t in &tf.transforms {
            if frame(&t.header.frame_id) == self.map.map_frame
                && frame(&t.child_frame_id) == odom
                && let Some(p) = Planar::from(&t.transform.translation, &t.transform.rotation)
            {
                self.map.map_to_odom = Some(p);
            }
        }
    }

    /// Takes in a battery state: its charge fraction, NaN for unknown.
    pub fn battery(&mut self, b: &BatteryState) {
        let p = f64::from(b.percentage);
        if p.is_nan() {
            self.battery = None;
        } else if (0.0..=1.0).contains(&p) {
            self.battery = Some(p);
        } else {
            self.counters.battery_refused += 1;
        }
    }

    /// Another writer's sample on the base's `cmd_vel`, heard at `now`.
    pub fn foreign_cmd_vel(&mut self, writer: &str, now: Duration) -> Option<Report> {
        self.counters.foreign_cmd_vel += 1;
        self.intruder.last_heard = Some(now);
        if std::mem::replace(&mut self.intruder.reported, true) {
            return None;
        }
        Some(Report::error(format!(
            "another node publishes on {} (writer {writer}): two controllers drive the base; held at zero while it does",
            self.cmd_vel_topic
        )))
    }

    /// Reports a refused sample, at most every [`REPEAT`].
    pub fn refusal(&mut self, why: String, now: Duration) -> Option<Report> {
        let due = self
            .last_refusal_report
            .is_none_or(|t| now.saturating_sub(t) >= REPEAT);
        due.then(|| {
            self.last_refusal_report = Some(now);
            Report::warn(why)
        })
    }

    /// Once per control period: silence reported (once), and the end of
    /// silence or of another writer.
    pub fn check(&mut self, now: Duration) -> Vec<Report> {
        let started = *self.silence.started.get_or_insert(now);
        let mut out = Vec::new();
        let since = self.silence.last_odometry.unwrap_or(started);
        let silent = now.saturating_sub(since) > self.timeout;
        if silent && !self.silence.lost {
            self.silence.lost = true;
            out.push(Report::error(format!(
                "no odometry on {} for {:.0} s: is the base up, is ROS_DOMAIN_ID the same? Held at zero until it comes",
                self.odom_topic,
                self.timeout.as_secs_f64()
            )));
        } else if !silent && self.silence.lost {
            self.silence.lost = false;
            out.push(Report::info(format!(
                "odometry on {} again",
                self.odom_topic
            )));
        }
        if self.intruder.reported && !self.intruder_heard(now) {
            self.intruder.reported = false;
            out.push(Report::info(format!(
                "no other writer on {} now",
                self.cmd_vel_topic
            )));
        }
        out
    }

    fn intruder_heard(&self, now: Duration) -> bool {
        self.intruder
            .last_heard
            .is_some_and(|t| now.saturating_sub(t) <= INTRUDER_QUIET)
    }

    /// Why the outputs must be held at zero now, if they must.
    pub fn hold(&self, now: Duration) -> Option<String> {
        if self.silence.lost || self.silence.last_odometry.is_none() {
            Some(format!("no odometry on {}", self.odom_topic))
        } else if self.intruder_heard(now) {
            Some(format!("another writer on {}", self.cmd_vel_topic))
        } else {
            None
        }
    }

    /// The newest pose, arena frame, once (each is a fix).
    pub fn take_pose(&mut self) -> Option<Pose> {
        self.pose.take()
    }

    /// The newest body twist the base measured, and when it came.
    pub fn twist(&self) -> Option<(mech_proto::Twist, Duration)> {
        self.twist
    }

    /// Puts the base's battery into the telemetry.
    pub fn patch(&self, t: &mut Telemetry) {
        if self.battery.is_some() {
            t.battery = self.battery;
        }
    }

    /// The `cmd_vel` for a body twist (REP 103: x forward, y left, yaw
    /// rate about z).
    pub fn command(twist: &mech_proto::Twist) -> RosTwist {
        RosTwist {
            linear: Vector3 {
                x: twist.vx,
                y: twist.vy,
                z: twist.vz,
            },
            angular: Vector3 {
                x: 0.0,
                y: 0.0,
                z: twist.wz,
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_ros2_dds::msgs::geometry::TransformStamped;

    const MS: Duration = Duration::from_millis(1);

    fn config(text: &str) -> Ros2Config {
        let c: Ros2Config = toml::from_str(text).unwrap();
        c.validate().unwrap();
        c
    }

    fn odom(x: f64, y: f64, yaw: f64, vx: f64) -> Odometry {
        let mut o = Odometry::default();
        o.header.frame_id = "odom".into();
        o.child_frame_id = "base_link".into();
        o.pose.pose.position.x = x;
        o.pose.pose.position.y = y;
        o.pose.pose.orientation = Quaternion::from_yaw(yaw);
        o.twist.twist.linear.x = vx;
        o
    }

    fn close(a: f64, b: f64) -> bool {
        (a - b).abs() < 1e-9
    }

    #[test]
    fn odometry_is_placed_in_the_arena_by_the_origin() {
        let c = config(
            "namespace = \"/tb3_1\"\n[origin]\nx = 1.0\ny = -0.5\nheading = 1.5707963267948966",
        );
        let mut s = BaseSession::new(&c);
        assert_eq!(s.odometry(&odom(1.0, 0.0, 0.0, 0.2), 10 * MS), Ok(None));
        let p = s.take_pose().unwrap();
        // One metre along the odometry's x is along the arena's y.
        assert!(close(p.x, 1.0) && close(p.y, 0.5), "{p:?}");
        assert!(close(p.heading, std::f64::consts::FRAC_PI_2));
        assert_eq!(s.take_pose(), None, "each pose taken once");
        let (twist, at) = s.twist().unwrap();
        assert_eq!((twist.vx, at), (0.2, 10 * MS));
        assert_eq!(s.hold(10 * MS), None);
    }

    #[test]
    fn non_finite_odometry_and_a_zero_quaternion_are_refused() {
        let mut s = BaseSession::new(&config(""));
        let mut zero = odom(0.0, 0.0, 0.0, 0.0);
        zero.pose.pose.orientation = Quaternion {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            w: 0.0,
        };
        for bad in [
            odom(f64::NAN, 0.0, 0.0, 0.0),
            odom(0.0, 0.0, 0.0, f64::INFINITY),
            zero,
        ] {
            let why = s.odometry(&bad, MS).unwrap_err();
            assert!(why.contains("/odom") && why.contains("refused"), "{why}");
        }
        assert_eq!(s.take_pose(), None);
        assert_eq!(s.counters.odometry_refused, 3);
        // Reported once per REPEAT.
        assert!(s.refusal("x".into(), MS).is_some());
        assert!(s.refusal("x".into(), 2 * MS).is_none());
        assert!(s.refusal("x".into(), MS + REPEAT).is_some());
    }

    #[test]
    fn silence_is_reported_once_and_holds_until_odometry_returns() {
        let mut s = BaseSession::new(&config("namespace = \"/tb3_1\""));
        assert!(s.check(Duration::ZERO).is_empty());
        assert!(s.hold(Duration::ZERO).is_some(), "nothing heard yet");
        let lost = s.check(2100 * MS);
        assert_eq!(lost.len(), 1);
        assert!(
            lost[0].text.starts_with(
                "no odometry on /tb3_1/odom for 2 s: is the base up, is ROS_DOMAIN_ID the same?"
            ),
            "{}",
            lost[0].text
        );
        assert!(s.check(2200 * MS).is_empty(), "once");
        s.odometry(&odom(0.0, 0.0, 0.0, 0.0), 2300 * MS).unwrap();
        let back = s.check(2300 * MS);
        assert_eq!(back[0].text, "odometry on /tb3_1/odom again");
        assert_eq!(s.hold(2300 * MS), None);
        assert!(s.check(4400 * MS)[0].text.starts_with("no odometry"));
        assert!(s.hold(4400 * MS).is_some());
    }

    #[test]
    fn another_writer_on_cmd_vel_holds_while_heard() {
        let mut s = BaseSession::new(&config("namespace = \"/tb3_1\""));
        s.odometry(&odom(0.0, 0.0, 0.0, 0.0), Duration::ZERO)
            .unwrap();
        let r = s.foreign_cmd_vel("01.0f.aa", 10 * MS).unwrap();
        assert!(
            r.text.contains("/tb3_1/cmd_vel") && r.text.contains("01.0f.aa"),
            "{}",
            r.text
        );
        assert!(
            s.foreign_cmd_vel("01.0f.aa", 20 * MS).is_none(),
            "once an episode"
        );
        assert!(s.hold(500 * MS).unwrap().contains("another writer"));
        s.odometry(&odom(0.0, 0.0, 0.0, 0.0), 1100 * MS).unwrap();
        assert!(s.check(1100 * MS)[0].text.starts_with("no other writer"));
        assert_eq!(s.hold(1100 * MS), None);
        assert_eq!(s.counters.foreign_cmd_vel, 2);
    }

    #[test]
    fn a_localised_robot_waits_for_map_to_odom_then_composes_it() {
        let mut s = BaseSession::new(&config("map_frame = \"map\""));
        let waiting = s.odometry(&odom(1.0, 0.0, 0.0, 0.0), MS).unwrap().unwrap();
        assert!(waiting.text.contains("map -> odom"), "{}", waiting.text);
        assert_eq!(s.take_pose(), None);
        let mut t = TransformStamped::default();
        t.header.frame_id = "map".into();
        t.child_frame_id = "odom".into();
        t.transform.translation.x = 2.0;
        t.transform.rotation = Quaternion::from_yaw(std::f64::consts::PI);
        s.transforms(&TfMessage {
            transforms: vec![t],
        });
        assert_eq!(s.odometry(&odom(1.0, 0.0, 0.0, 0.0), 2 * MS), Ok(None));
        let p = s.take_pose().unwrap();
        assert!(close(p.x, 1.0) && p.y.abs() < 1e-9, "{p:?}");
    }

    #[test]
    fn battery_is_a_fraction_or_unknown() {
        let mut s = BaseSession::new(&config(""));
        let mut t = Telemetry::default();
        let mut b = BatteryState {
            percentage: 0.5,
            ..BatteryState::default()
        };
        s.battery(&b);
        s.patch(&mut t);
        assert_eq!(t.battery, Some(0.5));
        b.percentage = 42.0;
        s.battery(&b);
        assert_eq!(s.counters.battery_refused, 1);
        b.percentage = f32::NAN;
        s.battery(&b);
        let mut t = Telemetry::default();
        s.patch(&mut t);
        assert_eq!(t.battery, None);
    }
}
