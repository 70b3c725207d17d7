//! The desired cluster pose and how it moves: held, at a cluster-frame
//! velocity, or along cluster waypoints on a trapezoidal speed profile
//! (centroid and heading each), slowed so no slot outruns its member, and
//! passed on to the next waypoint once the measured centroid is there.

use mech_proto::{ClusterPose, ClusterVelocity};

use super::{ClusterConfig, ClusterMotion, ClusterWaypoint};
use crate::ControlEvent;
use crate::MemberState;
use crate::geometry::{norm, rotate, wrap_angle};

pub(super) const ZERO_VELOCITY: ClusterVelocity = ClusterVelocity {
    vx: 0.0,
    vy: 0.0,
    wz: 0.0,
    scale_rate: 0.0,
};

/// The cluster pose being tracked, what it is doing, and the state of its
/// speed profiles.
#[derive(Debug, Clone)]
pub(super) struct DesiredPose {
    motion: ClusterMotion,
    /// `None` until the first member reports.
    pose: Option<ClusterPose>,
    /// Current centroid speed along a waypoint leg (for the acceleration ramp).
    path_speed: f64,
    /// Current heading rate toward a waypoint heading.
    turn_rate: f64,
    /// Desired velocity applied in the last step (cluster frame).
    velocity: ClusterVelocity,
    /// The desired pose has been set or moved by the operator; from then on
    /// membership changes no longer re-centre it.
    anchored: bool,
}

impl DesiredPose {
    /// Holding, nowhere yet.
    pub fn new() -> DesiredPose {
        DesiredPose {
            motion: ClusterMotion::Hold,
            pose: None,
            path_speed: 0.0,
            turn_rate: 0.0,
            velocity: ZERO_VELOCITY,
            anchored: false,
        }
    }

    pub fn motion(&self) -> &ClusterMotion {
        &self.motion
    }

    pub fn pose(&self) -> Option<ClusterPose> {
        self.pose
    }

    /// The velocity applied in the last step (cluster frame).
    pub fn velocity(&self) -> ClusterVelocity {
        self.velocity
    }

    /// `(next, total)` while following cluster waypoints.
    pub fn waypoint(&self) -> Option<(usize, usize)> {
        match &self.motion {
            ClusterMotion::Waypoints { list, next, .. } => Some((*next, list.len())),
            _ => None,
        }
    }

    pub fn set_velocity(&mut self, velocity: ClusterVelocity) {
        self.motion = ClusterMotion::Velocity(velocity);
        self.anchored = true;
    }

    pub fn set_waypoints(&mut self, list: Vec<ClusterWaypoint>, looped: bool) {
        self.motion = ClusterMotion::Waypoints {
            list,
            next: 0,
            looped,
        };
        self.anchored = true;
        self.path_speed = 0.0;
        self.turn_rate = 0.0;
    }

    pub fn hold(&mut self) {
        self.motion = ClusterMotion::Hold;
        self.path_speed = 0.0;
        self.turn_rate = 0.0;
    }

    /// Until the cluster is first told to move (or placed), its pose is
    /// wherever its members are: members joining one by one (routed in turn,
    /// `regrouped`) re-centre it instead of gathering round the first to
    /// report.
    pub fn place_until_anchored(&mut self, regrouped: bool, fresh: &[&MemberState]) {
        if (self.pose.is_none() || (!self.anchored && regrouped)) && !fresh.is_empty() {
            self.pose = Some(initial_pose(fresh));
        }
    }

    /// Integrates the desired pose over `dt` at the velocity the motion asks
    /// for, limited so no slot (the farthest `max_offset` from the centroid)
    /// moves faster than `speed_limit` by feed-forward; the new pose, `None`
    /// while there is none yet.
    pub fn advance(
        &mut self,
        dt: f64,
        max_offset: f64,
        speed_limit: f64,
        cfg: &ClusterConfig,
    ) -> Option<ClusterPose> {
        let mut pose = self.pose?;
        let v = self.motion_velocity(&pose, dt, cfg);
        let v = self.limit_slot_speed(v, pose.scale, max_offset, speed_limit);
        self.velocity = integrate(&mut pose, v, dt, cfg);
        self.snap_to_waypoint(&mut pose);
        self.pose = Some(pose);
        Some(pose)
    }

    /// The cluster-frame velocity the current motion asks for, before any
    /// speed limit.
    fn motion_velocity(
        &mut self,
        desired: &ClusterPose,
        dt: f64,
        cfg: &ClusterConfig,
    ) -> ClusterVelocity {
        let w = match &mut self.motion {
            ClusterMotion::Hold => return ZERO_VELOCITY,
            ClusterMotion::Velocity(v) => return *v,
            ClusterMotion::Waypoints { list, next, looped } => {
                if *next >= list.len() && *looped && !list.is_empty() {
                    *next = 0;
                }
                match list.get(*next) {
                    Some(w) => *w,
                    None => return ZERO_VELOCITY,
                }
            }
        };
        self.velocity_toward(&w, desired, dt, cfg)
    }

    /// Velocity along the leg to `w`: the centroid and the heading each on a
    /// trapezoidal profile that arrives without overshoot.
    fn velocity_toward(
        &mut self,
        w: &ClusterWaypoint,
        desired: &ClusterPose,
        dt: f64,
        cfg: &ClusterConfig,
    ) -> ClusterVelocity {
        let (dx, dy) = (w.x - desired.x, w.y - desired.y);
        let dist = norm(dx, dy);
        let speed = ramp(
            &mut self.path_speed,
            cfg.max_accel,
            cfg.cruise_speed,
            dist,
            dt,
        );
        let (wx, wy) = if dist > 1e-12 {
            (speed * dx / dist, speed * dy / dist)
        } else {
            (0.0, 0.0)
        };
        let turn = w.heading.map_or(0.0, |h| wrap_angle(h - desired.heading));
        let rate = ramp(
            &mut self.turn_rate,
            cfg.max_yaw_accel,
            cfg.max_yaw_rate,
            turn.abs(),
            dt,
        );
        let (cx, cy) = rotate(wx, wy, -desired.heading);
        ClusterVelocity {
            vx: cx,
            vy: cy,
            wz: rate * turn.signum(),
            scale_rate: 0.0,
        }
    }

    /// Scales `v` down so the fastest slot (`max_offset` from the centroid at
    /// `scale`) moves no faster than `speed_limit`; the leg profiles slow
    /// down with it, so they resume from the speed really used.
    fn limit_slot_speed(
        &mut self,
        v: ClusterVelocity,
        scale: f64,
        max_offset: f64,
        speed_limit: f64,
    ) -> ClusterVelocity {
        let slot_speed = norm(v.vx, v.vy) + (v.wz.abs() * scale + v.scale_rate.abs()) * max_offset;
        if slot_speed > speed_limit && slot_speed > 0.0 {
            let k = (speed_limit / slot_speed).max(0.0);
            self.path_speed *= k;
            self.turn_rate *= k;
            return ClusterVelocity {
                vx: v.vx * k,
                vy: v.vy * k,
                wz: v.wz * k,
                scale_rate: v.scale_rate * k,
            };
        }
        v
    }

    /// Puts the desired pose exactly on the waypoint once it is there to
    /// rounding, so arrival can be checked with equality.
    fn snap_to_waypoint(&self, desired: &mut ClusterPose) {
        let ClusterMotion::Waypoints { list, next, .. } = &self.motion else {
            return;
        };
        let Some(w) = list.get(*next) else { return };
        let at_position = norm(w.x - desired.x, w.y - desired.y) < 1e-9;
        let at_heading = w
            .heading
            .is_none_or(|h| wrap_angle(h - desired.heading).abs() < 1e-6);
        if at_position && at_heading {
            desired.x = w.x;
            desired.y = w.y;
            if let Some(h) = w.heading {
                desired.heading = wrap_angle(h);
            }
        }
    }

    /// Moves to the next waypoint once the desired pose sits on the current
    /// one and the `measured` centroid is within `arrival_radius`.
    pub fn check_arrival(
        &mut self,
        measured: Option<&ClusterPose>,
        arrival_radius: f64,
        events: &mut Vec<ControlEvent>,
    ) {
        let (Some(desired), Some(measured)) = (self.pose, measured) else {
            return;
        };
        let ClusterMotion::Waypoints { list, next, looped } = &mut self.motion else {
            return;
        };
        let Some(w) = list.get(*next) else { return };
        let settled = desired.x == w.x
            && desired.y == w.y
            && w.heading
                .is_none_or(|h| (wrap_angle(h) - desired.heading).abs() < 1e-9);
        if settled && norm(measured.x - w.x, measured.y - w.y) <= arrival_radius {
            events.push(ControlEvent::WaypointReached { index: *next });
            *next += 1;
            self.path_speed = 0.0;
            self.turn_rate = 0.0;
            if *next >= list.len() {
                if *looped {
                    *next = 0;
                } else {
                    events.push(ControlEvent::Finished);
                }
            }
        }
    }
}

/// One step of a trapezoidal profile toward a point `remaining` away:
/// `speed` (kept between steps) grows by `accel` up to `top`, but no faster
/// than still stops at the point, and the step never passes the point.
fn ramp(speed: &mut f64, accel: f64, top: f64, remaining: f64, dt: f64) -> f64 {
    let reachable = (2.0 * accel * remaining).sqrt();
    *speed = (*speed + accel * dt).min(top).min(reachable);
    if dt > 0.0 {
        speed.min(remaining / dt)
    } else {
        0.0
    }
}

/// Moves `desired` on by `v` (cluster frame) for `dt`, keeping the scale
/// within its bounds; a scale rate that hits a bound is not applied and comes
/// back as zero.
fn integrate(
    desired: &mut ClusterPose,
    mut v: ClusterVelocity,
    dt: f64,
    cfg: &ClusterConfig,
) -> ClusterVelocity {
    let (wx, wy) = rotate(v.vx, v.vy, desired.heading);
    desired.x += wx * dt;
    desired.y += wy * dt;
    desired.heading = wrap_angle(desired.heading + v.wz * dt);
    let scale = (desired.scale + v.scale_rate * dt).clamp(cfg.min_scale, cfg.max_scale);
    if scale != desired.scale + v.scale_rate * dt {
        v.scale_rate = 0.0;
    }
    desired.scale = scale;
    v
}

/// Starting cluster pose: centroid and circular-mean heading of the members.
fn initial_pose(fresh: &[&MemberState]) -> ClusterPose {
    let n = fresh.len() as f64;
    let x = fresh.iter().map(|s| s.pose.x).sum::<f64>() / n;
    let y = fresh.iter().map(|s| s.pose.y).sum::<f64>() / n;
    let s: f64 = fresh.iter().map(|m| m.pose.heading.sin()).sum();
    let c: f64 = fresh.iter().map(|m| m.pose.heading.cos()).sum();
    let heading = if norm(s, c) > 1e-9 { s.atan2(c) } else { 0.0 };
    ClusterPose {
        x,
        y,
        heading,
        scale: 1.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(x: f64, y: f64) -> ClusterPose {
        ClusterPose {
            x,
            y,
            heading: 0.0,
            scale: 1.0,
        }
    }

    #[test]
    fn a_profile_never_passes_its_point() {
        let mut speed = 0.0;
        let mut left = 0.3;
        for _ in 0..200 {
            let v = ramp(&mut speed, 0.25, 0.25, left, 0.05);
            assert!(v * 0.05 <= left + 1e-12);
            left -= v * 0.05;
        }
        assert!(left < 1e-6, "arrived: {left}");
    }

    #[test]
    fn a_waypoint_list_is_followed_to_its_end_and_reported_finished() {
        let cfg = ClusterConfig::default();
        let mut d = DesiredPose::new();
        assert_eq!(d.advance(0.05, 0.0, 1.0, &cfg), None, "no pose yet");
        d.pose = Some(pose(0.0, 0.0));
        let w = ClusterWaypoint {
            x: 0.5,
            y: 0.0,
            heading: None,
        };
        d.set_waypoints(vec![w], false);
        assert_eq!(d.waypoint(), Some((0, 1)));
        let mut events = Vec::new();
        for _ in 0..200 {
            let p = d.advance(0.05, 0.0, 1.0, &cfg).unwrap();
            d.check_arrival(Some(&p), cfg.arrival_radius, &mut events);
        }
        assert_eq!(d.pose(), Some(pose(0.5, 0.0)), "snapped onto the waypoint");
        assert_eq!(
            events,
            [
                ControlEvent::WaypointReached { index: 0 },
                ControlEvent::Finished
            ]
        );
        assert_eq!(d.waypoint(), Some((1, 1)));
    }

    #[test]
    fn the_slot_speed_limit_slows_the_whole_motion() {
        let cfg = ClusterConfig::default();
        let mut d = DesiredPose::new();
        d.pose = Some(pose(0.0, 0.0));
        d.set_velocity(ClusterVelocity {
            vx: 0.0,
            vy: 0.0,
            wz: 1.0,
            scale_rate: 0.0,
        });
        // A slot 2 m out at 1 rad/s would move at 2 m/s: limited to 0.5.
        d.advance(0.1, 2.0, 0.5, &cfg);
        assert!((d.velocity().wz - 0.25).abs() < 1e-12, "{:?}", d.velocity());
    }
}
