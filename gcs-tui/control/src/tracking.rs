//! Vehicle-level tracking laws: turn a moving reference (position, heading,
//! world-frame velocity) and a member's measured pose into the command its
//! platform obeys.
//!
//! - Holonomic members (kiwi, quadcopter) get a body [`Twist`]: world-frame
//!   feed-forward velocity plus proportional position feedback, rotated into
//!   the body frame, and a yaw rate holding the reference heading.
//! - Non-holonomic members (differential drive) get a [`Twist`] with `vy = 0`
//!   from point-offset feedback linearisation: the desired world velocity `u`
//!   is imposed on a point `offset` metres ahead of the wheel axle, which gives
//!   `v = u . e(theta)` and `w = u . n(theta) / offset`. The position error of
//!   the axle centre drives `u`, so on a straight or gently curved reference the
//!   centre converges to the reference (not a point ahead of it) while the
//!   heading turns toward the direction of motion with time constant
//!   `offset / |u|`.
//!
//! Both laws saturate to the platform's speed and yaw-rate limits; the
//! non-holonomic law scales `v` and `w` together so the path curvature is kept.
//! A platform without twist falls back to [`VelocityHeading`].

use mech_proto::{Command, CommandKind, Stop, Twist, VelocityHeading};

use super::geometry::{norm, rotate, wrap_angle};
use super::{Kinematics, MemberState};

/// Where a member should be now and how that target moves (world frame).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Reference {
    /// Target position, m.
    pub x: f64,
    pub y: f64,
    /// Target heading, rad; holonomic members hold it, non-holonomic members
    /// ignore it (their heading follows their motion).
    pub heading: f64,
    /// Target velocity, m/s, world frame (feed-forward).
    pub vx: f64,
    pub vy: f64,
    /// Target yaw rate, rad/s (feed-forward for holonomic members).
    pub wz: f64,
}

impl Reference {
    /// Distance from the member's position to the target, m.
    pub fn position_error(&self, member: &MemberState) -> f64 {
        norm(self.x - member.pose.x, self.y - member.pose.y)
    }
}

/// Feedback gains of the tracking laws.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackingGains {
    /// Position error to velocity, 1/s.
    pub k_position: f64,
    /// Heading error to yaw rate, 1/s (holonomic members).
    pub k_heading: f64,
    /// Distance of the controlled point ahead of a non-holonomic member's axle,
    /// m. Smaller turns faster toward the direction of motion but asks for
    /// larger yaw rates.
    pub offset: f64,
}

impl Default for TrackingGains {
    fn default() -> Self {
        TrackingGains {
            k_position: 2.0,
            k_heading: 2.5,
            offset: 0.1,
        }
    }
}

/// The command that makes `member` track `reference`.
pub fn track(member: &MemberState, reference: &Reference, gains: &TrackingGains) -> Command {
    let p = &member.platform;
    let theta = member.pose.heading;
    let ux = reference.vx + gains.k_position * (reference.x - member.pose.x);
    let uy = reference.vy + gains.k_position * (reference.y - member.pose.y);
    match p.kinematics {
        Kinematics::Holonomic => {
            let speed = norm(ux, uy);
            let k = if speed > p.max_speed {
                p.max_speed / speed
            } else {
                1.0
            };
            let (ux, uy) = (ux * k, uy * k);
            let wz = (reference.wz + gains.k_heading * wrap_angle(reference.heading - theta))
                .clamp(-p.max_yaw_rate, p.max_yaw_rate);
            if p.accepts(CommandKind::Twist) {
                let (vx, vy) = rotate(ux, uy, -theta);
                Command::Twist(Twist {
                    vx,
                    vy,
                    vz: 0.0,
                    wz,
                })
            } else {
                velocity_heading_toward(member, ux, uy)
            }
        }
        Kinematics::NonHolonomic => {
            let (s, c) = theta.sin_cos();
            let offset = gains.offset.max(1e-3);
            let v = c * ux + s * uy;
            let w = (-s * ux + c * uy) / offset;
            let mut k: f64 = 1.0;
            if v.abs() > p.max_speed {
                k = k.min(p.max_speed / v.abs());
            }
            if w.abs() > p.max_yaw_rate {
                k = k.min(p.max_yaw_rate / w.abs());
            }
            if p.accepts(CommandKind::Twist) {
                Command::Twist(Twist {
                    vx: v * k,
                    vy: 0.0,
                    vz: 0.0,
                    wz: w * k,
                })
            } else {
                velocity_heading_toward(member, ux, uy)
            }
        }
    }
}

/// Fallback for platforms without twist: drive toward the desired velocity's
/// direction, at its speed once roughly facing it.
fn velocity_heading_toward(member: &MemberState, ux: f64, uy: f64) -> Command {
    let p = &member.platform;
    if !p.accepts(CommandKind::VelocityHeading) {
        return Command::Stop(Stop {});
    }
    let speed = norm(ux, uy).min(p.max_speed);
    if speed < 1e-6 {
        return Command::VelocityHeading(VelocityHeading {
            speed: 0.0,
            heading: member.pose.heading,
        });
    }
    let heading = uy.atan2(ux);
    let facing = wrap_angle(heading - member.pose.heading).cos().max(0.0);
    Command::VelocityHeading(VelocityHeading {
        speed: speed * facing,
        heading,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::PlatformLimits;
    use mech_proto::{Pose, Velocity};

    fn member(kinematics: Kinematics, heading: f64) -> MemberState {
        MemberState {
            robot: "r".into(),
            platform: PlatformLimits {
                kinematics,
                capabilities: vec![CommandKind::Twist, CommandKind::VelocityHeading],
                max_speed: 0.5,
                max_yaw_rate: 2.0,
            },
            pose: Pose {
                heading,
                ..Pose::default()
            },
            velocity: Velocity::default(),
            stamp: 0.0,
        }
    }

    #[test]
    fn holonomic_moves_sideways_in_body_frame() {
        let m = member(Kinematics::Holonomic, std::f64::consts::FRAC_PI_2);
        // Target straight ahead in the world (+x) is to the robot's right.
        let r = Reference {
            x: 0.1,
            ..Reference::default()
        };
        let Command::Twist(t) = track(&m, &r, &TrackingGains::default()) else {
            panic!("twist expected")
        };
        assert!(t.vx.abs() < 1e-9);
        assert!(t.vy < 0.0);
        assert!(t.wz < 0.0, "turns back to heading 0");
    }

    #[test]
    fn diff_drive_never_slides_and_turns_toward_target() {
        let m = member(Kinematics::NonHolonomic, 0.0);
        let r = Reference {
            x: 0.0,
            y: 1.0,
            ..Reference::default()
        };
        let Command::Twist(t) = track(&m, &r, &TrackingGains::default()) else {
            panic!("twist expected")
        };
        assert_eq!(t.vy, 0.0);
        assert!(t.wz > 0.0, "target on the left: turn left");
        assert!(t.wz.abs() <= 2.0 + 1e-12, "yaw rate saturated");
    }

    #[test]
    fn diff_drive_saturation_keeps_curvature() {
        let m = member(Kinematics::NonHolonomic, 0.3);
        let r = Reference {
            x: 10.0,
            y: 4.0,
            ..Reference::default()
        };
        let g = TrackingGains::default();
        let Command::Twist(t) = track(&m, &r, &g) else {
            panic!("twist expected")
        };
        let (s, c) = 0.3f64.sin_cos();
        let (ux, uy) = (10.0 * g.k_position, 4.0 * g.k_position);
        let curvature = (-s * ux + c * uy) / g.offset / (c * ux + s * uy);
        assert!((t.wz / t.vx - curvature).abs() < 1e-9);
        assert!(t.vx <= 0.5 + 1e-12 && t.wz.abs() <= 2.0 + 1e-12);
    }

    #[test]
    fn velocity_heading_fallback_without_twist() {
        let mut m = member(Kinematics::NonHolonomic, 0.0);
        m.platform.capabilities = vec![CommandKind::VelocityHeading];
        let r = Reference {
            x: 1.0,
            y: 1.0,
            ..Reference::default()
        };
        let Command::VelocityHeading(v) = track(&m, &r, &TrackingGains::default()) else {
            panic!("velocity-heading expected")
        };
        assert!((v.heading - std::f64::consts::FRAC_PI_4).abs() < 1e-9);
        assert!(v.speed > 0.0 && v.speed <= 0.5);
    }
}
