//! A fleet of simulated robots running the real agent core against a real
//! station over loopback UDP, for fleet safety's tests and benchmark.
//!
//! The station is a [`Gcs`] with the demo arena and its neighbour
//! broadcaster; each robot is a [`SimAgent`] (the agent core driving a
//! simulated vehicle, true poses) with its own UDP socket; controllers are
//! in-process publishers, one channel per robot, whose commands take the
//! router's path like any peer's. Everything the robots know of each other
//! comes from the station's `Neighbours`.
//!
//! The robots are stepped together in simulated time, one control period
//! at a time (every message that arrived meanwhile handled first), and
//! never ahead of the wall clock: the station runs in real time, so a
//! state it reports is never younger in simulated time than it says. On a
//! loaded machine the simulation falls behind the clock, which only makes
//! the station's information look older to the robots.
//!
//! Positions are true (no noise, no filter lag), as the lock-step trials'
//! are, unless the rig is made with [`Options::noisy`]: then each robot
//! measures its position as the demo's robots do (UWB-like noise and
//! outliers through the median filter, with its `position_error`), and
//! every figure is still measured on the simulator's true poses.
//! The layer "off" is the operator's switch (`safety off`) for every robot,
//! so a run with it off differs in nothing else. Each control period the
//! true poses are measured: the smallest gap between two robots' discs, the
//! smallest clearance to the arena's edges, and the periods in which either
//! fell below the margin (violations) or below zero (collisions,
//! breaches).

#![allow(dead_code)]

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use mech_agent::PlatformSpec;
use mech_agent::machine::AgentSettings;
use mech_agent::safety::{Fence, SafetyConfig, Vec2};
use mech_agent::sim::safety_trial::clearance;
use mech_agent::sim::{SimAgent, UwbNoise, UwbNoiseModel};
use mech_core::router::Publishers;
use mech_core::{ArenaConfig, CoreConfig, Gcs};
use mech_proto::{Command, Pose, SafetyState, Waypoint};
use tokio::net::UdpSocket;

/// What a run measured, over every control period.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Metrics {
    /// Smallest distance between two robots' discs, m (negative: they
    /// overlapped).
    pub min_gap: f64,
    /// Periods in which two discs were closer than the margin (by more
    /// than the tolerance).
    pub separation_violations: u64,
    /// Periods in which two discs overlapped.
    pub collisions: u64,
    /// Smallest distance between a disc and the arena's edges (boundary,
    /// keep-outs) or a static disc of the arena, m.
    pub min_clearance: f64,
    /// Periods in which a disc came closer to an edge than the margin (by
    /// more than the tolerance).
    pub margin_violations: u64,
    /// Periods in which a disc crossed the boundary (a fence breach).
    pub breaches: u64,
    /// Fastest speed of a robot whose neighbour lists had been dropped for
    /// longer than its stale limit, one list period and half a second for
    /// its actuators to follow (they lag), m/s.
    pub max_stale_speed: f64,
    /// Simulated time in which two discs or a disc and an edge were closer
    /// than the margin (by more than the tolerance), s.
    pub below_margin: f64,
    /// Fastest true speed of a robot whose centre was inside a slow zone,
    /// above the zone's cap, m/s (0: never faster than a cap).
    pub zone_overspeed: f64,
    /// Largest distance between a robot's true position and the one it
    /// reported, m.
    pub max_estimate_error: f64,
}

impl Default for Metrics {
    fn default() -> Self {
        Metrics {
            min_gap: f64::INFINITY,
            separation_violations: 0,
            collisions: 0,
            min_clearance: f64::INFINITY,
            margin_violations: 0,
            breaches: 0,
            max_stale_speed: 0.0,
            below_margin: 0.0,
            zone_overspeed: 0.0,
            max_estimate_error: 0.0,
        }
    }
}

/// One simulated robot and its link.
struct Robot {
    name: String,
    sim: SimAgent,
    socket: UdpSocket,
    /// The channel its controller publishes on.
    channel: String,
    /// What its controller publishes (again every 100 ms, so the channel
    /// never goes silent).
    command: Option<Command>,
    /// Neighbour lists to it are dropped from this time on.
    drop_neighbours_from: Option<Duration>,
    /// When it finished its mission.
    arrived: Option<Duration>,
    /// Where its telemetry says it is (its estimate), after its last
    /// period.
    reported: Option<Vec2>,
}

impl Robot {
    fn position(&self) -> Vec2 {
        let p = self.sim.robot.pose();
        Vec2::new(p.x, p.y)
    }

    fn velocity(&self) -> Vec2 {
        let t = self.sim.robot.twist();
        Vec2::new(t.vx, t.vy).rotated(self.sim.robot.pose().heading)
    }
}

/// How a rig's robots sense and move.
#[derive(Debug, Clone)]
pub struct Options {
    /// Seed of the robots' position noise (robot `i` uses `seed + i`);
    /// `None`: true poses every period.
    pub noise: Option<u64>,
    /// Control period.
    pub dt: Duration,
    /// Every robot's `[safety]`.
    pub safety: SafetyConfig,
    /// Fraction of its top speed a robot drives a mission at.
    pub cruise_fraction: f64,
    /// The station's arena.
    pub arena: ArenaConfig,
    /// Neighbour lists' rate at the station, Hz.
    pub neighbour_rate: f64,
}

impl Default for Options {
    fn default() -> Self {
        Options {
            noise: None,
            dt: Duration::from_millis(20),
            safety: SafetyConfig {
                position_error: 0.0,
                ..SafetyConfig::default()
            },
            cruise_fraction: 0.6,
            arena: ArenaConfig::demo(),
            neighbour_rate: 20.0,
        }
    }
}

impl Options {
    /// The demo's robots: UWB-like positions through the median filter,
    /// 20 control periods a second, the default `[safety]` (its
    /// `position_error` included).
    pub fn noisy(seed: u64) -> Options {
        Options {
            noise: Some(seed),
            dt: Duration::from_millis(50),
            safety: SafetyConfig::default(),
            ..Options::default()
        }
    }
}

/// A station and its simulated fleet.
pub struct Rig {
    pub gcs: Gcs,
    router: SocketAddr,
    robots: Vec<Robot>,
    options: Options,
    layer_on: bool,
    fence: Fence,
    controllers: Publishers,
    /// Simulated time.
    time: Duration,
    started: Instant,
    next_commands: Duration,
    /// Until this time nothing from the station reaches a robot.
    frozen_until: Duration,
    /// Shortfall below the margin not counted as a violation, m.
    pub tolerance: f64,
    metrics: Metrics,
    buf: Vec<u8>,
    /// This rig's turn: rigs of one test binary run one at a time, so the
    /// tests' simulations do not take each other's cores (a rig's robots
    /// and station share the machine with whatever else runs).
    _turn: tokio::sync::MutexGuard<'static, ()>,
}

/// Whose turn it is to run a rig.
static TURN: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// Every controller's commands are published again this often.
const REPUBLISH: Duration = Duration::from_millis(100);

/// Longest a condition is waited for (registration, acknowledgements), in
/// simulated time: far beyond what they take.
const SETTLE: Duration = Duration::from_secs(30);

impl Rig {
    /// A station on loopback with the demo arena; its robots' layers on or
    /// (as an operator switches them) off.
    pub async fn new(layer_on: bool) -> Rig {
        Rig::with(layer_on, Options::default()).await
    }

    /// A station on loopback with `options`' arena, and robots as they say.
    pub async fn with(layer_on: bool, options: Options) -> Rig {
        let turn = TURN.lock().await;
        let mut config = CoreConfig::default();
        config.router.udp = "127.0.0.1:0".parse().unwrap();
        config.router.tcp = None;
        config.arena = Some(options.arena.clone());
        config.neighbours.rate_hz = options.neighbour_rate;
        let gcs = Gcs::start(config).await.unwrap();
        let arena = options.arena.to_arena("any", 1, true);
        Rig {
            _turn: turn,
            router: gcs.router().udp_addr(),
            controllers: gcs.router().publishers("ctl"),
            gcs,
            robots: Vec::new(),
            layer_on,
            fence: Fence::from_arena(&arena),
            time: Duration::ZERO,
            options,
            started: Instant::now(),
            next_commands: Duration::ZERO,
            frozen_until: Duration::ZERO,
            tolerance: 1e-3,
            metrics: Metrics::default(),
            buf: vec![0; 65_536],
        }
    }

    /// Adds robot `robot_<n>` of `platform` at `pose`; returns its index.
    pub async fn add(&mut self, platform: &PlatformSpec, pose: Pose) -> usize {
        let name = format!("robot_{}", self.robots.len() + 1);
        let mut settings = AgentSettings::new(&name);
        settings.safety = self.options.safety;
        settings.gains.cruise_fraction = self.options.cruise_fraction;
        let noise = self.options.noise.map(|seed| {
            let seed = seed.wrapping_add(self.robots.len() as u64);
            UwbNoise::new(UwbNoiseModel::default(), seed)
        });
        if noise.is_none() {
            // True poses, every control period: nothing for a median
            // filter to remove, and the pose the layer judges is exact.
            settings.filter_window = 1;
        }
        let sim = SimAgent::new(settings, platform, pose, noise, mech_proto::unix_micros());
        let socket = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        self.robots.push(Robot {
            channel: format!("ctl/{}", self.robots.len() + 1),
            name,
            sim,
            socket,
            command: None,
            drop_neighbours_from: None,
            arrived: None,
            reported: None,
        });
        self.robots.len() - 1
    }

    /// Runs until every robot is registered, reports its layer as the rig
    /// wants it, and obeys its controller's channel. Panics if that takes
    /// longer than [`SETTLE`].
    pub async fn settle(&mut self) {
        let registered = |r: &Rig| r.robots.iter().all(|x| x.sim.agent.registered());
        self.until(registered, "every robot registered").await;
        for i in 0..self.robots.len() {
            let name = self.robots[i].name.clone();
            let channel = self.robots[i].channel.clone();
            if !self.layer_on {
                self.gcs.router().set_safety(&name, false).await.unwrap();
            }
            self.gcs
                .router()
                .set_route(&name, Some(&channel))
                .await
                .unwrap();
        }
        let want = if self.layer_on {
            SafetyState::On
        } else {
            SafetyState::Off
        };
        let ready = move |r: &Rig| {
            r.robots.iter().all(|x| {
                x.sim.agent.safety().state == want && x.sim.agent.route().channel == x.channel
            })
        };
        self.until(ready, "every robot routed, its layer as asked")
            .await;
        // A robot's first estimates, before its median window filled, are
        // single fixes (outliers included); none of them moved meanwhile.
        self.metrics.max_estimate_error = 0.0;
    }

    /// Runs control periods until `done` holds; panics after [`SETTLE`].
    pub async fn until(&mut self, done: impl Fn(&Rig) -> bool, what: &str) {
        let end = self.time + SETTLE;
        while !done(self) {
            assert!(self.time < end, "not within {SETTLE:?}: {what}");
            self.step().await;
        }
    }

    /// Runs control periods until `done` has held for `hold` without a
    /// break; panics after [`SETTLE`].
    pub async fn until_steady(&mut self, done: impl Fn(&Rig) -> bool, hold: Duration, what: &str) {
        let end = self.time + SETTLE;
        let mut since = None;
        loop {
            if done(self) {
                let from = *since.get_or_insert(self.time);
                if self.time >= from + hold {
                    return;
                }
            } else {
                since = None;
            }
            assert!(self.time < end, "not within {SETTLE:?}: {what}");
            self.step().await;
        }
    }

    /// What robot `i`'s controller publishes from now on.
    pub fn command(&mut self, i: usize, command: Command) {
        self.robots[i].command = Some(command);
        self.next_commands = self.time;
    }

    /// Sends robot `i` a mission of one waypoint on `wp/gcs` and routes it
    /// there; returns once the robot follows it.
    pub async fn mission(&mut self, i: usize, to: (f64, f64)) {
        let name = self.robots[i].name.clone();
        let waypoint = Waypoint {
            x: to.0,
            y: to.1,
            z: 0.0,
            time: None,
        };
        self.robots[i].command = None;
        self.gcs
            .send_waypoints("gcs", &name, "wp/gcs", vec![waypoint], false)
            .await
            .unwrap();
        self.robots[i].channel = "wp/gcs".into();
        self.gcs
            .router()
            .set_route(&name, Some("wp/gcs"))
            .await
            .unwrap();
        let on_it = move |r: &Rig| {
            let a = &r.robots[i].sim.agent;
            a.route().channel == "wp/gcs" && a.mission("wp/gcs").is_some()
        };
        self.until(on_it, "the mission acknowledged and routed")
            .await;
    }

    /// Neighbour lists to robot `i` are dropped from now on (a lossy link
    /// that loses exactly them).
    pub fn drop_neighbours(&mut self, i: usize) {
        self.robots[i].drop_neighbours_from = Some(self.time);
    }

    /// Nothing from the station reaches any robot for `span` from now (a
    /// station frozen, or its link down).
    pub fn freeze(&mut self, span: Duration) {
        self.frozen_until = self.time + span;
    }

    /// Runs `seconds` of simulated time.
    pub async fn run_for(&mut self, seconds: f64) {
        let end = self.time + Duration::from_secs_f64(seconds);
        while self.time < end {
            self.step().await;
        }
    }

    /// Runs until every robot with a mission finished it, at most
    /// `seconds`; whether they all did.
    pub async fn run_until_arrived(&mut self, seconds: f64) -> bool {
        let end = self.time + Duration::from_secs_f64(seconds);
        while self.time < end {
            if self.all_arrived() {
                return true;
            }
            self.step().await;
        }
        self.all_arrived()
    }

    fn all_arrived(&self) -> bool {
        self.robots
            .iter()
            .all(|r| r.channel != "wp/gcs" || r.arrived.is_some())
    }

    /// The latest arrival, simulated time since the rig started (`None`
    /// until every robot with a mission arrived).
    pub fn last_arrival(&self) -> Option<Duration> {
        self.robots
            .iter()
            .filter(|r| r.channel == "wp/gcs")
            .map(|r| r.arrived)
            .try_fold(Duration::ZERO, |m, t| t.map(|t| m.max(t)))
    }

    /// Simulated time so far.
    pub fn time(&self) -> Duration {
        self.time
    }

    pub fn metrics(&self) -> Metrics {
        self.metrics
    }

    /// Robot `i`'s speed, m/s.
    pub fn speed(&self, i: usize) -> f64 {
        self.robots[i].velocity().norm()
    }

    /// What robot `i`'s safety layer reports.
    pub fn report(&self, i: usize) -> mech_proto::SafetyReport {
        self.robots[i].sim.agent.safety()
    }

    /// Each robot as it is now: where, heading, speed, whether it
    /// arrived, and what its layer does (for a failure's message).
    pub fn describe(&self) -> String {
        self.robots
            .iter()
            .map(|r| {
                let (p, v) = (r.sim.robot.pose(), r.velocity());
                format!(
                    "{} at ({:.2}, {:.2}) heading {:.2}, {:.3} m/s, arrived {:?}, {:?}",
                    r.name,
                    p.x,
                    p.y,
                    p.heading,
                    v.norm(),
                    r.arrived,
                    r.sim.agent.safety().intervention
                )
            })
            .collect::<Vec<_>>()
            .join("\n")
    }

    /// The robots' true positions.
    pub fn positions(&self) -> Vec<Vec2> {
        self.robots.iter().map(Robot::position).collect()
    }

    /// The station's count of safety notices it received (the event log).
    pub fn safety_notices(&self) -> usize {
        self.gcs.with_fleet(|f| {
            f.log
                .iter()
                .filter(|l| l.text.contains(": safety: "))
                .count()
        })
    }

    /// One control period: every datagram that arrived handled, every
    /// controller's command published when due, every robot stepped and
    /// its messages sent, the true poses measured, then a wait for the
    /// wall clock if the simulation is ahead of it.
    pub async fn step(&mut self) {
        let now = self.time;
        for r in &mut self.robots {
            loop {
                match r.socket.try_recv_from(&mut self.buf) {
                    Ok((n, _)) => {
                        let bytes = &self.buf[..n];
                        let neighbours =
                            mech_proto::peek(bytes).is_ok_and(|h| h.kind == neighbours_kind());
                        if neighbours && r.drop_neighbours_from.is_some() || now < self.frozen_until
                        {
                            continue;
                        }
                        let replies = r.sim.handle_bytes(bytes, now);
                        send(&mut r.sim, &r.socket, self.router, replies).await;
                    }
                    Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => break,
                    Err(e) => panic!("{}: {e}", r.name),
                }
            }
        }
        if now >= self.next_commands {
            self.next_commands = now + REPUBLISH;
            for r in &self.robots {
                if let Some(c) = &r.command {
                    let _ = self
                        .controllers
                        .on(&r.channel)
                        .send(&r.name, c.clone())
                        .await;
                }
            }
        }
        for r in &mut self.robots {
            let out = r.sim.tick(now);
            let p = r.sim.agent.telemetry(now).pose;
            r.reported = Some(Vec2::new(p.x, p.y));
            send(&mut r.sim, &r.socket, self.router, out).await;
            let done = r.sim.agent.mission("wp/gcs").is_some_and(|m| m.finished());
            if r.arrived.is_none() && r.channel == "wp/gcs" && done {
                r.arrived = Some(now);
            }
        }
        self.time += self.options.dt;
        self.measure();
        let ahead = self.time.saturating_sub(self.started.elapsed());
        if !ahead.is_zero() {
            tokio::time::sleep(ahead).await;
        } else {
            tokio::task::yield_now().await;
        }
    }

    fn measure(&mut self) {
        let safety = &self.options.safety;
        let (margin, radius) = (self.fence.margin, safety.radius);
        let stale_after = Duration::from_secs_f64(safety.stale_after + 0.05 + 0.5);
        let m = &mut self.metrics;
        let (mut close, mut touching) = (false, false);
        for (i, a) in self.robots.iter().enumerate() {
            for b in &self.robots[i + 1..] {
                let gap = (a.position() - b.position()).norm() - 2.0 * radius;
                m.min_gap = m.min_gap.min(gap);
                close |= gap < margin - self.tolerance;
                touching |= gap < 0.0;
            }
        }
        m.separation_violations += u64::from(close);
        m.collisions += u64::from(touching);
        let (mut short, mut breached) = (false, false);
        let discs = self.options.arena.shape().obstacle_list();
        for r in &self.robots {
            let to_discs = discs.iter().filter_map(|o| match o {
                mech_proto::Obstacle::Disc(d) => {
                    Some((r.position() - Vec2::new(d.x, d.y)).norm() - d.radius)
                }
                mech_proto::Obstacle::Polygon(_) => None,
            });
            let edges = clearance(&self.fence, r.position());
            let c = to_discs.fold(edges, f64::min) - radius;
            m.min_clearance = m.min_clearance.min(c);
            short |= c < margin - self.tolerance;
            breached |= c < 0.0;
            if r.drop_neighbours_from
                .is_some_and(|from| self.time >= from + stale_after)
            {
                m.max_stale_speed = m.max_stale_speed.max(r.velocity().norm());
            }
        }
        m.margin_violations += u64::from(short);
        m.breaches += u64::from(breached);
        if close || short {
            m.below_margin += self.options.dt.as_secs_f64();
        }
        for r in &self.robots {
            let (p, speed) = (r.position(), r.velocity().norm());
            for (zone, cap) in &self.fence.slow_zones {
                if mech_agent::safety::geometry::inside(zone, p) {
                    m.zone_overspeed = m.zone_overspeed.max(speed - cap);
                }
            }
            if let Some(e) = r.reported {
                m.max_estimate_error = m.max_estimate_error.max((e - p).norm());
            }
        }
    }

    /// Stops the station (the robots' sockets close with the rig).
    pub async fn shutdown(self) {
        self.gcs.shutdown().await;
    }
}

/// The wire number of a `Neighbours` message.
fn neighbours_kind() -> u8 {
    mech_proto::Body::Neighbours(mech_proto::Neighbours {
        robot: String::new(),
        stamp_us: 0,
        robots: vec![],
        obstacles: vec![],
    })
    .kind()
}

/// Sends `out`, encoded by the robot's agent, to the station.
async fn send(
    sim: &mut SimAgent,
    socket: &UdpSocket,
    router: SocketAddr,
    out: Vec<mech_proto::Envelope>,
) {
    let mut bytes = Vec::new();
    for env in out {
        bytes.clear();
        if sim.agent.encode(&env, &mut bytes).is_ok() {
            let _ = socket.send_to(&bytes, router).await;
        }
    }
}
