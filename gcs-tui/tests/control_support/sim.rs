//! Stepped-time kinematic robots for the controller tests: a platform obeys
//! twist, velocity-heading and stop within its limits, with a first-order
//! velocity lag, and zeroes its motion when no command arrived for the
//! failsafe timeout (as the agent does on a silent channel).

#![allow(dead_code)]

use mech_gcs::control::{Kinematics, MemberState, PlatformLimits, wrap_angle};
use mech_proto::{Command, CommandKind, Pose, Velocity};

pub const FAILSAFE_TIMEOUT: f64 = 0.5;
const VELOCITY_LAG: f64 = 0.1;
const HEADING_GAIN: f64 = 3.0;

pub fn limits(platform: &str) -> PlatformLimits {
    let capabilities = vec![
        CommandKind::Twist,
        CommandKind::VelocityHeading,
        CommandKind::Stop,
    ];
    let (max_speed, max_yaw_rate) = match platform {
        "diff-drive" => (0.5, 3.0),
        "kiwi" => (0.6, 3.0),
        _ => (1.0, 2.0),
    };
    PlatformLimits {
        kinematics: Kinematics::of_platform(platform, &capabilities),
        capabilities,
        max_speed,
        max_yaw_rate,
    }
}

#[derive(Debug, Clone)]
pub struct SimBot {
    pub name: String,
    pub limits: PlatformLimits,
    pub pose: Pose,
    /// Body-frame velocity being applied: vx, vy, wz.
    body: (f64, f64, f64),
    command: Option<Command>,
    last_command: f64,
    /// When false the robot sends no telemetry (radio fault).
    pub reporting: bool,
    pub last_report: f64,
}

impl SimBot {
    pub fn new(name: &str, platform: &str, x: f64, y: f64, heading: f64) -> SimBot {
        SimBot {
            name: name.into(),
            limits: limits(platform),
            pose: Pose {
                x,
                y,
                z: 0.0,
                heading,
            },
            body: (0.0, 0.0, 0.0),
            command: None,
            last_command: f64::NEG_INFINITY,
            reporting: true,
            last_report: 0.0,
        }
    }

    pub fn apply(&mut self, now: f64, command: &Command) {
        self.command = Some(command.clone());
        self.last_command = now;
    }

    /// Whether the failsafe holds the robot (no command for the timeout).
    pub fn failsafe(&self, now: f64) -> bool {
        now - self.last_command > FAILSAFE_TIMEOUT
    }

    pub fn speed(&self) -> f64 {
        self.body.0.hypot(self.body.1)
    }

    pub fn step(&mut self, now: f64, dt: f64) {
        let l = &self.limits;
        let target = match (&self.command, self.failsafe(now)) {
            (_, true) | (None, _) => (0.0, 0.0, 0.0),
            (Some(Command::Twist(t)), _) => {
                let vy = if l.kinematics == Kinematics::Holonomic {
                    t.vy
                } else {
                    0.0
                };
                let s = t.vx.hypot(vy);
                let k = if s > l.max_speed {
                    l.max_speed / s
                } else {
                    1.0
                };
                (
                    t.vx * k,
                    vy * k,
                    t.wz.clamp(-l.max_yaw_rate, l.max_yaw_rate),
                )
            }
            (Some(Command::VelocityHeading(v)), _) => {
                let w = HEADING_GAIN * wrap_angle(v.heading - self.pose.heading);
                (
                    v.speed.clamp(-l.max_speed, l.max_speed),
                    0.0,
                    w.clamp(-l.max_yaw_rate, l.max_yaw_rate),
                )
            }
            (Some(_), _) => (0.0, 0.0, 0.0),
        };
        let a = (dt / VELOCITY_LAG).min(1.0);
        self.body.0 += a * (target.0 - self.body.0);
        self.body.1 += a * (target.1 - self.body.1);
        self.body.2 += a * (target.2 - self.body.2);
        let (s, c) = self.pose.heading.sin_cos();
        self.pose.x += (c * self.body.0 - s * self.body.1) * dt;
        self.pose.y += (s * self.body.0 + c * self.body.1) * dt;
        self.pose.heading = wrap_angle(self.pose.heading + self.body.2 * dt);
        if self.reporting {
            self.last_report = now + dt;
        }
    }

    /// What the controller knows: the last reported state.
    pub fn state(&self) -> MemberState {
        let (s, c) = self.pose.heading.sin_cos();
        MemberState {
            robot: self.name.clone(),
            platform: self.limits.clone(),
            pose: self.pose,
            velocity: Velocity {
                vx: c * self.body.0 - s * self.body.1,
                vy: s * self.body.0 + c * self.body.1,
                vz: 0.0,
                wz: self.body.2,
            },
            stamp: self.last_report,
        }
    }
}

/// Robots stepped together: `physics_steps` integration steps per control
/// period.
#[derive(Debug)]
pub struct World {
    pub robots: Vec<SimBot>,
    pub now: f64,
    /// Last state each robot reported (frozen once it stops reporting).
    reported: Vec<MemberState>,
}

impl World {
    pub fn new(robots: Vec<SimBot>) -> World {
        let reported = robots.iter().map(SimBot::state).collect();
        World {
            robots,
            now: 0.0,
            reported,
        }
    }

    pub fn robot(&mut self, name: &str) -> &mut SimBot {
        self.robots
            .iter_mut()
            .find(|r| r.name == name)
            .expect("robot exists")
    }

    /// Telemetry as received: each robot's last report.
    pub fn states(&self) -> Vec<MemberState> {
        self.reported.clone()
    }

    pub fn deliver(&mut self, robot: &str, command: &Command) {
        let now = self.now;
        self.robot(robot).apply(now, command);
    }

    /// Advances `period` seconds in `substeps` steps and collects telemetry.
    pub fn advance(&mut self, period: f64, substeps: usize) {
        let dt = period / substeps as f64;
        for _ in 0..substeps {
            for r in &mut self.robots {
                r.step(self.now, dt);
            }
            self.now += dt;
        }
        for (r, rep) in self.robots.iter().zip(self.reported.iter_mut()) {
            if r.reporting {
                *rep = r.state();
            }
        }
    }
}
