//! The agent core: protocol state machine, routing, failsafe, onboard
//! control and telemetry of one robot, with no sockets, threads or clocks.
//!
//! Drive it with [`Agent::handle`] for each received message and
//! [`Agent::tick`] once per control period, both given the current time.
//! The same core runs on a real robot ([`crate::runtime`]), in the simulated
//! fleet ([`crate::sim`]) and in deterministic lock-step tests.

use std::collections::HashMap;
use std::time::Duration;

use mech_proto::{
    AutopilotRequest, Body, Bye, Command, CommandKind, Computation, EStop, EStopAck, Echo,
    Envelope, FailsafeState, Header, Health, Heartbeat, Hello, Level, Mission, MissionAck, Notice,
    NoticeCode, Route, RouteAck, Telemetry, Twist, Velocity, VelocitySource,
};
use nalgebra::{DMatrix, Matrix3, Vector3};

use crate::auth::{Checked, RobotAuth};
use crate::control::{Controller, Gains, MissionRun, Mode};
use crate::failsafe::{Failsafe, FailsafeConfig};
use crate::filter::MedianFilter;
use crate::fusion::{FusionCounters, FusionSettings, PoseFusion};
use crate::hal::{EdgeCount, PositionSample};
use crate::order::{CommandOrder, is_older};
use crate::platform::Platform;
use crate::wheels::{WheelSettings, Wheels};

/// Settings of the agent core (the parts of the robot config it uses).
#[derive(Debug, Clone, PartialEq)]
pub struct AgentSettings {
    /// Robot name: `robot_1`, `rover-a`...
    pub name: String,
    pub failsafe: FailsafeConfig,
    /// Telemetry period (default 50 ms = 20 Hz).
    pub telemetry_period: Duration,
    /// Period of the agent's `Heartbeat`.
    pub hello_period: Duration,
    /// Period of `Hello` while unregistered: short, so a robot is back
    /// within a fraction of a second of its station.
    pub hello_retry: Duration,
    /// Answer a rejected command with `Notice{NotRouted}` (at most one a
    /// second), so a controller learns why it is ignored.
    pub notify_not_routed: bool,
    /// Moving-median window for position samples.
    pub filter_window: usize,
    /// Whether `PositionFix` messages (external positioning relayed by the
    /// GCS) are the position source.
    pub external_position: bool,
    /// Whether the robot has any position source; without one, modes that
    /// need a position are not offered.
    pub has_position: bool,
    /// A position older than this marks health `Degraded`.
    pub position_stale_after: Duration,
    pub gains: Gains,
    /// Wheel encoders (`[encoders]`): measured velocity, closed-loop wheel
    /// speed, stall detection, and odometry fused with the position source.
    /// `None`: velocity is reported from the commanded outputs and the
    /// outputs are open loop.
    pub wheels: Option<WheelSettings>,
    /// Noise figures of the odometry + position fusion (used with `wheels`
    /// and a position source).
    pub fusion: FusionSettings,
    /// Whether an autopilot (PX4, ArduPilot) flies the vehicle: operators'
    /// autopilot requests are then queued for it
    /// ([`Agent::take_autopilot_requests`]); without one they are answered
    /// as unsupported.
    pub autopilot: bool,
}

impl AgentSettings {
    pub fn new(name: impl Into<String>) -> AgentSettings {
        AgentSettings {
            name: name.into(),
            failsafe: FailsafeConfig::default(),
            telemetry_period: Duration::from_millis(50),
            hello_period: Duration::from_secs(1),
            hello_retry: Duration::from_millis(250),
            notify_not_routed: true,
            filter_window: 9,
            external_position: false,
            has_position: true,
            position_stale_after: Duration::from_secs(1),
            gains: Gains::default(),
            wheels: None,
            fusion: FusionSettings::default(),
            autopilot: false,
        }
    }
}

/// Counters of everything the agent refused or could not use.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Commands on a channel other than the acknowledged route.
    pub not_routed: u64,
    /// Commands this robot cannot obey (capability or motor count).
    pub refused: u64,
    /// Commands ignored while e-stopped.
    pub ignored_estopped: u64,
    /// E-stops and releases older than one already obeyed (delayed resends).
    pub stale_estops: u64,
    /// Commands older than one already obeyed from the same sender on the
    /// same channel (overtaken on the way).
    pub stale_commands: u64,
    /// Routes with an epoch older than the one in force.
    pub stale_routes: u64,
    /// Missions with an id older than the one held for their channel.
    pub stale_missions: u64,
    /// Messages addressed to another robot.
    pub not_for_me: u64,
    /// Bytes that did not decode as a message.
    pub bad_messages: u64,
    /// Times the failsafe stopped the robot.
    pub failsafe_trips: u64,
    /// Actuator or position driver errors.
    pub driver_faults: u64,
    /// Position fixes used.
    pub position_samples: u64,
    /// Times a wheel stalled (driven without turning) and the outputs were
    /// zeroed.
    pub stalls: u64,
    /// Commands obeyed.
    pub commands: u64,
    /// Times the router said it did not know this robot (it restarted),
    /// and the robot registered again at once.
    pub reregistered: u64,
    /// When the failsafe last stopped the robot, and when it last obeyed a
    /// new e-stop: the robot's clock, µs since the Unix epoch (0: never).
    pub tripped_at_us: u64,
    pub estopped_at_us: u64,
}

/// The result of one control period.
#[derive(Debug, Clone, PartialEq)]
pub struct Tick {
    /// Actuator outputs to write now, one per motor, each in `[-1, 1]`.
    pub outputs: Vec<f64>,
    /// Messages to send to the router.
    pub outgoing: Vec<Envelope>,
}

/// One robot's agent core.
#[derive(Debug)]
pub struct Agent {
    settings: AgentSettings,
    controller: Controller,
    failsafe: Failsafe,
    filter: MedianFilter,
    estimate: Option<PositionSample>,
    /// Encoders: speeds, speed loops, stall watch (with `[encoders]`).
    wheels: Option<Wheels>,
    /// Odometry fused with fixes (with encoders and a position source).
    fusion: Option<PoseFusion>,
    /// Each wheel's effect on the body displacement (the platform's
    /// odometry, one column per wheel), for the odometry covariance.
    wheel_jacobian: Option<DMatrix<f64>>,
    registered: bool,
    route: Route,
    /// Whether a route has been applied at all (epoch 0 is a valid epoch).
    routed_once: bool,
    /// Id of the newest e-stop or release obeyed since registering. The
    /// router numbers them in order, so an older one (a delayed resend of a
    /// release, overtaken by a new e-stop) must not undo a newer one.
    last_estop_id: Option<u32>,
    /// Stored missions, by the channel that sent them.
    missions: HashMap<String, MissionRun>,
    /// Newest command obeyed from each sender on each channel.
    order: CommandOrder,
    seq: u32,
    /// Unix time (µs) at agent time zero, for message stamps.
    stamp_origin_us: u64,
    next_hello: Duration,
    next_heartbeat: Duration,
    /// The newest router heartbeat not yet echoed: its sequence number and
    /// when it arrived, so the next heartbeat tells the router which one it
    /// answers and how long it was held (the router measures the round trip).
    router_beat: Option<(u32, Duration)>,
    next_telemetry: Duration,
    last_not_routed_notice: Option<Duration>,
    last_driver_fault: Option<Duration>,
    /// Actuators are held at zero (state `Fault`) until then after an
    /// actuator driver error.
    actuator_fault_until: Option<Duration>,
    last_state: FailsafeState,
    outputs: Vec<f64>,
    counters: Counters,
    version: String,
    /// Signing and checking, when the robot has a key.
    auth: Option<RobotAuth>,
    /// Operators' autopilot requests not yet taken by the vehicle.
    autopilot_requests: Vec<AutopilotRequest>,
}

impl Agent {
    /// An agent for a robot with `platform`. `stamp_origin_us` is the Unix
    /// time in µs at agent time zero (0 in tests).
    pub fn new(
        settings: AgentSettings,
        platform: Box<dyn Platform>,
        stamp_origin_us: u64,
    ) -> Agent {
        let controller = Controller::new(platform, settings.gains, settings.has_position);
        let motors = controller.platform().motors();
        let p = controller.platform();
        let wheels = settings
            .wheels
            .zip(p.max_wheel_speed())
            .map(|(w, max)| Wheels::new(w, motors, max));
        let fusion = (wheels.is_some() && settings.has_position).then(|| {
            PoseFusion::new(FusionSettings {
                restart_after: settings.filter_window,
                ..settings.fusion
            })
        });
        let wheel_jacobian = wheels.as_ref().and_then(|_| wheel_jacobian(p));
        Agent {
            filter: MedianFilter::new(settings.filter_window),
            wheels,
            fusion,
            wheel_jacobian,
            failsafe: Failsafe::new(settings.failsafe),
            controller,
            estimate: None,
            registered: false,
            route: Route {
                robot: settings.name.clone(),
                channel: String::new(),
                epoch: 0,
            },
            routed_once: false,
            last_estop_id: None,
            missions: HashMap::new(),
            order: CommandOrder::default(),
            seq: 0,
            stamp_origin_us,
            next_hello: Duration::ZERO,
            next_heartbeat: Duration::ZERO,
            router_beat: None,
            next_telemetry: Duration::ZERO,
            last_not_routed_notice: None,
            last_driver_fault: None,
            actuator_fault_until: None,
            // Nothing heard from a router yet: not a trip when the first tick
            // finds the router lost.
            last_state: FailsafeState::RouterLost,
            outputs: vec![0.0; motors],
            counters: Counters::default(),
            version: env!("CARGO_PKG_VERSION").to_string(),
            auth: None,
            autopilot_requests: Vec::new(),
            settings,
        }
    }

    /// Signs everything with `key` and obeys only what the router (named
    /// `router`) signed for this robot.
    pub fn with_key(mut self, key: mech_proto::auth::Key, router: &str) -> Agent {
        self.auth = Some(RobotAuth::new(key, router));
        self
    }

    /// Messages refused by authentication, by reason (zero without a key).
    pub fn auth_rejections(&self) -> crate::auth::RobotRejections {
        self.auth.as_ref().map(|a| a.rejected).unwrap_or_default()
    }

    /// Encodes a message to send, signed when the robot has a key. The
    /// header's stamp is the robot's clock reading.
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
        mech_proto::encode_into(env, out)?;
        if let Some(auth) = self.auth.as_mut()
            && let Err(e) = auth.seal(out, env.header.stamp_us, link)
        {
            return Err(mech_proto::Error::Encode(e.to_string()));
        }
        Ok(())
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
        &self.route
    }

    pub fn registered(&self) -> bool {
        self.registered
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
        self.estimate
    }

    /// What the odometry fusion did with the fixes (zero without encoders).
    pub fn fusion_counters(&self) -> FusionCounters {
        self.fusion.as_ref().map(|f| f.counters).unwrap_or_default()
    }

    /// Each wheel's measured rim speed (m/s), while encoder readings are
    /// fresh.
    pub fn wheel_speeds(&self, now: Duration) -> Option<Vec<f64>> {
        self.wheels.as_ref().and_then(|w| w.speeds(now))
    }

    /// The outputs of the last tick.
    pub fn outputs(&self) -> &[f64] {
        &self.outputs
    }

    /// The stored mission for `channel`, if any.
    pub fn mission(&self, channel: &str) -> Option<&MissionRun> {
        self.missions.get(channel)
    }

    /// The failsafe state now.
    pub fn failsafe_state(&self, now: Duration) -> FailsafeState {
        // A mission on the routed channel is the robot's controller, running
        // or done: silence on that channel is not a fault.
        let mission_controls = self.mission_running() || self.mission_done_on_route();
        let state = self
            .failsafe
            .state(now, !self.route.channel.is_empty(), mission_controls);
        let faulted = self.actuator_fault_until.is_some_and(|t| now < t);
        if faulted && state != FailsafeState::EStopped {
            FailsafeState::Fault
        } else {
            state
        }
    }

    /// The `Hello` this robot registers with.
    pub fn hello(&self) -> Hello {
        let p = self.controller.platform();
        Hello {
            name: self.settings.name.clone(),
            platform: p.name().to_string(),
            capabilities: self.controller.capabilities().to_vec(),
            motors: p.motors() as u8,
            max_speed: p.limits().max_speed,
            max_yaw_rate: p.limits().max_yaw_rate,
            agent_version: self.version.clone(),
        }
    }

    /// A position measurement from the robot's own source: through the
    /// median filter, and with encoders, into the odometry fusion.
    pub fn observe_position(&mut self, sample: PositionSample) {
        self.counters.position_samples += 1;
        let median = self.filter.push(sample);
        self.estimate = Some(match self.fusion.as_mut() {
            None => median,
            Some(fusion) => {
                fusion.correct(&sample, &median, sample.stamp);
                fused(fusion, median)
            }
        });
    }

    /// One reading of every wheel encoder (motor order), taken at `now`,
    /// before this period's [`Agent::tick`]: measured speeds for telemetry
    /// and the speed loops, odometry for the pose, the stall watch. A
    /// reading that does not fit the robot is a driver fault (the notice is
    /// returned).
    pub fn observe_wheels(&mut self, counts: &[EdgeCount], now: Duration) -> Option<Envelope> {
        let wheels = self.wheels.as_mut()?;
        let step = match wheels.observe(counts, &self.outputs, now) {
            Ok(step) => step,
            Err(e) => return self.driver_fault(&format!("encoders: {e}"), now),
        };
        let sigma = wheels.settings().metres_per_edge() / 2.0;
        let (Some(fusion), Some(jacobian)) = (self.fusion.as_mut(), &self.wheel_jacobian) else {
            return None;
        };
        // The platform's odometry is linear in the wheel speeds, so it turns
        // each wheel's travel into the body's displacement too.
        let d = self.controller.platform().wheel_odometry(&step.travel)?;
        let relative = self.settings.fusion.odometry_sigma;
        let variances: Vec<f64> = step
            .travel
            .iter()
            .map(|t| (relative * t.abs() + sigma).powi(2))
            .collect();
        let wheel_cov = DMatrix::from_diagonal(&nalgebra::DVector::from_vec(variances));
        let body = jacobian * wheel_cov * jacobian.transpose();
        let cov = Matrix3::from_fn(|r, c| body[(r, c)]);
        fusion.predict(Vector3::new(d.vx, d.vy, d.wz), cov, now);
        if let Some(e) = self.estimate {
            self.estimate = Some(fused(fusion, e));
        }
        None
    }

    /// An actuator or position driver failed; health becomes `Fault` for a
    /// second and the GCS is told (at most once a second).
    pub fn driver_fault(&mut self, what: &str, now: Duration) -> Option<Envelope> {
        self.counters.driver_faults += 1;
        let recent = self
            .last_driver_fault
            .is_some_and(|t| now.saturating_sub(t) < Duration::from_secs(1));
        self.last_driver_fault = Some(now);
        (!recent).then(|| {
            self.envelope(
                mech_proto::ROUTER,
                Body::Notice(Notice {
                    level: Level::Error,
                    code: NoticeCode::DriverFault,
                    text: truncate(what),
                }),
                now,
            )
        })
    }

    /// Writing the actuators failed: outputs are held at zero (state
    /// `Fault`) for a second, then the robot obeys commands again if the
    /// driver recovered; the GCS is told.
    pub fn actuator_fault(&mut self, what: &str, now: Duration) -> Option<Envelope> {
        self.actuator_fault_until = Some(now + Duration::from_secs(1));
        self.controller.idle();
        self.driver_fault(what, now)
    }

    /// Decodes and handles one received datagram or frame; undecodable bytes
    /// are counted and dropped.
    pub fn handle_bytes(&mut self, bytes: &[u8], now: Duration) -> Vec<Envelope> {
        // A radio is a broadcast medium: frames for other robots are
        // skipped before they are checked (they are signed for those
        // robots, not refused forgeries).
        if let Ok(head) = mech_proto::peek(bytes) {
            let dest = head.destination;
            if !(dest.is_empty() || dest == mech_proto::BROADCAST || dest == self.settings.name) {
                self.counters.not_for_me += 1;
                return Vec::new();
            }
        }
        let env = match mech_proto::decode(bytes) {
            Ok(env) => env,
            Err(_) => {
                self.counters.bad_messages += 1;
                return Vec::new();
            }
        };
        let local_us = self.stamp_origin_us + now.as_micros() as u64;
        if let Some(auth) = self.auth.as_mut() {
            match auth.check(bytes, &env.header.sender, &env.body, local_us) {
                Checked::Accept => {}
                Checked::Synced => {
                    // Station time known: register now.
                    self.next_hello = now;
                    return Vec::new();
                }
                Checked::Reject => {
                    if auth.rejected.total().is_power_of_two() {
                        tracing::warn!(robot = %self.settings.name, rejected = ?auth.rejected, "refused a message not signed by the router for this robot");
                    }
                    return Vec::new();
                }
            }
        }
        self.handle(env, now)
    }

    /// Handles one message from the router; returns the replies.
    pub fn handle(&mut self, env: Envelope, now: Duration) -> Vec<Envelope> {
        let mut out = Vec::new();
        // Everything reaches the agent through the router, so any message is
        // proof the router is alive.
        self.failsafe.router_heard(now);
        let dest = env.header.destination.as_str();
        if !(dest.is_empty() || dest == mech_proto::BROADCAST || dest == self.settings.name) {
            self.counters.not_for_me += 1;
            return out;
        }
        let Header {
            channel,
            sender,
            seq,
            stamp_us,
            ..
        } = env.header;
        let stamp = (seq, stamp_us);
        match env.body {
            Body::Welcome(w) => self.welcomed(w.route, now, &mut out),
            Body::Route(r) => self.route_received(r, now, &mut out),
            Body::Command(cmd) => self.command(&channel, &sender, stamp, &cmd, now, &mut out),
            Body::FleetCommand(f) => {
                if let Some(part) = f.parts.into_iter().find(|p| p.robot == self.settings.name) {
                    self.command(&channel, &sender, stamp, &part.command, now, &mut out);
                }
            }
            Body::Mission(m) => self.mission_received(&channel, m, now, &mut out),
            Body::Heartbeat(_) => self.router_beat = Some((seq, now)),
            Body::EStop(e) => self.estop_received(e, now, &mut out),
            Body::Bye(bye) if sender == mech_proto::ROUTER => self.router_left(&bye.reason),
            Body::Autopilot(r) => self.autopilot_received(r, now, &mut out),
            Body::Notice(n) if n.code == NoticeCode::UnknownRobot && self.registered => {
                // The router restarted and forgot this robot: register now
                // rather than after the router timeout.
                tracing::info!(robot = %self.settings.name, "the router does not know this robot; registering again");
                self.counters.reregistered += 1;
                self.registered = false;
                self.next_hello = now;
            }
            Body::PositionFix(fix)
                if self.settings.external_position && fix.robot == self.settings.name =>
            {
                self.observe_position(PositionSample {
                    pose: fix.pose,
                    stamp: now,
                    quality: fix.quality.clamp(0.0, 1.0),
                    has_heading: true,
                });
            }
            _ => {}
        }
        out
    }

    /// The router said it is stopping: it is lost now, not after the
    /// router timeout (the failsafe acts on the next tick, and the robot
    /// registers again once a router answers).
    fn router_left(&mut self, reason: &str) {
        tracing::warn!(robot = %self.settings.name, reason = %truncate(reason), "the router is stopping");
        self.failsafe.router_gone();
    }

    /// Registered (again): the Welcome's route is applied whatever its
    /// epoch, since a (possibly restarted) router numbers e-stops, route
    /// epochs and missions afresh.
    fn welcomed(&mut self, route: Route, now: Duration, out: &mut Vec<Envelope>) {
        if !self.registered {
            tracing::info!(robot = %self.settings.name, route = %route.channel, "registered with the router");
            self.last_estop_id = None;
            self.order.clear();
        }
        self.registered = true;
        self.next_heartbeat = now;
        self.apply_route(route, now, out);
    }

    /// A route change, unless it is a delayed resend of one already
    /// replaced (an older epoch).
    fn route_received(&mut self, r: Route, now: Duration, out: &mut Vec<Envelope>) {
        if r.robot != self.settings.name {
            self.counters.not_for_me += 1;
        } else if self.routed_once && is_older(r.epoch, self.route.epoch) {
            self.counters.stale_routes += 1;
        } else {
            self.apply_route(r, now, out);
        }
    }

    /// E-stop or release, unless older than the last one obeyed (a delayed
    /// resend of a release must never undo a newer e-stop); acknowledged.
    fn estop_received(&mut self, e: EStop, now: Duration, out: &mut Vec<Envelope>) {
        if self.last_estop_id.is_some_and(|last| is_older(e.id, last)) {
            self.counters.stale_estops += 1;
            return;
        }
        self.last_estop_id = Some(e.id);
        if e.engage && !self.failsafe.estopped() {
            self.counters.estopped_at_us = self.stamp_origin_us + now.as_micros() as u64;
        }
        if e.engage {
            self.failsafe.engage_estop(e.id);
            self.controller.idle();
            self.missions.values_mut().for_each(|m| m.paused = true);
        } else if self.failsafe.estopped() {
            self.failsafe.release_estop();
        }
        let ack = Body::EStopAck(EStopAck {
            engage: e.engage,
            id: e.id,
        });
        out.push(self.envelope(mech_proto::ROUTER, ack, now));
    }

    /// An operator's request to the autopilot: queued for the vehicle,
    /// unless the robot has no autopilot or is e-stopped and the request
    /// could start it moving (arm, offboard, take off); a refusal is a
    /// notice in the station's event log.
    fn autopilot_received(&mut self, r: AutopilotRequest, now: Duration, out: &mut Vec<Envelope>) {
        if r.robot != self.settings.name {
            self.counters.not_for_me += 1;
            return;
        }
        let refusal = if !self.settings.autopilot {
            Some(format!(
                "{} has no autopilot: {} refused",
                self.settings.name,
                r.action.as_str()
            ))
        } else if self.failsafe.estopped() && r.action.starts_motion() {
            Some(format!(
                "{} is e-stopped: {} refused until release",
                self.settings.name,
                r.action.as_str()
            ))
        } else {
            None
        };
        match refusal {
            Some(text) => {
                self.counters.refused += 1;
                out.push(self.notice(Level::Warn, NoticeCode::Unsupported, &text, now));
            }
            None => self.autopilot_requests.push(r),
        }
    }

    /// The autopilot requests received since the last call, oldest first,
    /// for the vehicle to carry out.
    pub fn take_autopilot_requests(&mut self) -> Vec<AutopilotRequest> {
        std::mem::take(&mut self.autopilot_requests)
    }

    /// A notice from this robot to the router (the station's event log).
    pub fn notice(
        &mut self,
        level: Level,
        code: NoticeCode,
        text: &str,
        now: Duration,
    ) -> Envelope {
        let body = Body::Notice(Notice {
            level,
            code,
            text: truncate(text),
        });
        self.envelope(mech_proto::ROUTER, body, now)
    }

    /// One control period: failsafe, controller, actuator outputs, and the
    /// periodic messages that are due (Hello, Heartbeat, Telemetry).
    pub fn tick(&mut self, now: Duration) -> Tick {
        let mut outgoing = Vec::new();
        self.register(now, &mut outgoing);
        self.watch_stall(now, &mut outgoing);
        let drive = self.judge_failsafe(now);
        self.control(drive, now);
        if self.registered {
            self.report(now, &mut outgoing);
        }
        Tick {
            outputs: self.outputs.clone(),
            outgoing,
        }
    }

    /// Registration: after the router is lost, register again (it may have
    /// restarted, or the robot moved); while unregistered, Hello every
    /// `hello_retry` (with a key, ask the station's time first: signed
    /// stamps need it).
    fn register(&mut self, now: Duration, outgoing: &mut Vec<Envelope>) {
        if self.registered && self.failsafe.router_lost(now) {
            self.registered = false;
            self.next_hello = now;
            if let Some(auth) = self.auth.as_mut() {
                auth.forget_router();
            }
        }
        if !self.registered && now >= self.next_hello {
            self.next_hello = now + self.settings.hello_retry;
            let body = match self.auth.as_mut() {
                Some(auth) if !auth.synced() => Body::TimeRequest(auth.time_request()),
                _ => Body::Hello(self.hello()),
            };
            outgoing.push(self.envelope(mech_proto::ROUTER, body, now));
        }
    }

    /// A wheel driven without turning for the stall time: outputs held at
    /// zero as for an actuator fault, and the GCS told which wheel.
    fn watch_stall(&mut self, now: Duration, outgoing: &mut Vec<Envelope>) {
        let Some(stall) = self.wheels.as_mut().and_then(Wheels::take_stall) else {
            return;
        };
        self.counters.stalls += 1;
        let text = format!(
            "{} stalled: driven at {:.0}% for {:.2} s without an encoder edge; outputs zeroed",
            self.controller.platform().motor_name(stall.wheel),
            stall.output.abs() * 100.0,
            stall.for_time.as_secs_f64(),
        );
        tracing::error!(robot = %self.settings.name, "{text}");
        outgoing.extend(self.actuator_fault(&text, now));
    }

    /// The failsafe's verdict for this period: whether the robot may drive.
    /// Counts trips and idles the controller when it may not.
    fn judge_failsafe(&mut self, now: Duration) -> bool {
        let mission_running = self.mission_running();
        let state = self.failsafe_state(now);
        let drive = self.failsafe.may_drive(state, mission_running);
        if state != FailsafeState::Ok && self.last_state == FailsafeState::Ok {
            self.counters.failsafe_trips += 1;
            self.counters.tripped_at_us = self.stamp_origin_us + now.as_micros() as u64;
        }
        if state != self.last_state {
            tracing::info!(robot = %self.settings.name, from = ?self.last_state, to = ?state, "failsafe");
        }
        if !drive && !matches!(self.controller.mode(), Mode::Idle) {
            // The next accepted command (or a re-registration that finds a
            // mission to resume) starts motion again.
            self.controller.idle();
        }
        self.last_state = state;
        drive
    }

    /// This period's actuator outputs: the controller's, or zeros when the
    /// robot may not drive or lacks the position its mode needs.
    fn control(&mut self, drive: bool, now: Duration) {
        self.outputs.clear();
        let motors = self.controller.platform().motors();
        let needs_position = matches!(
            self.controller.mode(),
            Mode::VelocityHeading(_) | Mode::Waypoints
        );
        if !drive || (needs_position && self.estimate.is_none()) {
            self.outputs.resize(motors, 0.0);
            if let Some(w) = self.wheels.as_mut() {
                w.reset_loops();
            }
            return;
        }
        let pose = self.estimate.map(|e| e.pose).unwrap_or_default();
        let mission = self
            .missions
            .get_mut(&self.route.channel)
            .filter(|m| !m.paused);
        let out = self.controller.update(&pose, now, mission);
        match self.wheels.as_mut() {
            // Each output asks for a wheel speed; the speed loops deliver it.
            Some(w) => self.outputs.extend(w.close_loop(out, now)),
            None => self.outputs.extend_from_slice(out),
        }
    }

    /// The heartbeat and telemetry that are due.
    fn report(&mut self, now: Duration, outgoing: &mut Vec<Envelope>) {
        if now >= self.next_heartbeat {
            self.next_heartbeat = now + self.settings.hello_period;
            let echo = self.router_beat.take().map(|(seq, at)| Echo {
                seq,
                held_us: now.saturating_sub(at).as_micros() as u64,
            });
            outgoing.push(self.beat(now, echo));
        }
        if now >= self.next_telemetry {
            // Stay on the grid so the rate does not drift with jitter.
            self.next_telemetry = (self.next_telemetry + self.settings.telemetry_period).max(now);
            let t = Body::Telemetry(self.telemetry(now));
            outgoing.push(self.envelope(mech_proto::ROUTER, t, now));
        }
    }

    /// The robot's telemetry now. `velocity` is the twist the wheel
    /// encoders measure while their readings are fresh, otherwise the twist
    /// the current outputs produce (the platform's forward kinematics, which
    /// is what a robot without encoders knows of its motion); either is
    /// turned from the body frame into the world frame by the estimated
    /// heading, as the protocol specifies, and `velocity_source` says which.
    pub fn telemetry(&self, now: Duration) -> Telemetry {
        let state = self.failsafe_state(now);
        let platform = self.controller.platform();
        let (twist, velocity_source) = match self
            .wheel_speeds(now)
            .and_then(|speeds| platform.wheel_odometry(&speeds))
        {
            Some(measured) => (measured, VelocitySource::Measured),
            None => (platform.motion(&self.outputs), VelocitySource::Commanded),
        };
        let stale = self.settings.has_position
            && self
                .estimate
                .is_none_or(|e| now.saturating_sub(e.stamp) > self.settings.position_stale_after);
        let faulted = self
            .last_driver_fault
            .is_some_and(|t| now.saturating_sub(t) < Duration::from_secs(1));
        let pose = self.estimate.map(|e| e.pose).unwrap_or_default();
        let (sin, cos) = pose.heading.sin_cos();
        Telemetry {
            pose,
            velocity: Velocity {
                vx: twist.vx * cos - twist.vy * sin,
                vy: twist.vx * sin + twist.vy * cos,
                vz: twist.vz,
                wz: twist.wz,
            },
            mode: self.controller.mode().control_mode(),
            channel: self.route.channel.clone(),
            computation: if self.route.channel.starts_with("offboard/") {
                Computation::Offboard
            } else {
                Computation::Onboard
            },
            failsafe: state,
            health: if faulted {
                Health::Fault
            } else if stale {
                Health::Degraded
            } else {
                Health::Ok
            },
            battery: None,
            position_quality: self.estimate.map_or(0.0, |e| e.quality.clamp(0.0, 1.0)),
            actuators: self.outputs.clone(),
            mission: self
                .missions
                .get(&self.route.channel)
                .map(MissionRun::progress),
            stale: self.stale_total(),
            velocity_source,
            safety: None,
        }
    }

    /// Messages ignored as stale, for telemetry.
    fn stale_total(&self) -> u32 {
        let c = &self.counters;
        let n = c.stale_commands + c.stale_estops + c.stale_routes + c.stale_missions;
        u32::try_from(n).unwrap_or(u32::MAX)
    }

    /// A heartbeat as a robot with several links sends on each link it is
    /// not using, so the router hears which are alive (no echo: the round
    /// trip is timed on the link in use).
    pub fn heartbeat(&mut self, now: Duration) -> Envelope {
        self.beat(now, None)
    }

    /// A heartbeat, echoing the router's newest one when there is one (the
    /// periodic heartbeat, every `hello_period`).
    fn beat(&mut self, now: Duration, echo: Option<Echo>) -> Envelope {
        let hb = Body::Heartbeat(Heartbeat {
            uptime_ms: now.as_millis() as u64,
            echo,
        });
        self.envelope(mech_proto::ROUTER, hb, now)
    }

    /// The `Bye` sent when the agent shuts down.
    pub fn bye(&mut self, reason: &str, now: Duration) -> Envelope {
        self.envelope(
            mech_proto::ROUTER,
            Body::Bye(Bye {
                reason: truncate(reason),
            }),
            now,
        )
    }

    fn mission_running(&self) -> bool {
        matches!(self.controller.mode(), Mode::Waypoints)
            && self
                .missions
                .get(&self.route.channel)
                .is_some_and(|m| !m.paused && !m.finished())
    }

    /// The routed channel's mission is finished: the robot holds at its
    /// last waypoint, as told.
    fn mission_done_on_route(&self) -> bool {
        self.missions
            .get(&self.route.channel)
            .is_some_and(|m| !m.paused && m.finished())
    }

    fn apply_route(&mut self, route: Route, now: Duration, out: &mut Vec<Envelope>) {
        let changed = !self.routed_once
            || route.channel != self.route.channel
            || route.epoch != self.route.epoch;
        if changed {
            tracing::info!(robot = %self.settings.name, channel = %route.channel, epoch = route.epoch, "route");
            self.routed_once = true;
            self.order.clear();
            self.controller.idle();
            self.failsafe.channel_heard(now);
            self.route.channel = route.channel;
            self.route.epoch = route.epoch;
            // Re-routing to a channel resumes its paused mission, but not
            // while e-stopped: missions stay paused through a release.
            if !self.failsafe.estopped()
                && let Some(m) = self.missions.get_mut(&self.route.channel)
            {
                m.paused = false;
            }
        }
        self.resume_mission(now);
        let ack = Body::RouteAck(RouteAck {
            robot: self.settings.name.clone(),
            channel: self.route.channel.clone(),
            epoch: self.route.epoch,
        });
        out.push(self.envelope(mech_proto::ROUTER, ack, now));
    }

    /// Follows the routed channel's mission if one is waiting and the robot
    /// is otherwise idle.
    fn resume_mission(&mut self, now: Duration) {
        let runnable = self
            .missions
            .get(&self.route.channel)
            .is_some_and(|m| !m.paused && !m.finished());
        if runnable
            && !self.failsafe.estopped()
            && matches!(self.controller.mode(), Mode::Idle)
            && self.controller.follow_mission().is_ok()
        {
            self.failsafe.channel_heard(now);
        }
    }

    /// Obeys a command if it comes on the routed channel, the robot is not
    /// e-stopped, and it is not older than one already obeyed from its
    /// sender (`stamp` = its header's sequence number and stamp).
    fn command(
        &mut self,
        channel: &str,
        sender: &str,
        stamp: (u32, u64),
        cmd: &Command,
        now: Duration,
        out: &mut Vec<Envelope>,
    ) {
        if self.failsafe.estopped() {
            self.counters.ignored_estopped += 1;
            return;
        }
        if self.route.channel.is_empty() || channel != self.route.channel {
            self.counters.not_routed += 1;
            let quiet = self
                .last_not_routed_notice
                .is_some_and(|t| now.saturating_sub(t) < Duration::from_secs(1));
            if self.settings.notify_not_routed && !quiet {
                self.last_not_routed_notice = Some(now);
                let text = format!(
                    "{} obeys channel {:?}; command on {channel:?} rejected",
                    self.settings.name, self.route.channel
                );
                let notice = Body::Notice(Notice {
                    level: Level::Warn,
                    code: NoticeCode::NotRouted,
                    text: truncate(&text),
                });
                out.push(self.envelope(sender, notice, now));
            }
            return;
        }
        let restart_after = self.settings.failsafe.channel_timeout;
        if !self
            .order
            .admit(sender, channel, stamp.0, stamp.1, now, restart_after)
        {
            self.counters.stale_commands += 1;
            return;
        }
        if matches!(cmd, Command::Stop(_)) {
            // A stop holds: the channel's mission must not resume by itself
            // (on a re-registration or a mission resend) until re-sent or
            // re-routed.
            if let Some(m) = self.missions.get_mut(channel) {
                m.paused = true;
            }
        }
        match self.controller.command(cmd) {
            Ok(()) => {
                self.counters.commands += 1;
                self.failsafe.channel_heard(now);
            }
            Err(e) => {
                self.counters.refused += 1;
                let notice = Body::Notice(Notice {
                    level: Level::Warn,
                    code: NoticeCode::Unsupported,
                    text: truncate(&e.to_string()),
                });
                out.push(self.envelope(sender, notice, now));
            }
        }
    }

    fn mission_received(
        &mut self,
        channel: &str,
        mission: Mission,
        now: Duration,
        out: &mut Vec<Envelope>,
    ) {
        let id = mission.id;
        if channel.is_empty() {
            // A robot routed to none has the empty channel: a mission on it
            // would run without anyone having routed the robot.
            self.counters.refused += 1;
            let ack = Body::MissionAck(MissionAck {
                id,
                accepted: false,
                reason: "a mission must be sent on a channel".to_string(),
            });
            out.push(self.envelope(mech_proto::ROUTER, ack, now));
            return;
        }
        if !self
            .controller
            .capabilities()
            .contains(&CommandKind::Waypoints)
        {
            let reason = if self.settings.has_position {
                "this platform does not follow waypoints"
            } else {
                "this robot has no position source"
            };
            let ack = Body::MissionAck(MissionAck {
                id,
                accepted: false,
                reason: reason.to_string(),
            });
            out.push(self.envelope(mech_proto::ROUTER, ack, now));
            return;
        }
        if self
            .missions
            .get(channel)
            .is_some_and(|run| is_older(id, run.mission.id))
        {
            // A delayed copy of a mission already replaced on this channel:
            // not acknowledged (the router stopped retrying it long ago).
            self.counters.stale_missions += 1;
            return;
        }
        let paused = match self.missions.get_mut(channel) {
            // A repeated id is a retry of an upload already held (its ack was
            // lost): progress and pause are kept, so a retry never restarts a
            // stopped or e-stopped mission. A re-send uses a new id.
            Some(run) if run.mission.id == id => {
                run.paused |= self.failsafe.estopped();
                run.paused
            }
            _ => {
                let mut run = MissionRun::new(mission);
                run.paused = self.failsafe.estopped();
                let paused = run.paused;
                self.missions.insert(channel.to_string(), run);
                paused
            }
        };
        if channel == self.route.channel && !paused && self.controller.follow_mission().is_ok() {
            self.failsafe.channel_heard(now);
        }
        let ack = Body::MissionAck(MissionAck {
            id,
            accepted: true,
            reason: String::new(),
        });
        out.push(self.envelope(mech_proto::ROUTER, ack, now));
    }

    fn envelope(&mut self, destination: &str, body: Body, now: Duration) -> Envelope {
        self.seq = self.seq.wrapping_add(1);
        Envelope::new(
            Header {
                seq: self.seq,
                stamp_us: self.stamp_origin_us + now.as_micros() as u64,
                sender: self.settings.name.clone(),
                destination: destination.to_string(),
                channel: String::new(),
            },
            body,
        )
    }
}

/// The estimate with the fused planar pose; height, quality and stamp stay
/// the median filter's (odometry is planar, and the stamp says how fresh the
/// fixes are).
fn fused(fusion: &PoseFusion, mut estimate: PositionSample) -> PositionSample {
    if let Some(p) = fusion.pose() {
        estimate.pose = mech_proto::Pose {
            z: estimate.pose.z,
            ..p
        };
        estimate.has_heading = true;
    }
    estimate
}

/// The platform's odometry as a matrix: column `i` is the body displacement
/// (forward, left, heading) of one metre of wheel `i`'s travel.
fn wheel_jacobian(platform: &dyn Platform) -> Option<DMatrix<f64>> {
    let n = platform.motors();
    let mut j = DMatrix::zeros(3, n);
    for i in 0..n {
        let mut unit = vec![0.0; n];
        unit[i] = 1.0;
        let Twist { vx, vy, wz, .. } = platform.wheel_odometry(&unit)?;
        j.set_column(i, &Vector3::new(vx, vy, wz));
    }
    Some(j)
}

/// Cuts free text to the protocol's limit on a character boundary.
fn truncate(text: &str) -> String {
    let mut end = text.len().min(mech_proto::MAX_TEXT_LEN);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    text[..end].to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::platform::PlatformSpec;
    use mech_proto::{EStop, Pose, Twist, Waypoint, Welcome};

    const PERIOD: Duration = Duration::from_millis(20);

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    fn msg(channel: &str, body: Body) -> Envelope {
        Envelope::new(
            Header {
                sender: "ctl".into(),
                destination: "r1".into(),
                channel: channel.into(),
                ..Header::default()
            },
            body,
        )
    }

    fn twist(vx: f64) -> Body {
        Body::Command(Command::Twist(Twist {
            vx,
            ..Twist::default()
        }))
    }

    fn route(channel: &str, epoch: u32) -> Body {
        Body::Route(Route {
            robot: "r1".into(),
            channel: channel.into(),
            epoch,
        })
    }

    /// A registered agent with a position, routed to `channel`.
    fn routed(channel: &str) -> Agent {
        let mut a = Agent::new(
            AgentSettings::new("r1"),
            PlatformSpec::diff_drive().build(),
            0,
        );
        a.observe_position(PositionSample {
            pose: Pose::default(),
            stamp: ms(0),
            quality: 1.0,
            has_heading: true,
        });
        let w = Body::Welcome(Welcome {
            robot_id: 1,
            route: Route {
                robot: "r1".into(),
                channel: channel.into(),
                epoch: 1,
            },
            router_version: "t".into(),
        });
        let out = a.handle(msg("", w), ms(0));
        assert!(matches!(&out[0].body, Body::RouteAck(r) if r.channel == channel && r.epoch == 1));
        a
    }

    fn moving(outputs: &[f64]) -> bool {
        outputs.iter().any(|u| *u != 0.0)
    }

    #[test]
    fn says_hello_every_quarter_second_until_welcomed() {
        let mut a = Agent::new(AgentSettings::new("r1"), PlatformSpec::kiwi().build(), 0);
        let hellos = |t: &Tick| {
            t.outgoing
                .iter()
                .filter(|e| matches!(e.body, Body::Hello(_)))
                .count()
        };
        assert_eq!(hellos(&a.tick(ms(0))), 1);
        assert_eq!(hellos(&a.tick(ms(200))), 0);
        let t = a.tick(ms(250));
        assert_eq!(hellos(&t), 1);
        let Body::Hello(h) = &t.outgoing[0].body else {
            panic!()
        };
        assert_eq!((h.platform.as_str(), h.motors), ("kiwi", 3));
        assert!(h.capabilities.contains(&CommandKind::Waypoints));
        a.handle(msg("", route("", 0)), ms(1010));
        assert!(!a.registered(), "only Welcome registers");
        a.handle(
            msg(
                "",
                Body::Welcome(Welcome {
                    robot_id: 1,
                    route: Route {
                        robot: "r1".into(),
                        channel: "".into(),
                        epoch: 0,
                    },
                    router_version: "t".into(),
                }),
            ),
            ms(1020),
        );
        let t = a.tick(ms(2000));
        assert_eq!(hellos(&t), 0);
        assert!(
            t.outgoing
                .iter()
                .any(|e| matches!(e.body, Body::Telemetry(_)))
        );
    }

    #[test]
    fn obeys_the_routed_channel_and_rejects_others() {
        let mut a = routed("joy/0");
        a.handle(msg("joy/0", twist(0.2)), ms(10));
        assert!(moving(&a.tick(ms(20)).outputs));
        let out = a.handle(msg("key/0", twist(-0.3)), ms(30));
        assert!(matches!(&out[0].body, Body::Notice(n) if n.code == NoticeCode::NotRouted));
        assert_eq!(out[0].header.destination, "ctl");
        let t = a.tick(ms(40));
        assert!(
            t.outputs.iter().all(|u| *u > 0.0),
            "still the joy/0 command: {:?}",
            t.outputs
        );
        assert_eq!(a.counters().not_routed, 1);
        // A second rejection within a second is counted but not answered.
        assert!(a.handle(msg("key/0", twist(-0.3)), ms(50)).is_empty());
        assert_eq!(a.counters().not_routed, 2);
    }

    #[test]
    fn unrouted_robot_holds_still() {
        let mut a = routed("");
        a.handle(msg("joy/0", twist(0.2)), ms(10));
        assert!(!moving(&a.tick(ms(20)).outputs));
        assert_eq!(a.counters().not_routed, 1);
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

    fn router_heartbeat(a: &mut Agent, now: Duration) {
        a.handle(msg("", Body::Heartbeat(Heartbeat::new(0))), now);
    }

    #[test]
    fn a_heartbeat_echoes_the_newest_router_heartbeat_once() {
        let mut a = routed("");
        let echoes = |t: &Tick| -> Vec<Option<Echo>> {
            t.outgoing
                .iter()
                .filter_map(|e| match e.body {
                    Body::Heartbeat(h) => Some(h.echo),
                    _ => None,
                })
                .collect()
        };
        // Registration makes a heartbeat due at once: nothing to echo yet.
        assert_eq!(echoes(&a.tick(ms(0))), [None]);
        for (seq, at) in [(40, 300), (41, 550)] {
            let mut beat = msg("", Body::Heartbeat(Heartbeat::new(0)));
            beat.header.seq = seq;
            a.handle(beat, ms(at));
        }
        let held = Duration::from_millis(1000 - 550).as_micros() as u64;
        assert_eq!(
            echoes(&a.tick(ms(1000))),
            [Some(Echo {
                seq: 41,
                held_us: held
            })],
            "the newest, with the time it was held"
        );
        a.handle(msg("", route("", 2)), ms(1500)); // the router is still heard
        assert_eq!(echoes(&a.tick(ms(2000))), [None], "each is echoed once");
    }

    #[test]
    fn a_router_that_does_not_know_the_robot_gets_a_hello_at_once() {
        let mut a = routed("joy/0");
        let t = a.tick(ms(100));
        assert!(!t.outgoing.iter().any(|e| matches!(e.body, Body::Hello(_))));
        let notice = Body::Notice(Notice {
            level: Level::Warn,
            code: NoticeCode::UnknownRobot,
            text: "send Hello".into(),
        });
        a.handle(msg("", notice), ms(110));
        assert!(!a.registered());
        let t = a.tick(ms(120));
        assert!(
            t.outgoing.iter().any(|e| matches!(e.body, Body::Hello(_))),
            "Hello at the next period, not after the router timeout"
        );
        assert_eq!(a.counters().reregistered, 1);
    }

    #[test]
    fn frames_for_other_robots_on_a_shared_radio_are_skipped() {
        let mut a = routed("joy/0");
        let other = Envelope::new(
            Header {
                destination: "r2".into(),
                channel: "joy/0".into(),
                ..Header::default()
            },
            twist(0.5),
        );
        a.handle_bytes(&mech_proto::encode(&other).unwrap(), ms(10));
        assert!(!moving(&a.tick(ms(20)).outputs));
        assert_eq!(a.counters().not_for_me, 1);
        assert_eq!(a.counters().commands, 0);
        a.handle_bytes(
            &mech_proto::encode(&msg("joy/0", twist(0.5))).unwrap(),
            ms(30),
        );
        assert_eq!(a.counters().commands, 1);
    }

    #[test]
    fn router_loss_stops_and_re_registers() {
        let mut a = routed("joy/0");
        let mut now = ms(0);
        let mut stopped = None;
        while now < ms(3000) {
            now += PERIOD;
            // Everything arrives through the router: after 100 ms it is gone.
            if now <= ms(100) {
                a.handle(msg("joy/0", twist(0.2)), now);
            }
            let t = a.tick(now);
            if stopped.is_none() && !moving(&t.outputs) {
                stopped = Some(now);
            }
            if a.failsafe_state(now) == FailsafeState::RouterLost {
                assert!(
                    t.outgoing.iter().any(|e| matches!(e.body, Body::Hello(_))),
                    "registers again at once"
                );
                break;
            }
        }
        assert_eq!(a.failsafe_state(now), FailsafeState::RouterLost);
        assert!(!a.registered());
        assert!(stopped.unwrap() <= ms(100) + ms(500) + PERIOD);
    }

    #[test]
    fn a_router_bye_stops_at_once_and_registers_again() {
        let mut a = routed("joy/0");
        let now = ms(100);
        a.handle(msg("joy/0", twist(0.2)), now);
        assert!(moving(&a.tick(now).outputs));
        // A Bye from anyone but the router is not the router leaving.
        let bye = |sender: &str| {
            let mut m = msg(
                "",
                Body::Bye(Bye {
                    reason: "stopping".into(),
                }),
            );
            m.header.sender = sender.into();
            m
        };
        a.handle(bye("ctl"), now);
        assert_ne!(a.failsafe_state(now), FailsafeState::RouterLost);
        a.handle(bye(mech_proto::ROUTER), now);
        assert_eq!(a.failsafe_state(now), FailsafeState::RouterLost);
        let t = a.tick(now + PERIOD);
        assert!(!moving(&t.outputs), "stops on the next tick");
        assert!(
            t.outgoing.iter().any(|e| matches!(e.body, Body::Hello(_))),
            "asks to register again at once"
        );
    }

    #[test]
    fn route_change_zeroes_acks_and_switches_channel() {
        let mut a = routed("joy/0");
        a.handle(msg("joy/0", twist(0.2)), ms(10));
        assert!(moving(&a.tick(ms(20)).outputs));
        let out = a.handle(msg("", route("wp/gcs", 2)), ms(30));
        assert!(matches!(&out[0].body, Body::RouteAck(r) if r.channel == "wp/gcs" && r.epoch == 2));
        assert!(!moving(&a.tick(ms(40)).outputs), "zeroed on switch");
        a.handle(msg("joy/0", twist(0.2)), ms(50));
        assert!(!moving(&a.tick(ms(60)).outputs), "old channel now rejected");
        a.handle(msg("wp/gcs", twist(0.1)), ms(70));
        assert!(moving(&a.tick(ms(80)).outputs));
        // A repeated Route (router retry) is acked again but changes nothing.
        let out = a.handle(msg("", route("wp/gcs", 2)), ms(90));
        assert!(matches!(&out[0].body, Body::RouteAck(_)));
        assert!(moving(&a.tick(ms(100)).outputs));
        let t = a.telemetry(ms(100));
        assert_eq!(t.channel, "wp/gcs");
        assert_eq!(t.computation, Computation::Onboard);
        a.handle(msg("", route("offboard/r1", 3)), ms(110));
        assert_eq!(a.telemetry(ms(110)).computation, Computation::Offboard);
    }

    #[test]
    fn estop_latches_until_release_and_pauses_missions() {
        let mut a = routed("wp/gcs");
        let mission = mission_to(5, 2.0);
        let out = a.handle(msg("wp/gcs", Body::Mission(mission.clone())), ms(10));
        assert!(matches!(&out[0].body, Body::MissionAck(m) if m.id == 5 && m.accepted));
        assert!(moving(&a.tick(ms(20)).outputs));
        let out = a.handle(
            msg(
                "",
                Body::EStop(EStop {
                    engage: true,
                    id: 9,
                }),
            ),
            ms(30),
        );
        assert!(matches!(&out[0].body, Body::EStopAck(e) if e.engage && e.id == 9));
        assert!(!moving(&a.tick(ms(40)).outputs));
        a.handle(msg("wp/gcs", twist(0.2)), ms(50));
        assert!(
            !moving(&a.tick(ms(60)).outputs),
            "commands ignored while latched"
        );
        assert_eq!(a.failsafe_state(ms(60)), FailsafeState::EStopped);
        a.handle(
            msg(
                "",
                Body::EStop(EStop {
                    engage: false,
                    id: 10,
                }),
            ),
            ms(70),
        );
        assert!(
            !moving(&a.tick(ms(80)).outputs),
            "mission stays paused after release"
        );
        a.handle(msg("wp/gcs", twist(0.2)), ms(90));
        assert!(moving(&a.tick(ms(100)).outputs), "obeys the next command");
        // Re-sending the mission (a new upload, so a new id) resumes it.
        let resent = Mission { id: 6, ..mission };
        a.handle(msg("wp/gcs", Body::Mission(resent)), ms(110));
        assert_eq!(*a.mode(), Mode::Waypoints);
        assert!(moving(&a.tick(ms(120)).outputs));
    }

    #[test]
    fn mission_runs_only_while_routed_and_ignores_channel_silence() {
        let mut a = routed("joy/0");
        let mission = mission_to(1, 5.0);
        let out = a.handle(msg("wp/gcs", Body::Mission(mission)), ms(10));
        assert!(
            matches!(&out[0].body, Body::MissionAck(m) if m.accepted),
            "stored and acked while not routed"
        );
        a.tick(ms(20));
        assert_ne!(*a.mode(), Mode::Waypoints);
        a.handle(msg("", route("wp/gcs", 2)), ms(30));
        assert_eq!(*a.mode(), Mode::Waypoints);
        let mut now = ms(30);
        while now < ms(3000) {
            now += PERIOD;
            router_heartbeat(&mut a, now);
            assert!(
                moving(&a.tick(now).outputs),
                "mission is its own controller"
            );
        }
        let tel = a.telemetry(now);
        assert_eq!(
            tel.mission.map(|m| (m.id, m.next, m.total)),
            Some((1, 0, 1))
        );
        assert_eq!(tel.mode, mech_proto::ControlMode::Waypoints);
    }

    #[test]
    fn a_finished_mission_holds_without_reading_as_channel_silence() {
        let mut a = routed("wp/gcs");
        // The robot is at the origin: a waypoint there is reached at once.
        a.handle(msg("wp/gcs", Body::Mission(mission_to(1, 0.0))), ms(10));
        let mut now = ms(10);
        while now < ms(2000) {
            now += PERIOD;
            router_heartbeat(&mut a, now);
            assert!(!moving(&a.tick(now).outputs), "holds at the waypoint");
        }
        let tel = a.telemetry(now);
        assert_eq!(tel.mission.map(|m| (m.next, m.total)), Some((1, 1)));
        assert_eq!(tel.failsafe, FailsafeState::Ok, "done, not silent");
        // A controller that goes quiet on a channel without a mission still
        // reads as silent.
        let mut b = routed("joy/0");
        router_heartbeat(&mut b, ms(2000));
        assert_eq!(b.failsafe_state(ms(2000)), FailsafeState::ChannelSilent);
    }

    #[test]
    fn mission_on_router_loss_follows_config() {
        for continues in [false, true] {
            let mut settings = AgentSettings::new("r1");
            settings.failsafe.mission_continues_on_link_loss = continues;
            let mut a = Agent::new(settings, PlatformSpec::diff_drive().build(), 0);
            a.observe_position(PositionSample {
                pose: Pose::default(),
                stamp: ms(0),
                quality: 1.0,
                has_heading: true,
            });
            a.handle(
                msg(
                    "",
                    Body::Welcome(Welcome {
                        robot_id: 1,
                        route: Route {
                            robot: "r1".into(),
                            channel: "wp/gcs".into(),
                            epoch: 1,
                        },
                        router_version: "t".into(),
                    }),
                ),
                ms(0),
            );
            let mission = mission_to(1, 5.0);
            a.handle(msg("wp/gcs", Body::Mission(mission)), ms(0));
            let t = a.tick(ms(2000));
            assert_eq!(a.failsafe_state(ms(2000)), FailsafeState::RouterLost);
            assert_eq!(moving(&t.outputs), continues, "continues = {continues}");
        }
    }

    #[test]
    fn undecodable_bytes_and_unsupported_commands_are_counted() {
        let mut a = routed("joy/0");
        assert!(a.handle_bytes(&[0x93, 0x01, 0xff], ms(5)).is_empty());
        assert_eq!(a.counters().bad_messages, 1);
        let out = a.handle(
            msg(
                "joy/0",
                Body::Command(Command::Actuators(mech_proto::Actuators {
                    outputs: vec![0.5],
                })),
            ),
            ms(10),
        );
        assert!(matches!(&out[0].body, Body::Notice(n) if n.code == NoticeCode::Unsupported));
        assert_eq!(a.counters().refused, 1);
        let mut other = msg("joy/0", twist(0.2));
        other.header.destination = "r2".into();
        a.handle(other, ms(20));
        assert_eq!(a.counters().not_for_me, 1);
        assert!(!moving(&a.tick(ms(30)).outputs));
    }

    #[test]
    fn actuator_fault_holds_outputs_at_zero_then_recovers() {
        let mut a = routed("joy/0");
        a.handle(msg("joy/0", twist(0.2)), ms(10));
        assert!(moving(&a.tick(ms(20)).outputs));
        assert!(a.actuator_fault("left motor: I/O error", ms(25)).is_some());
        assert!(
            a.actuator_fault("left motor: I/O error", ms(26)).is_none(),
            "one notice a second"
        );
        a.handle(msg("joy/0", twist(0.2)), ms(30));
        let t = a.tick(ms(40));
        assert!(!moving(&t.outputs));
        assert_eq!(a.failsafe_state(ms(40)), FailsafeState::Fault);
        assert_eq!(a.telemetry(ms(40)).health, Health::Fault);
        router_heartbeat(&mut a, ms(1100));
        a.handle(msg("joy/0", twist(0.2)), ms(1100));
        assert!(
            moving(&a.tick(ms(1110)).outputs),
            "recovers once the driver works"
        );
        assert_eq!(a.counters().driver_faults, 2);
    }

    fn estop(engage: bool, id: u32) -> Body {
        Body::EStop(EStop { engage, id })
    }

    /// A mission of one waypoint at (`x`, 0), 5 cm arrival radius.
    fn mission_to(id: u32, x: f64) -> Mission {
        Mission {
            id,
            waypoints: vec![Waypoint {
                x,
                y: 0.0,
                z: 0.0,
                time: None,
            }],
            looped: false,
            arrival_radius: 0.05,
            start_index: 0,
        }
    }

    fn one_waypoint(id: u32) -> Body {
        Body::Mission(mission_to(id, 2.0))
    }

    #[test]
    fn a_delayed_release_cannot_undo_a_newer_estop() {
        let mut a = routed("joy/0");
        a.handle(msg("", estop(true, 9)), ms(0));
        a.handle(msg("", estop(false, 10)), ms(10));
        a.handle(msg("", estop(true, 11)), ms(20));
        // A resend of release 10, overtaken on the way by e-stop 11.
        let out = a.handle(msg("", estop(false, 10)), ms(30));
        assert!(out.is_empty(), "a stale release is not acknowledged");
        assert_eq!(a.failsafe_state(ms(30)), FailsafeState::EStopped);
        assert_eq!(a.counters().stale_estops, 1);
        a.handle(msg("", estop(false, 12)), ms(40));
        assert_eq!(a.failsafe_state(ms(40)), FailsafeState::Ok);
    }

    #[test]
    fn a_mission_without_a_channel_is_refused_by_an_unrouted_robot() {
        let mut a = routed("");
        let out = a.handle(msg("", one_waypoint(3)), ms(0));
        assert!(matches!(&out[0].body, Body::MissionAck(m) if m.id == 3 && !m.accepted));
        assert!(
            !moving(&a.tick(ms(20)).outputs),
            "routed to none, it holds still"
        );
    }

    #[test]
    fn a_stop_holds_the_mission_through_a_re_registration() {
        let mut a = routed("wp/gcs");
        a.handle(msg("wp/gcs", one_waypoint(5)), ms(0));
        assert!(moving(&a.tick(ms(20)).outputs));
        a.handle(
            msg("wp/gcs", Body::Command(Command::Stop(mech_proto::Stop {}))),
            ms(30),
        );
        assert!(!moving(&a.tick(ms(40)).outputs));
        // The router repeats the mission (its ack was lost), then the robot
        // re-registers after a link drop: neither restarts the mission.
        a.handle(msg("wp/gcs", one_waypoint(5)), ms(50));
        let w = Body::Welcome(Welcome {
            robot_id: 1,
            route: Route {
                robot: "r1".into(),
                channel: "wp/gcs".into(),
                epoch: 1,
            },
            router_version: "t".into(),
        });
        a.handle(msg("", w), ms(2000));
        assert!(!moving(&a.tick(ms(2020)).outputs), "the stop holds");
    }

    #[test]
    fn re_routing_while_estopped_keeps_missions_paused() {
        let mut a = routed("wp/gcs");
        a.handle(msg("wp/gcs", one_waypoint(5)), ms(0));
        a.handle(msg("", estop(true, 1)), ms(10));
        a.handle(msg("", route("joy/0", 2)), ms(20));
        a.handle(msg("", route("wp/gcs", 3)), ms(30));
        a.handle(msg("", estop(false, 2)), ms(40));
        // A resend of the route after the release must not start it either.
        a.handle(msg("", route("wp/gcs", 3)), ms(50));
        assert!(
            !moving(&a.tick(ms(60)).outputs),
            "the mission stays paused until re-sent"
        );
    }

    #[test]
    fn telemetry_velocity_is_in_the_world_frame() {
        let mut a = routed("joy/0");
        // Enough samples facing +y to fill the median filter's window.
        for _ in 0..AgentSettings::new("r1").filter_window {
            a.observe_position(PositionSample {
                pose: Pose {
                    heading: std::f64::consts::FRAC_PI_2,
                    ..Pose::default()
                },
                stamp: ms(0),
                quality: 1.0,
                has_heading: true,
            });
        }
        a.handle(msg("joy/0", twist(0.2)), ms(0));
        a.tick(PERIOD);
        let v = a.telemetry(PERIOD).velocity;
        // Facing +y, driving forward moves the robot along world +y.
        assert!(v.vx.abs() < 1e-9, "vx {}", v.vx);
        assert!(v.vy > 0.1, "vy {}", v.vy);
    }

    #[test]
    fn an_encoder_reading_that_does_not_fit_the_robot_is_a_driver_fault() {
        let mut s = AgentSettings::new("r1");
        s.wheels = Some(WheelSettings {
            counting: crate::hal::Counting::Quadrature,
            counts_per_revolution: 1440.0,
            wheel_radius: 0.03,
            speed_loop: None,
            stall: crate::wheels::StallSettings::default(),
        });
        let mut a = Agent::new(s, PlatformSpec::diff_drive().build(), 0);
        let notice = a.observe_wheels(&[EdgeCount::default()], ms(0)).unwrap();
        assert!(
            matches!(&notice.body, Body::Notice(n) if n.code == NoticeCode::DriverFault && n.text.contains("1 encoder readings for 2 wheels"))
        );
        assert_eq!(a.counters().driver_faults, 1);
        // A robot without [encoders] ignores readings.
        let mut plain = Agent::new(
            AgentSettings::new("r1"),
            PlatformSpec::diff_drive().build(),
            0,
        );
        assert!(
            plain
                .observe_wheels(&[EdgeCount::default()], ms(0))
                .is_none()
        );
        assert_eq!(
            plain.telemetry(ms(0)).velocity_source,
            VelocitySource::Commanded
        );
    }

    #[test]
    fn external_position_fixes_feed_the_filter_only_when_configured() {
        for external in [false, true] {
            let mut s = AgentSettings::new("r1");
            s.external_position = external;
            let mut a = Agent::new(s, PlatformSpec::diff_drive().build(), 0);
            let fix = mech_proto::PositionFix {
                robot: "r1".into(),
                pose: Pose {
                    x: 1.5,
                    ..Pose::default()
                },
                quality: 0.9,
            };
            a.handle(msg("", Body::PositionFix(fix)), ms(0));
            assert_eq!(a.estimate().map(|e| e.pose.x), external.then_some(1.5));
        }
    }
}

#[cfg(test)]
mod loss_tests {
    //! The failsafe under packet loss: a controller publishing at 25 Hz over
    //! a link losing 30% of its messages never trips the 0.5 s timeout, and
    //! when the controller stops, the robot stops within timeout + one
    //! control period.
    use super::*;
    use crate::platform::PlatformSpec;
    use mech_proto::{Twist, Welcome};
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
