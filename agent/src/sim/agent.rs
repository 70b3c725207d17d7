//! A simulated agent: the real [`Agent`] core driving a [`SimRobot`]
//! instead of motors, fed with noisy positions of the simulated vehicle
//! through the same median filter and, when the robot has encoders
//! ([`SimAgent::with_encoders`]), with simulated wheel encoder counts.
//! Steppable without sockets or tokio:
//! call [`SimAgent::handle`] for each message and [`SimAgent::tick`] each
//! control period with the simulated time.

use std::time::Duration;

use mech_proto::{Envelope, Pose};

use super::encoder::{SimEncoderModel, SimEncoders};
use super::noise::UwbNoise;
use super::robot::SimRobot;
use crate::hal::{PositionSample, WheelEncoders};
use crate::machine::{Agent, AgentSettings};
use crate::platform::PlatformSpec;
use crate::runtime::Vehicle;

/// Agent core + simulated vehicle + position noise.
#[derive(Debug)]
pub struct SimAgent {
    pub agent: Agent,
    pub robot: SimRobot,
    /// `None`: perfect positions.
    noise: Option<UwbNoise>,
    /// Wheel encoders, when the robot has them.
    encoders: Option<SimEncoders>,
    /// Time between position fixes (zero: one every tick).
    fix_period: Duration,
    next_fix: Duration,
    last_tick: Option<Duration>,
}

impl SimAgent {
    pub fn new(
        settings: AgentSettings,
        platform: &PlatformSpec,
        pose: Pose,
        noise: Option<UwbNoise>,
        stamp_origin_us: u64,
    ) -> SimAgent {
        SimAgent {
            agent: Agent::new(settings, platform.build(), stamp_origin_us),
            robot: SimRobot::new(platform, pose),
            noise,
            encoders: None,
            fix_period: Duration::ZERO,
            next_fix: Duration::ZERO,
            last_tick: None,
        }
    }

    /// Gives the simulated wheels encoders of `model` (seeded). The agent
    /// uses them if its settings have `wheels` (`[encoders]`).
    pub fn with_encoders(mut self, model: SimEncoderModel, seed: u64) -> SimAgent {
        let wheels = self.robot.wheel_speeds().len();
        self.encoders = (wheels > 0).then(|| SimEncoders::new(model, wheels, seed));
        self
    }

    /// One position fix every `period` instead of every tick (a UWB tag at
    /// 10 Hz under a 50 Hz control loop).
    pub fn with_fix_period(mut self, period: Duration) -> SimAgent {
        self.fix_period = period;
        self
    }

    /// Handles one message from the router.
    pub fn handle(&mut self, env: Envelope, now: Duration) -> Vec<Envelope> {
        self.agent.handle(env, now)
    }

    /// Handles one received datagram.
    pub fn handle_bytes(&mut self, bytes: &[u8], now: Duration) -> Vec<Envelope> {
        self.agent.handle_bytes(bytes, now)
    }

    /// Advances the vehicle to `now` with the agent's last outputs, measures
    /// its position, and runs one agent control period.
    pub fn tick(&mut self, now: Duration) -> Vec<Envelope> {
        let dt = self
            .last_tick
            .map_or(0.0, |t| now.saturating_sub(t).as_secs_f64());
        self.last_tick = Some(now);
        let outputs = self.agent.outputs().to_vec();
        self.robot.step_outputs(&outputs, dt);
        let mut notices = Vec::new();
        if let Some(e) = self.encoders.as_mut() {
            if dt > 0.0 {
                e.advance(self.robot.wheel_travel(), now);
            }
            if let Ok(counts) = e.read_all(now) {
                notices.extend(self.agent.observe_wheels(&counts, now));
            }
        }
        if now >= self.next_fix {
            self.next_fix = now + self.fix_period;
            let truth = self.robot.pose();
            let pose = match &mut self.noise {
                Some(n) => n.measure(&truth),
                None => truth,
            };
            self.agent.observe_position(PositionSample {
                pose,
                stamp: now,
                quality: 1.0,
                has_heading: true,
            });
        }
        let mut out = self.agent.tick(now).outgoing;
        out.extend(notices);
        out
    }

    /// The `Bye` sent on shutdown.
    pub fn bye(&mut self, now: Duration) -> Envelope {
        self.agent.bye("shutdown", now)
    }
}

/// The simulator runs in the same loop as a robot: a simulated agent is a
/// [`Vehicle`] whose actuators move its simulated body.
impl Vehicle for SimAgent {
    fn agent(&self) -> &crate::machine::Agent {
        &self.agent
    }
    fn agent_mut(&mut self) -> &mut crate::machine::Agent {
        &mut self.agent
    }
    fn handle_bytes(&mut self, bytes: &[u8], now: Duration) -> Vec<Envelope> {
        SimAgent::handle_bytes(self, bytes, now)
    }
    fn handle(&mut self, env: Envelope, now: Duration) -> Vec<Envelope> {
        SimAgent::handle(self, env, now)
    }
    fn tick(&mut self, now: Duration) -> Vec<Envelope> {
        SimAgent::tick(self, now)
    }
    fn stop(&mut self, now: Duration) -> Envelope {
        let motors = self.robot.platform().motors();
        self.robot.step_outputs(&vec![0.0; motors], 1e-6);
        self.bye(now)
    }
}
