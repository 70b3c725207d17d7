//! The actuator outputs of each control period, and the one place they are
//! made.
//!
//! [`Actuation::obey`] is the last step of every command the robot obeys
//! before its actuators: whatever the mode (raw actuators, steering and
//! throttle, twist, velocity-heading, waypoints), whatever sent it (any
//! controller on the routed channel, an onboard mission), and whatever the
//! vehicle (a [`Platform`] driven directly, wheel speed loops, or an
//! autopilot flown by [`crate::autopilot`], which turns these outputs into
//! its setpoints). There the failsafe's verdict is applied, the controller's
//! [`Demand`] is taken (at the level its mode works at, before the platform
//! turns it into outputs), and the platform and the wheel speed loops make
//! the outputs. The robot's [`Sensors`] are at hand there: the position
//! estimate, and its velocity ([`Sensors::motion`]), so the fleet safety
//! layer ([`Safety`]) limits what the robot obeys, whoever sent it, in
//! that one function: on the platform's outputs for the demand, before
//! the wheel speed loops.

use std::time::Duration;

use mech_proto::{FailsafeState, Pose};

use super::fleet_safety::Safety;
use super::sensors::Sensors;
use super::step::Step;
use crate::control::{Controller, MissionRun, Mode};
use crate::failsafe::{Failsafe, FailsafeConfig};
use crate::platform::Platform;
use crate::safety::Vec2;
use crate::wheels::Wheels;

/// What the failsafe lets the robot do this period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Permit {
    /// Obey the controller.
    Drive,
    /// Outputs zero, the controller keeping its mode: an onboard mission
    /// waiting for a link, which goes on when the router is heard again.
    Wait,
    /// Outputs zero and the controller idle: the next accepted command (or
    /// a mission resumed on registering again) starts motion again.
    Stop,
}

/// The failsafe's verdicts and the outputs of the last period.
#[derive(Debug)]
pub(crate) struct Actuation {
    failsafe: Failsafe,
    /// One per motor, each in `[-1, 1]`.
    outputs: Vec<f64>,
}

impl Actuation {
    pub(crate) fn new(config: FailsafeConfig, motors: usize) -> Actuation {
        Actuation {
            failsafe: Failsafe::new(config),
            outputs: vec![0.0; motors],
        }
    }

    /// The outputs of the last period.
    pub(crate) fn outputs(&self) -> &[f64] {
        &self.outputs
    }

    /// The failsafe's verdict for this period in `state`: whether the robot
    /// may drive. A trip (leaving `Ok`) is counted, with its time.
    pub(crate) fn judge(
        &mut self,
        state: FailsafeState,
        mission_running: bool,
        step: &mut Step,
    ) -> bool {
        let verdict = self.failsafe.judge(state, mission_running);
        if verdict.tripped() {
            step.counters.failsafe_trips += 1;
            step.counters.tripped_at_us = step.stamp_us();
        }
        if verdict.state != verdict.previous {
            tracing::info!(robot = %step.robot(), from = ?verdict.previous, to = ?verdict.state, "failsafe");
        }
        verdict.drive
    }

    /// This period's outputs: held at zero unless the failsafe's `permit`
    /// is to drive (see [`Permit`] for whether the controller idles) or
    /// when the mode steers by a position the robot does not have;
    /// otherwise what the controller demands, following `mission` in
    /// waypoint mode, through the platform, limited by the fleet safety
    /// layer, and through the wheel speed loops. See the module docs:
    /// every obeyed command passes here.
    pub(crate) fn obey(
        &mut self,
        permit: Permit,
        controller: &mut Controller,
        mission: Option<&mut MissionRun>,
        sensors: &mut Sensors,
        safety: &mut Safety,
        step: &mut Step,
    ) -> &[f64] {
        match permit {
            Permit::Drive => {}
            Permit::Wait => {
                safety.idle();
                return self.hold(controller.platform(), sensors);
            }
            Permit::Stop => {
                if !matches!(controller.mode(), Mode::Idle) {
                    controller.idle();
                }
                safety.idle();
                return self.hold(controller.platform(), sensors);
            }
        }
        let now = step.now;
        let motion = sensors.motion(controller.platform(), &self.outputs, now);
        let estimate = motion.estimate.map(|e| e.pose);
        let pose = match estimate {
            Some(pose) => pose,
            None if controller.needs_position() => {
                safety.idle();
                return self.hold(controller.platform(), sensors);
            }
            None => Pose::default(),
        };
        let demand = controller.demand(&pose, now, mission);
        let platform = controller.platform();
        let velocity = motion.velocity;
        safety.steered_by(controller.bearing_gain());
        let outputs = safety.filter(
            platform,
            estimate.as_ref().map(|pose| (pose, motion.position_error)),
            Vec2::new(velocity.vx, velocity.vy),
            demand.outputs(platform),
            step,
        );
        self.actuate(outputs, sensors.wheels_mut(), now)
    }

    /// Every output zero, and the wheel speed loops forget their
    /// integrators (the robot was stopped by something other than its
    /// command).
    fn hold(&mut self, platform: &dyn Platform, sensors: &mut Sensors) -> &[f64] {
        self.outputs.clear();
        self.outputs.resize(platform.motors(), 0.0);
        if let Some(w) = sensors.wheels_mut() {
            w.reset_loops();
        }
        &self.outputs
    }

    /// The outputs `open_loop` (the platform's, for the demand, as the
    /// safety layer let them through); with wheel encoders, each asks for a
    /// wheel speed and the speed loops deliver it.
    fn actuate(
        &mut self,
        open_loop: Vec<f64>,
        wheels: Option<&mut Wheels>,
        now: Duration,
    ) -> &[f64] {
        self.outputs = match wheels {
            Some(w) => w.close_loop(&open_loop, now),
            None => open_loop,
        };
        &self.outputs
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;

    #[test]
    fn a_mode_that_steers_by_position_holds_still_without_an_estimate() {
        let mut a = Agent::new(
            AgentSettings::new("r1"),
            PlatformSpec::diff_drive().build(),
            0,
        );
        let w = Body::Welcome(Welcome {
            robot_id: 1,
            route: Route {
                robot: "r1".into(),
                channel: "joy/0".into(),
                epoch: 1,
            },
            router_version: "t".into(),
        });
        a.handle(msg("", w), ms(0));
        // One controller, numbering its commands.
        let command = |seq: u32, body: Body| {
            let mut m = msg("joy/0", body);
            m.header.seq = seq;
            m
        };
        a.handle(command(1, heading(0.2)), ms(10));
        assert!(!moving(&a.tick(ms(20)).outputs), "no position yet");
        assert_eq!(a.failsafe_state(ms(20)), FailsafeState::Ok);
        a.handle(command(2, twist(0.2)), ms(30));
        assert!(moving(&a.tick(ms(40)).outputs), "a twist needs none");
        a.observe_position(PositionSample {
            pose: Pose::default(),
            stamp: ms(40),
            quality: 1.0,
            has_heading: true,
        });
        a.handle(command(3, heading(0.2)), ms(50));
        assert!(
            moving(&a.tick(ms(60)).outputs),
            "with an estimate it steers"
        );
    }

    fn heading(speed: f64) -> Body {
        Body::Command(Command::VelocityHeading(mech_proto::VelocityHeading {
            speed,
            heading: 0.0,
        }))
    }

    #[test]
    fn channel_silence_stops_within_timeout_plus_one_period() {
        let mut a = routed("joy/0");
        let last_command = ms(100);
        a.handle(msg("joy/0", twist(0.2)), last_command);
        let mut now = ms(100);
        let mut stopped_at = None;
        while now < ms(2000) {
            now += PERIOD;
            router_heartbeat(&mut a, now);
            let t = a.tick(now);
            if !moving(&t.outputs) {
                stopped_at = Some(now);
                break;
            }
        }
        let stopped_at = stopped_at.unwrap();
        assert!(
            stopped_at <= last_command + a.settings().failsafe.channel_timeout + PERIOD,
            "{stopped_at:?}"
        );
        assert!(stopped_at > last_command + a.settings().failsafe.channel_timeout);
        assert_eq!(a.failsafe_state(now), FailsafeState::ChannelSilent);
        assert_eq!(a.telemetry(now).failsafe, FailsafeState::ChannelSilent);
        // The next accepted command resumes.
        a.handle(msg("joy/0", twist(0.2)), now);
        assert!(moving(&a.tick(now + PERIOD).outputs));
        assert_eq!(a.counters().failsafe_trips, 1);
    }
}

#[cfg(test)]
mod loss_tests {
    //! The failsafe under packet loss: a controller publishing at 25 Hz over
    //! a link losing 30% of its messages never trips the 0.5 s timeout, and
    //! when the controller stops, the robot stops within timeout + one
    //! control period.
    use super::super::testing::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn no_false_trips_at_30_percent_loss_and_timely_stop() {
        let mut rng = rand::rngs::SmallRng::seed_from_u64(30);
        let period = Duration::from_millis(20);
        for run in 0..20u64 {
            let mut a = Agent::new(AgentSettings::new("r1"), PlatformSpec::kiwi().build(), 0);
            // The controller numbers its messages, as every sender does.
            let mut seq = 0u32;
            let mut env = |channel: &str, body: Body| {
                seq += 1;
                Envelope::new(
                    Header {
                        seq,
                        destination: "r1".into(),
                        channel: channel.into(),
                        ..Header::default()
                    },
                    body,
                )
            };
            let route = Route {
                robot: "r1".into(),
                channel: "joy/0".into(),
                epoch: 1,
            };
            a.handle(
                env(
                    "",
                    Body::Welcome(Welcome {
                        robot_id: 1,
                        route,
                        router_version: "t".into(),
                    }),
                ),
                Duration::ZERO,
            );
            let stop_publishing = Duration::from_secs(10);
            let mut last_delivered = Duration::ZERO;
            let mut now = Duration::ZERO;
            let mut stopped_at = None;
            while now < Duration::from_secs(12) {
                now += period;
                // Router heartbeats every 240 ms and controller commands every
                // 40 ms (on the 20 ms control grid), each lost with
                // probability 0.3.
                if now.as_millis().is_multiple_of(240) && !rng.random_bool(0.3) {
                    a.handle(env("", Body::Heartbeat(Heartbeat::new(0))), now);
                }
                if now < stop_publishing
                    && now.as_millis().is_multiple_of(40)
                    && !rng.random_bool(0.3)
                {
                    a.handle(
                        env(
                            "joy/0",
                            Body::Command(Command::Twist(Twist {
                                vx: 0.1,
                                ..Twist::default()
                            })),
                        ),
                        now,
                    );
                    last_delivered = now;
                }
                let moving = a.tick(now).outputs.iter().any(|u| *u != 0.0);
                if now < stop_publishing && last_delivered > Duration::ZERO {
                    assert!(moving, "run {run}: false trip at {now:?}");
                }
                if now >= stop_publishing && !moving && stopped_at.is_none() {
                    stopped_at = Some(now);
                }
            }
            let stopped_at = stopped_at.unwrap();
            assert!(
                stopped_at <= last_delivered + a.settings().failsafe.channel_timeout + period,
                "run {run}"
            );
        }
    }
}
