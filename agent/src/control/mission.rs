//! Waypoint navigation for one mission: arrival radius, optional arrival
//! times (speed chosen to meet them), looping, progress reporting.

use std::time::Duration;

use mech_proto::{Mission, MissionProgress, Pose, Twist, Waypoint};

use super::{Gains, drive_factor};
use crate::platform::{Limits, Platform};
use mech_proto::wrap_angle;

/// A mission being flown or driven, with its progress.
#[derive(Debug, Clone, PartialEq)]
pub struct MissionRun {
    pub mission: Mission,
    /// Index of the waypoint being approached; `== len` when finished.
    pub next: usize,
    /// Agent time the mission first ran; waypoint times count from here.
    started: Option<Duration>,
    /// Where the current leg began, for the arrival-time speed.
    leg_start: Option<Duration>,
    /// Paused by an e-stop release until re-sent or re-routed.
    pub paused: bool,
}

impl MissionRun {
    pub fn new(mission: Mission) -> MissionRun {
        let next = (mission.start_index as usize).min(mission.waypoints.len());
        MissionRun {
            mission,
            next,
            started: None,
            leg_start: None,
            paused: false,
        }
    }

    pub fn finished(&self) -> bool {
        self.next >= self.mission.waypoints.len()
    }

    pub fn progress(&self) -> MissionProgress {
        MissionProgress {
            id: self.mission.id,
            next: self.next as u32,
            total: self.mission.waypoints.len() as u32,
        }
    }

    /// One control period: the body twist toward the current waypoint,
    /// advancing past waypoints within the arrival radius.
    pub fn step(
        &mut self,
        pose: &Pose,
        now: Duration,
        platform: &dyn Platform,
        gains: &Gains,
    ) -> Twist {
        // Arrival times of this period count from when the mission (or its
        // lap) had started before any waypoint was passed in it.
        let started = *self.started.get_or_insert(now);
        self.leg_start.get_or_insert(now);
        let flies = platform.flies();
        if !self.pass_reached(pose, now, flies) || self.paused {
            return Twist::default();
        }
        let Some(wp) = self.mission.waypoints.get(self.next) else {
            return Twist::default();
        };
        let limits = platform.limits();
        let (dx, dy, dz) = offset_to(wp, pose, flies);
        let horizontal = dx.hypot(dy);
        let dist = (horizontal * horizontal + dz * dz).sqrt();
        let speed = leg_speed(wp, dist, started, now, &limits, gains);
        let bearing = dy.atan2(dx);
        if platform.holonomic() {
            let (s, c) = (bearing - pose.heading).sin_cos();
            let (h_speed, v_speed) = if dist > 0.0 {
                (speed * horizontal / dist, speed * dz / dist)
            } else {
                (0.0, 0.0)
            };
            Twist {
                vx: h_speed * c,
                vy: h_speed * s,
                vz: v_speed.clamp(-limits.max_climb, limits.max_climb),
                wz: 0.0,
            }
        } else {
            let err = wrap_angle(bearing - pose.heading);
            let wz = (gains.heading * err).clamp(-limits.max_yaw_rate, limits.max_yaw_rate);
            Twist {
                vx: speed * drive_factor(err, gains.turn_in_place),
                vy: 0.0,
                vz: 0.0,
                wz,
            }
        }
    }

    /// Moves `next` past every waypoint already within the arrival radius
    /// (none while paused); `false` once no waypoint is left to approach.
    fn pass_reached(&mut self, pose: &Pose, now: Duration, flies: bool) -> bool {
        // At most one lap of advances per period: a looped mission whose
        // waypoints all lie inside the radius must not spin here forever.
        for _ in 0..=self.mission.waypoints.len() {
            let Some(wp) = self.mission.waypoints.get(self.next) else {
                return false;
            };
            let (dx, dy, dz) = offset_to(wp, pose, flies);
            let dist = (dx * dx + dy * dy + dz * dz).sqrt();
            if dist > self.mission.arrival_radius || self.paused {
                break;
            }
            self.next += 1;
            self.leg_start = Some(now);
            if self.finished() && self.mission.looped && !self.mission.waypoints.is_empty() {
                self.next = 0;
                self.started = Some(now);
            }
            if self.finished() {
                return false;
            }
        }
        true
    }
}

/// From the robot to the waypoint, m, world frame; no height for a robot
/// that does not fly.
fn offset_to(wp: &Waypoint, pose: &Pose, flies: bool) -> (f64, f64, f64) {
    let dz = if flies { wp.z - pose.z } else { 0.0 };
    (wp.x - pose.x, wp.y - pose.y, dz)
}

/// Speed toward `wp`, `dist` away, at `now`: cruise, or the remaining
/// distance over the time left until `wp`'s arrival time (counted from
/// `started`); slowing down near the waypoint so it is not overshot.
fn leg_speed(
    wp: &Waypoint,
    dist: f64,
    started: Duration,
    now: Duration,
    limits: &Limits,
    gains: &Gains,
) -> f64 {
    let cruise = limits.max_speed * gains.cruise_fraction;
    let speed = match wp.time {
        Some(t) => {
            // In seconds, not `Duration`s: any finite time is counted.
            let left = started.as_secs_f64() + t - now.as_secs_f64();
            if left > 1e-3 {
                dist / left
            } else {
                limits.max_speed
            }
        }
        None => cruise,
    };
    speed.min(gains.position * dist).min(limits.max_speed)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::platform::PlatformSpec;
    use mech_proto::Waypoint;

    fn mission(points: &[(f64, f64)], looped: bool) -> Mission {
        Mission {
            id: 1,
            waypoints: points
                .iter()
                .map(|&(x, y)| Waypoint {
                    x,
                    y,
                    z: 0.0,
                    time: None,
                })
                .collect(),
            looped,
            arrival_radius: 0.05,
            start_index: 0,
        }
    }

    #[test]
    fn advances_within_radius_and_loops() {
        let p = PlatformSpec::diff_drive().build();
        let g = Gains::default();
        let mut run = MissionRun::new(mission(&[(0.0, 0.0), (1.0, 0.0)], true));
        let t = run.step(&Pose::default(), Duration::ZERO, p.as_ref(), &g);
        assert_eq!(run.next, 1);
        assert!(t.vx > 0.0);
        run.step(
            &Pose {
                x: 0.99,
                ..Pose::default()
            },
            Duration::ZERO,
            p.as_ref(),
            &g,
        );
        assert_eq!(run.next, 0, "looped back to the first waypoint");
        let mut once = MissionRun::new(mission(&[(0.0, 0.0)], false));
        assert_eq!(
            once.step(&Pose::default(), Duration::ZERO, p.as_ref(), &g),
            Twist::default()
        );
        assert!(once.finished());
        assert_eq!(
            once.progress(),
            MissionProgress {
                id: 1,
                next: 1,
                total: 1
            }
        );
    }

    #[test]
    fn arrival_time_sets_the_speed() {
        let p = PlatformSpec::kiwi().build();
        let g = Gains {
            position: 100.0,
            ..Gains::default()
        };
        let mut m = mission(&[(2.0, 0.0)], false);
        m.waypoints[0].time = Some(10.0);
        let mut run = MissionRun::new(m);
        let t = run.step(&Pose::default(), Duration::ZERO, p.as_ref(), &g);
        assert!((t.vx - 0.2).abs() < 1e-9, "2 m in 10 s: {t:?}");
        let late = run.step(&Pose::default(), Duration::from_secs(9), p.as_ref(), &g);
        assert!(
            (late.vx - p.limits().max_speed).abs() < 1e-9,
            "late: as fast as allowed"
        );
    }

    /// An arrival time longer than a `Duration` holds (the message layer
    /// refuses it, but a mission may come from elsewhere) only slows the
    /// robot down to nearly nothing; it never stops the agent.
    #[test]
    fn an_arrival_time_beyond_any_clock_is_only_slow() {
        let p = PlatformSpec::kiwi().build();
        let g = Gains {
            position: 100.0,
            ..Gains::default()
        };
        for t in [1e20, f64::MAX] {
            let mut m = mission(&[(2.0, 0.0)], false);
            m.waypoints[0].time = Some(t);
            let mut run = MissionRun::new(m);
            let twist = run.step(&Pose::default(), Duration::from_secs(5), p.as_ref(), &g);
            assert!(twist.vx >= 0.0 && twist.vx < 1e-9, "{t}: {twist:?}");
        }
    }
}
