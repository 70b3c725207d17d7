//! The agent core: one robot's protocol state machine, routing, failsafe,
//! onboard control and telemetry, with no sockets, threads or clocks.
//!
//! Drive it with [`Agent::handle`] for each received message and
//! [`Agent::tick`] once per control period, both given the current time.
//! The same core runs on a real robot ([`crate::runtime`]), in the simulated
//! fleet ([`crate::sim`]) and in deterministic lock-step tests.
//!
//! [`Agent`] composes one state machine per concern, each in its own file
//! with its state and its tests:
//! - `wire`: numbering, stamping and signing what the robot sends; the
//!   checks received bytes pass (addressed here, decodable, signed).
//! - `registration`: Hello and Welcome, heartbeats, the router's liveness,
//!   its loss and its Bye.
//! - `intake`: the route in force and the checks every command passes
//!   (routed channel, stale order); the routed channel's silence.
//! - `estop`: the e-stop latch, its order and acknowledgement, and what it
//!   stops.
//! - `missions`: stored missions per channel, pause and resume.
//! - `sensors`: the position estimate, wheel encoders and stall, driver and
//!   actuator faults (`sensors/faults`).
//! - `autopilot_requests`: operators' requests queued for the autopilot.
//! - `actuation`: the failsafe's verdict, and `Actuation::obey`, the one
//!   place every obeyed command becomes actuator outputs.
//! - `fleet_safety`: fleet safety, the [`crate::safety::SafetyLayer`] fed with
//!   the station's arena and neighbours, which `Actuation::obey` applies
//!   to whatever is about to be obeyed.
//! - `telemetry` and `counters`: what the robot reports.
//!
//! The onboard controller ([`crate::control`]) and the failsafe's rules
//! ([`crate::failsafe`]) are modules of the crate. `Agent` itself only
//! routes each message to the part it concerns and runs the parts in order
//! each period.

mod actuation;
mod autopilot_requests;
mod counters;
mod estop;
mod fleet_safety;
mod intake;
mod missions;
mod registration;
mod sensors;
mod settings;
mod step;
mod telemetry;
mod wire;

#[cfg(test)]
mod testing;

use std::time::Duration;

use mech_proto::{
    AutopilotRequest, Body, Bye, Envelope, FailsafeState, Hello, Level, Mission, NoticeCode, Route,
    Telemetry,
};

use crate::control::{Controller, MissionRun, Mode};
use crate::failsafe::Conditions;
use crate::fusion::FusionCounters;
use crate::hal::{EdgeCount, PositionSample};
use crate::platform::Platform;

use actuation::{Actuation, Permit};
use autopilot_requests::AutopilotRequests;
use estop::EStopLatch;
use fleet_safety::Safety;
use intake::Intake;
use missions::Missions;
use registration::Registration;
use sensors::Sensors;
use step::Step;
use telemetry::{Snapshot, TelemetrySchedule};
use wire::{Unread, Wire};

pub use counters::Counters;
pub use settings::AgentSettings;

/// The agent software's version, sent in `Hello`.
const VERSION: &str = env!("CARGO_PKG_VERSION");

/// The result of one control period.
#[derive(Debug, Clone, PartialEq)]
pub struct Tick {
    /// Actuator outputs to write now, one per motor, each in `[-1, 1]`.
    pub outputs: Vec<f64>,
    /// Messages to send to the router.
    pub outgoing: Vec<Envelope>,
}

/// One robot's agent core: the parts it composes (see the module docs).
#[derive(Debug)]
pub struct Agent {
    settings: AgentSettings,
    wire: Wire,
    registration: Registration,
    intake: Intake,
    estop: EStopLatch,
    missions: Missions,
    autopilot: AutopilotRequests,
    sensors: Sensors,
    /// The mode commanded, and the platform's kinematics.
    controller: Controller,
    actuation: Actuation,
    safety: Safety,
    telemetry: TelemetrySchedule,
    counters: Counters,
}

/// Building the agent and driving it: messages in, control periods, driver
/// reports.
impl Agent {
    /// An agent for a robot with `platform`. `stamp_origin_us` is the Unix
    /// time in µs at agent time zero (0 in tests).
    pub fn new(
        settings: AgentSettings,
        platform: Box<dyn Platform>,
        stamp_origin_us: u64,
    ) -> Agent {
        let controller = Controller::new(platform, settings.gains, settings.has_position);
        let p = controller.platform();
        Agent {
            wire: Wire::new(&settings.name, stamp_origin_us),
            registration: Registration::new(&settings),
            intake: Intake::new(&settings),
            estop: EStopLatch::default(),
            missions: Missions::default(),
            autopilot: AutopilotRequests::new(settings.autopilot),
            sensors: Sensors::new(&settings, p),
            actuation: Actuation::new(settings.failsafe, p.motors()),
            safety: Safety::new(settings.safety),
            telemetry: TelemetrySchedule::new(settings.telemetry_period),
            counters: Counters::default(),
            controller,
            settings,
        }
    }

    /// Signs everything with `key` and obeys only what the router (named
    /// `router`) signed for this robot.
    pub fn with_key(mut self, key: mech_proto::auth::Key, router: &str) -> Agent {
        self.wire.with_key(key, router);
        self
    }

    /// Numbers a message that is about to be sent (once, whichever links
    /// carry it): the robot's messages are numbered as they leave, so a
    /// message a link skips on purpose is not a gap the router counts as
    /// lost.
    pub fn number(&mut self, env: &mut Envelope) {
        self.wire.number(env);
    }

    /// Encodes a message to send, signed when the robot has a key. The
    /// header's stamp is the robot's clock reading; its number is the one
    /// [`Agent::number`] gave it.
    pub fn encode(&mut self, env: &Envelope, out: &mut Vec<u8>) -> Result<(), mech_proto::Error> {
        self.encode_on(env, 0, out)
    }

    /// Like [`Agent::encode`], for the robot's link number `link` (its
    /// place in the config's link list): each link is its own signed
    /// stream, so a message sent on two links is never taken for a replay.
    pub fn encode_on(
        &mut self,
        env: &Envelope,
        link: u8,
        out: &mut Vec<u8>,
    ) -> Result<(), mech_proto::Error> {
        self.wire.encode_on(env, link, out)
    }

    /// A position measurement from the robot's own source: through the
    /// median filter, and with encoders, into the odometry fusion.
    pub fn observe_position(&mut self, sample: PositionSample) {
        self.sensors.observe_position(sample, &mut self.counters);
    }

    /// The vehicle cannot be driven now (a ROS 2 base without odometry, or
    /// with another controller on its `cmd_vel`): the outputs are held at
    /// zero (state `Fault`) until `until`, the controller and its mission
    /// kept for when it can; the station is told when a hold begins.
    pub fn hold_outputs(&mut self, what: &str, until: Duration, now: Duration) -> Option<Envelope> {
        let mut out = Vec::new();
        let mut step = Step::new(now, &mut self.wire, &mut self.counters, &mut out);
        self.sensors.faults.hold(what, until, &mut step);
        out.pop()
    }

    /// Counts an input from the vehicle's driver that was refused (a
    /// sample that does not decode or is not finite).
    pub fn count_refused(&mut self) {
        self.counters.refused += 1;
    }

    /// The body twist the vehicle measured itself at `now` (a ROS 2 base's
    /// odometry): telemetry, the safety layer and the moved-on estimate
    /// use it while fresh instead of what the outputs would give.
    pub fn observe_velocity(&mut self, twist: mech_proto::Twist, now: Duration) {
        self.sensors.observe_velocity(twist, now);
    }

    /// One reading of every wheel encoder (motor order), taken at `now`,
    /// before this period's [`Agent::tick`]: measured speeds for telemetry
    /// and the speed loops, odometry for the pose, the stall watch. A
    /// reading that does not fit the robot is a driver fault (the notice is
    /// returned).
    pub fn observe_wheels(&mut self, counts: &[EdgeCount], now: Duration) -> Option<Envelope> {
        let mut out = Vec::new();
        let mut step = Step::new(now, &mut self.wire, &mut self.counters, &mut out);
        let applied = self.actuation.outputs();
        self.sensors
            .observe_wheels(counts, applied, self.controller.platform(), &mut step);
        out.pop()
    }

    /// An actuator or position driver failed; health becomes `Fault` for a
    /// second and the GCS is told (at most once a second).
    pub fn driver_fault(&mut self, what: &str, now: Duration) -> Option<Envelope> {
        let mut out = Vec::new();
        let mut step = Step::new(now, &mut self.wire, &mut self.counters, &mut out);
        self.sensors.faults.driver_fault(what, &mut step);
        out.pop()
    }

    /// Writing the actuators failed: outputs are held at zero (state
    /// `Fault`) for a second, then the robot obeys commands again if the
    /// driver recovered; the GCS is told.
    pub fn actuator_fault(&mut self, what: &str, now: Duration) -> Option<Envelope> {
        let mut out = Vec::new();
        let mut step = Step::new(now, &mut self.wire, &mut self.counters, &mut out);
        self.sensors
            .faults
            .actuator_fault(what, &mut self.controller, &mut step);
        out.pop()
    }

    /// Decodes and handles one received datagram or frame; undecodable bytes
    /// are counted and dropped.
    pub fn handle_bytes(&mut self, bytes: &[u8], now: Duration) -> Vec<Envelope> {
        match self.wire.receive(bytes, now) {
            Ok(env) => return self.handle(env, now),
            Err(Unread::NotForMe) => self.counters.not_for_me += 1,
            Err(Unread::Undecodable) => self.counters.bad_messages += 1,
            Err(Unread::Synced) => self.registration.synced(now),
            Err(Unread::Refused) => {}
        }
        Vec::new()
    }

    /// Handles one message from the router; returns the replies.
    pub fn handle(&mut self, env: Envelope, now: Duration) -> Vec<Envelope> {
        let mut out = Vec::new();
        self.registration.router_heard(now);
        if !self.wire.for_me(&env.header.destination) {
            self.counters.not_for_me += 1;
            return out;
        }
        let header = env.header;
        let estopped = self.estop.engaged();
        let mut step = Step::new(now, &mut self.wire, &mut self.counters, &mut out);
        match env.body {
            Body::Welcome(w) => self.welcomed(w.robot_id, w.route, now, &mut out),
            Body::Route(r) if self.intake.fresh_route(&r, &mut step) => {
                self.apply_route(r, now, &mut out);
            }
            Body::Command(cmd) => {
                let (controller, missions) = (&mut self.controller, &mut self.missions);
                self.intake
                    .command(&header, &cmd, estopped, controller, missions, &mut step);
            }
            Body::FleetCommand(f) => {
                if let Some(part) = f.parts.iter().find(|p| p.robot == self.settings.name) {
                    let (controller, missions) = (&mut self.controller, &mut self.missions);
                    self.intake.command(
                        &header,
                        &part.command,
                        estopped,
                        controller,
                        missions,
                        &mut step,
                    );
                }
            }
            Body::Mission(m) => self.mission_received(&header.channel, m, now, &mut out),
            Body::Heartbeat(_) => self.registration.router_beat(header.seq, now),
            Body::EStop(e) => {
                self.estop
                    .receive(e, &mut self.controller, &mut self.missions, &mut step);
            }
            Body::Bye(bye) if header.sender == mech_proto::ROUTER => {
                self.registration
                    .router_left(&self.settings.name, &bye.reason);
            }
            Body::Autopilot(r) => self.autopilot.receive(r, estopped, &mut step),
            Body::Notice(n) if n.code == NoticeCode::UnknownRobot => {
                self.registration.unknown_to_router(&mut step);
            }
            Body::PositionFix(fix) => self.sensors.position_fix(fix, &mut step),
            Body::Arena(arena) => self.safety.arena(&arena, &mut step),
            Body::Neighbours(n) => self.safety.neighbours(&n, &self.settings.name, now),
            _ => {}
        }
        out
    }

    /// The autopilot requests received since the last call, oldest first,
    /// for the vehicle to carry out.
    pub fn take_autopilot_requests(&mut self) -> Vec<AutopilotRequest> {
        self.autopilot.take()
    }

    /// A notice from this robot to the router (the station's event log).
    pub fn notice(
        &mut self,
        level: Level,
        code: NoticeCode,
        text: &str,
        now: Duration,
    ) -> Envelope {
        self.wire.notice(mech_proto::ROUTER, level, code, text, now)
    }

    /// One control period: registration, the stall watch, the failsafe's
    /// verdict, the actuator outputs, and the periodic messages that are
    /// due (Hello, Heartbeat, Telemetry).
    pub fn tick(&mut self, now: Duration) -> Tick {
        let mut outgoing = Vec::new();
        let mut step = Step::new(now, &mut self.wire, &mut self.counters, &mut outgoing);
        let (settings, controller) = (&self.settings, &self.controller);
        self.registration
            .tick(&mut step, || hello(settings, controller));
        self.sensors.watch_stall(&mut self.controller, &mut step);
        self.sensors
            .advance(self.controller.platform(), self.actuation.outputs(), now);
        let state = self.failsafe_state(now);
        let mission_running = self.mission_running();
        let mut step = Step::new(now, &mut self.wire, &mut self.counters, &mut outgoing);
        let drive = self.actuation.judge(state, mission_running, &mut step);
        let permit = if drive {
            Permit::Drive
        } else if mission_running && !self.registration.router_lost(now) {
            // Every link silent for the channel timeout: the mission waits,
            // keeping its place, and goes on when the router is heard again
            // (past the router timeout it idles, and registering again
            // resumes it).
            Permit::Wait
        } else {
            Permit::Stop
        };
        let mission = self.missions.following(self.intake.channel());
        let outputs = self
            .actuation
            .obey(
                permit,
                &mut self.controller,
                mission,
                &mut self.sensors,
                &mut self.safety,
                &mut step,
            )
            .to_vec();
        if self.registration.registered() {
            self.report(now, &mut outgoing);
        }
        Tick { outputs, outgoing }
    }

    /// A heartbeat as a robot with several links sends on each link it is
    /// not using, so the router hears which are alive (no echo: the round
    /// trip is timed on the link in use).
    pub fn heartbeat(&mut self, now: Duration) -> Envelope {
        let body = registration::heartbeat(now, None);
        self.wire.envelope(mech_proto::ROUTER, body, now)
    }

    /// The `Bye` sent when the agent shuts down.
    pub fn bye(&mut self, reason: &str, now: Duration) -> Envelope {
        let body = Body::Bye(Bye {
            reason: wire::truncate(reason),
        });
        self.wire.envelope(mech_proto::ROUTER, body, now)
    }

    /// The heartbeat and telemetry that are due.
    fn report(&mut self, now: Duration, outgoing: &mut Vec<Envelope>) {
        let telemetry = self
            .telemetry
            .due(now)
            .then(|| Body::Telemetry(self.telemetry(now)));
        let mut step = Step::new(now, &mut self.wire, &mut self.counters, outgoing);
        self.registration.heartbeat_if_due(&mut step);
        if let Some(t) = telemetry {
            step.send(mech_proto::ROUTER, t);
        }
    }

    /// Registered (again): the Welcome's route is applied whatever its
    /// epoch, since a (possibly restarted) router numbers e-stops, route
    /// epochs and missions afresh.
    fn welcomed(&mut self, id: u16, route: Route, now: Duration, out: &mut Vec<Envelope>) {
        if self
            .registration
            .welcomed(&self.settings.name, &route.channel, now)
        {
            self.estop.forget_ids();
            self.intake.forget_senders();
            self.safety.registered(id);
        }
        self.apply_route(route, now, out);
    }

    /// Puts a route in force and acknowledges it. A change idles the
    /// controller and resumes the new channel's paused mission, but not
    /// while e-stopped: missions stay paused through a release.
    fn apply_route(&mut self, route: Route, now: Duration, out: &mut Vec<Envelope>) {
        if self.intake.apply(route, now) {
            self.controller.idle();
            if !self.estop.engaged() {
                self.missions.unpause(self.intake.channel());
            }
        }
        self.resume_mission(now);
        let ack = self.intake.ack();
        out.push(self.wire.envelope(mech_proto::ROUTER, ack, now));
    }

    /// Follows the routed channel's mission if one is waiting and the robot
    /// is otherwise idle.
    fn resume_mission(&mut self, now: Duration) {
        if self.missions.runnable(self.intake.channel())
            && !self.estop.engaged()
            && matches!(self.controller.mode(), Mode::Idle)
            && self.controller.follow_mission().is_ok()
        {
            self.intake.channel_heard(now);
        }
    }

    /// A mission upload: stored and acknowledged (or refused), and followed
    /// at once when it is for the routed channel and not paused.
    fn mission_received(
        &mut self,
        channel: &str,
        mission: Mission,
        now: Duration,
        out: &mut Vec<Envelope>,
    ) {
        let cannot_follow = missions::cannot_follow(&self.controller, self.settings.has_position);
        let mut step = Step::new(now, &mut self.wire, &mut self.counters, out);
        let estopped = self.estop.engaged();
        let routed = self.intake.channel().to_string();
        let start = self.missions.receive(
            channel,
            mission,
            cannot_follow,
            estopped,
            &routed,
            &mut step,
        );
        if start && channel == self.intake.channel() && self.controller.follow_mission().is_ok() {
            self.intake.channel_heard(now);
        }
    }
}

/// What the agent knows now, read from its parts.
impl Agent {
    /// Messages refused by authentication, by reason (zero without a key).
    pub fn auth_rejections(&self) -> crate::auth::RobotRejections {
        self.wire.rejections()
    }

    pub fn name(&self) -> &str {
        &self.settings.name
    }

    pub fn settings(&self) -> &AgentSettings {
        &self.settings
    }

    pub fn platform(&self) -> &dyn Platform {
        self.controller.platform()
    }

    /// The channel this robot obeys ("" = none).
    pub fn route(&self) -> &Route {
        self.intake.route()
    }

    pub fn registered(&self) -> bool {
        self.registration.registered()
    }

    pub fn counters(&self) -> Counters {
        self.counters
    }

    pub fn mode(&self) -> &Mode {
        self.controller.mode()
    }

    /// The position estimate: the median of the fixes, or, with encoders,
    /// odometry fused with them (its `stamp` is always the newest fix's).
    pub fn estimate(&self) -> Option<PositionSample> {
        self.sensors.estimate()
    }

    /// What the odometry fusion did with the fixes (zero without encoders).
    pub fn fusion_counters(&self) -> FusionCounters {
        self.sensors.fusion_counters()
    }

    /// Each wheel's measured rim speed (m/s), while encoder readings are
    /// fresh.
    pub fn wheel_speeds(&self, now: Duration) -> Option<Vec<f64>> {
        self.sensors.wheel_speeds(now)
    }

    /// The outputs of the last tick.
    pub fn outputs(&self) -> &[f64] {
        self.actuation.outputs()
    }

    /// What the fleet safety layer is doing (as telemetry reports it).
    pub fn safety(&self) -> mech_proto::SafetyReport {
        self.safety.report()
    }

    /// The stored mission for `channel`, if any.
    pub fn mission(&self, channel: &str) -> Option<&MissionRun> {
        self.missions.get(channel)
    }

    /// The failsafe state now.
    pub fn failsafe_state(&self, now: Duration) -> FailsafeState {
        self.conditions(now).state()
    }

    /// The `Hello` this robot registers with.
    pub fn hello(&self) -> Hello {
        hello(&self.settings, &self.controller)
    }

    /// The robot's telemetry now. `velocity` is the twist the wheel
    /// encoders measure while their readings are fresh, otherwise the twist
    /// the current outputs produce (the platform's forward kinematics, which
    /// is what a robot without encoders knows of its motion); either is
    /// turned from the body frame into the world frame by the estimated
    /// heading, as the protocol specifies, and `velocity_source` says which.
    pub fn telemetry(&self, now: Duration) -> Telemetry {
        let channel = self.intake.channel();
        let outputs = self.actuation.outputs();
        Snapshot {
            motion: self.sensors.motion(self.platform(), outputs, now),
            health: self.sensors.health(now),
            failsafe: self.failsafe_state(now),
            mode: self.controller.mode().control_mode(),
            channel,
            outputs,
            mission: self.missions.get(channel).map(MissionRun::progress),
            stale: self.counters.stale_total(),
            safety: self.safety.report(),
        }
        .telemetry()
    }

    /// What the failsafe judges now, from the parts that know it.
    fn conditions(&self, now: Duration) -> Conditions {
        let channel = self.intake.channel();
        Conditions {
            estopped: self.estop.engaged(),
            actuator_fault: self.sensors.faults.actuators_held(now),
            router_lost: self.registration.router_lost(now),
            link_silent: self
                .registration
                .router_silent_for(self.settings.failsafe.channel_timeout, now),
            routed: self.intake.routed(),
            channel_silent: self.intake.channel_silent(now),
            // A mission on the routed channel is the robot's controller,
            // running or done: silence on that channel is not a fault.
            mission_controls: self.mission_running() || self.missions.done(channel),
        }
    }

    /// Whether the controller is following the routed channel's mission.
    fn mission_running(&self) -> bool {
        matches!(self.controller.mode(), Mode::Waypoints)
            && self.missions.runnable(self.intake.channel())
    }
}

/// The `Hello` of a robot with these settings and controller.
fn hello(settings: &AgentSettings, controller: &Controller) -> Hello {
    let p = controller.platform();
    Hello {
        name: settings.name.clone(),
        platform: p.name().to_string(),
        capabilities: controller.capabilities().to_vec(),
        motors: p.motors() as u8,
        max_speed: p.limits().max_speed,
        max_yaw_rate: p.limits().max_yaw_rate,
        agent_version: VERSION.to_string(),
    }
}
