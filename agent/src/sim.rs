//! The simulator: simulated vehicles ([`SimRobot`]), UWB-like position noise
//! ([`UwbNoise`]), wheel encoders ([`SimEncoders`]), simulated agents
//! running the real agent core ([`SimAgent`]) and whole fleets of them on
//! UDP ([`SimFleet`]), as used by `mech-agent --sim` and `mech-gcs --demo`.

pub mod agent;
pub mod encoder;
pub mod noise;
pub mod robot;
pub mod safety_trial;
pub mod trial;

use std::net::SocketAddr;
use std::time::Duration;

use mech_proto::Pose;
use tokio::net::UdpSocket;
use tokio::sync::watch;
use tokio::task::JoinHandle;

pub use agent::SimAgent;
pub use encoder::{SimEncoderModel, SimEncoders};
pub use noise::{UwbNoise, UwbNoiseModel};
pub use robot::SimRobot;

use crate::machine::AgentSettings;
use crate::platform::PlatformSpec;
use crate::runtime::{self, Ticker};

/// Most phase groups a fleet's shared tick is split into.
const MAX_TICK_PHASES: usize = 10;

/// The rectangle robots are spread over, m.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Arena {
    pub min_x: f64,
    pub min_y: f64,
    pub max_x: f64,
    pub max_y: f64,
}

impl Default for Arena {
    /// The 2017 lab's Pozyx area, about 3.9 m x 2.8 m.
    fn default() -> Self {
        Arena {
            min_x: 0.0,
            min_y: 0.0,
            max_x: 3.9,
            max_y: 2.8,
        }
    }
}

impl Arena {
    /// Start pose of robot `i` of `n`: a grid filling the arena with a 10%
    /// margin, all facing +x.
    pub fn start_pose(&self, i: usize, n: usize) -> Pose {
        let n = n.max(1);
        let (w, h) = (
            (self.max_x - self.min_x).max(0.0),
            (self.max_y - self.min_y).max(0.0),
        );
        let cols = ((n as f64 * w / h.max(1e-9)).sqrt().ceil() as usize).clamp(1, n);
        let rows = n.div_ceil(cols);
        let (c, r) = (i % cols, i / cols);
        let x = self.min_x + w * (0.1 + 0.8 * (c as f64 + 0.5) / cols as f64);
        let y = self.min_y + h * (0.1 + 0.8 * (r as f64 + 0.5) / rows as f64);
        Pose {
            x,
            y,
            z: 0.0,
            heading: 0.0,
        }
    }
}

/// Options of a simulated fleet.
#[derive(Debug, Clone, PartialEq)]
pub struct SimFleetOptions {
    /// UWB-like position noise (Gaussian + outliers) through the median filter.
    pub noise: bool,
    /// Seed of the noise; robot `i` uses `seed + i`.
    pub seed: u64,
    /// Control periods per second (one shared tick drives every agent).
    pub control_rate_hz: f64,
    /// Telemetry messages per second per robot.
    pub telemetry_rate_hz: f64,
    /// Platforms, cycled over the robots.
    pub platforms: Vec<PlatformSpec>,
    /// Failsafe settings of every agent.
    pub failsafe: crate::failsafe::FailsafeConfig,
    pub noise_model: UwbNoiseModel,
    /// Keys of robots that sign (by robot name); a robot without one runs
    /// unsigned.
    pub secrets: std::collections::BTreeMap<String, [u8; mech_proto::auth::KEY_LEN]>,
    /// The router's sender name, which signing robots check.
    pub router_name: String,
    /// Every agent's `[safety]`: footprint and braking for the fleet
    /// safety layer, which the station's arena switches on.
    pub safety: crate::safety::SafetyConfig,
}

impl Default for SimFleetOptions {
    fn default() -> Self {
        SimFleetOptions {
            noise: true,
            seed: 1,
            control_rate_hz: 20.0,
            telemetry_rate_hz: 20.0,
            platforms: vec![
                PlatformSpec::diff_drive(),
                PlatformSpec::kiwi(),
                PlatformSpec::diff_drive(),
                PlatformSpec::quadcopter(),
            ],
            failsafe: crate::failsafe::FailsafeConfig::default(),
            noise_model: UwbNoiseModel::default(),
            secrets: std::collections::BTreeMap::new(),
            router_name: mech_proto::ROUTER.to_string(),
            safety: crate::safety::SafetyConfig::default(),
        }
    }
}

/// A running fleet of simulated agents, one tokio task and one UDP socket
/// each, all stepped by one shared tick.
#[derive(Debug)]
pub struct SimFleet {
    names: Vec<String>,
    addrs: Vec<SocketAddr>,
    shutdown: watch::Sender<bool>,
    agents: Vec<JoinHandle<()>>,
    ticker: JoinHandle<()>,
}

impl SimFleet {
    /// Spawns `n` simulated agents on the current tokio runtime: names
    /// `robot_1..robot_n`, platforms cycled from `options.platforms`
    /// (diff-drive, kiwi, diff-drive, quadcopter by default), spread over
    /// `arena`, each with its own UDP socket on 127.0.0.1:0 talking to
    /// `router`, running the same agent core as the real agent.
    pub async fn spawn(
        n: usize,
        router: SocketAddr,
        arena: Arena,
        options: SimFleetOptions,
    ) -> std::io::Result<SimFleet> {
        let period = Duration::from_secs_f64(1.0 / options.control_rate_hz.clamp(0.1, 1000.0));
        let telemetry = Duration::from_secs_f64(1.0 / options.telemetry_rate_hz.clamp(0.1, 1000.0));
        let (shutdown, shutdown_rx) = watch::channel(false);
        // Agents are split into phase groups ticked in turn, so their
        // telemetry reaches the router spread over the period instead of in
        // one burst of n datagrams (which would overflow socket buffers).
        let phases = n.clamp(1, MAX_TICK_PHASES);
        let (tick_txs, tick_rxs): (Vec<_>, Vec<_>) =
            (0..phases).map(|_| watch::channel(Duration::ZERO)).unzip();
        let origin = tokio::time::Instant::now();
        let stamp_origin = mech_proto::unix_micros();
        let platforms = if options.platforms.is_empty() {
            SimFleetOptions::default().platforms
        } else {
            options.platforms.clone()
        };
        let mut names = Vec::with_capacity(n);
        let mut addrs = Vec::with_capacity(n);
        let mut agents = Vec::with_capacity(n);
        for i in 0..n {
            let name = format!("robot_{}", i + 1);
            let mut settings = AgentSettings::new(&name);
            settings.failsafe = options.failsafe;
            settings.telemetry_period = telemetry;
            settings.safety = options.safety;
            let noise = options
                .noise
                .then(|| UwbNoise::new(options.noise_model, options.seed.wrapping_add(i as u64)));
            let spec = &platforms[i % platforms.len()];
            let mut sim =
                SimAgent::new(settings, spec, arena.start_pose(i, n), noise, stamp_origin);
            if let Some(secret) = options.secrets.get(&name) {
                let key = mech_proto::auth::Key::new(secret);
                sim.agent = sim.agent.with_key(key, &options.router_name);
            }
            let socket = UdpSocket::bind("127.0.0.1:0").await?;
            addrs.push(socket.local_addr()?);
            let ticker = Ticker::Shared(tick_rxs[i % phases].clone());
            let io = runtime::Io::Udp { socket, router };
            let shutdown_rx = shutdown_rx.clone();
            agents.push(tokio::spawn(async move {
                let _ = runtime::drive(sim, io, ticker, origin, shutdown_rx).await;
            }));
            names.push(name);
        }
        let ticker = tokio::spawn(async move {
            let mut interval = tokio::time::interval(period / phases as u32);
            interval.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            for phase in (0..phases).cycle() {
                let at = interval.tick().await;
                if tick_txs[phase]
                    .send(at.saturating_duration_since(origin))
                    .is_err()
                {
                    break;
                }
            }
        });
        Ok(SimFleet {
            names,
            addrs,
            shutdown,
            agents,
            ticker,
        })
    }

    /// Robot names, in spawn order.
    pub fn names(&self) -> Vec<String> {
        self.names.clone()
    }

    /// Each robot's UDP address, in spawn order.
    pub fn addrs(&self) -> &[SocketAddr] {
        &self.addrs
    }

    /// Stops every agent (each sends `Bye` and zeroes its outputs).
    pub async fn shutdown(self) {
        let _ = self.shutdown.send(true);
        for a in self.agents {
            let _ = a.await;
        }
        self.ticker.abort();
        let _ = self.ticker.await;
    }
}
