//! Brings a robot up from its [`RobotConfig`]: builds the agent core, the
//! link, the actuators and the position source, then runs the loop until
//! shutdown. The binary is a thin wrapper around [`run`].

use std::net::SocketAddr;

use mech_proto::Pose;
use mech_proto::auth::Key;
use tokio::net::UdpSocket;
use tokio::sync::watch;
use tokio::time::Instant;

use crate::config::{ActuatorConfig, LinkConfig, PositionConfig, RobotConfig};
use crate::hal::{Actuators, NoActuators, PositionSample, PositionSource, WheelEncoders};
use crate::links::LinkChoice;
use crate::machine::{Agent, AgentSettings, Counters};
use crate::runtime::{self, HardwareVehicle, Io, Ticker};
use crate::sim::{SimAgent, SimEncoderModel, UwbNoise, UwbNoiseModel};

/// Why a robot could not be brought up.
#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    #[error("cannot open the UDP socket: {0}")]
    Udp(std::io::Error),
    #[error("cannot open serial port {port}: {message}")]
    Serial { port: String, message: String },
    #[error("actuators: {0}")]
    Actuators(String),
    #[error("encoders: {0}")]
    Encoders(String),
    #[error("this build has no {feature} support; rebuild with `--features {feature}`")]
    Feature { feature: &'static str },
    #[error("key: {0}")]
    Key(String),
    #[error("autopilot: {0}")]
    Autopilot(String),
    #[error("{0}")]
    Ros2(String),
}

/// Command-line overrides of the config.
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    /// Simulate the vehicle whatever the config's drivers say.
    pub sim: bool,
    /// Router address instead of the config's.
    pub router: Option<SocketAddr>,
}

/// Runs the robot until `shutdown` turns true, then zeroes the actuators and
/// says `Bye`; returns the agent's counters.
pub async fn run(
    config: RobotConfig,
    overrides: Overrides,
    shutdown: watch::Receiver<bool>,
) -> Result<Counters, LaunchError> {
    let key = config.key().map_err(LaunchError::Key)?;
    let router_name = config
        .auth
        .as_ref()
        .map_or(mech_proto::ROUTER.to_string(), |a| a.router.clone());
    let origin = Instant::now();
    let stamp_origin = mech_proto::unix_micros();
    let simulated = overrides.sim || matches!(config.position(), PositionConfig::Sim);
    let io = open_link(&config, &overrides).await?;
    let ticker = Ticker::Own(config.control_period());
    let settings = config.agent_settings(simulated);
    tracing::info!(
        name = %settings.name,
        platform = config.platform().build().name(),
        simulated,
        "agent starting"
    );
    // The agent's own key, and the router's name it checks signatures for.
    let signing = key.map(|k| (k, router_name));
    let counters = if simulated {
        let sim = simulated_vehicle(&config, settings, stamp_origin, signing);
        runtime::drive(sim, io, ticker, origin, shutdown).await
    } else {
        let agent = hardware_agent(&config, settings, stamp_origin, signing);
        match (config.autopilot(), config.ros2()) {
            (Some(autopilot), _) => {
                let vehicle = open_autopilot(autopilot, agent)?;
                runtime::drive(vehicle, io, ticker, origin, shutdown).await
            }
            (None, Some(ros2)) => {
                let vehicle = open_ros2_base(ros2, agent, stamp_origin)?;
                runtime::drive(vehicle, io, ticker, origin, shutdown).await
            }
            (None, None) => {
                let vehicle = HardwareVehicle {
                    agent,
                    actuators: open_actuators(&config)?,
                    positions: open_position(&config, origin)?,
                    encoders: open_encoders(&config, origin)?,
                };
                runtime::drive(vehicle, io, ticker, origin, shutdown).await
            }
        }
    };
    tracing::info!("agent stopped");
    Ok(counters)
}

/// A simulated robot at the configured start pose, with simulated
/// encoders if the config has encoders.
fn simulated_vehicle(
    config: &RobotConfig,
    settings: AgentSettings,
    stamp_origin: u64,
    signing: Option<(Key, String)>,
) -> SimAgent {
    let s = config.sim;
    let noise = s
        .noise
        .then(|| UwbNoise::new(UwbNoiseModel::default(), s.seed));
    let pose = Pose {
        x: s.x,
        y: s.y,
        z: s.z,
        heading: s.heading,
    };
    let mut sim = SimAgent::new(settings, config.platform(), pose, noise, stamp_origin);
    if let Some(e) = config.encoders() {
        // The configured encoders' resolution and kind, on simulated
        // wheels with the simulator's slip and noise.
        let model = SimEncoderModel {
            counting: e.kind,
            counts_per_revolution: e.counts_per_revolution,
            wheel_radius: e.wheel_radius,
            ..SimEncoderModel::default()
        };
        sim = sim.with_encoders(model, s.seed);
    }
    if let Some((key, router)) = signing {
        sim.agent = sim.agent.with_key(key, &router);
    }
    sim
}

/// The agent core of a real robot (an autopilot's estimate and a ROS 2
/// base's odometry are already filtered, so they are taken as they come).
fn hardware_agent(
    config: &RobotConfig,
    mut settings: AgentSettings,
    stamp_origin: u64,
    signing: Option<(Key, String)>,
) -> Agent {
    if config.autopilot().is_some() {
        settings.autopilot = true;
    }
    if config.autopilot().is_some() || config.ros2().is_some() {
        settings.has_position = true;
        settings.filter_window = 1;
    }
    let agent = Agent::new(settings, config.platform().build(), stamp_origin);
    match signing {
        Some((key, router)) => agent.with_key(key, &router),
        None => agent,
    }
}

async fn open_link(config: &RobotConfig, overrides: &Overrides) -> Result<Io, LaunchError> {
    let links = config.links();
    let caps: Vec<Option<std::time::Duration>> = links
        .iter()
        .map(|l| match l {
            LinkConfig::Serial {
                telemetry_rate_hz: Some(hz),
                ..
            } => Some(std::time::Duration::from_secs_f64(1.0 / hz)),
            _ => None,
        })
        .collect();
    if let ([only], false) = (links.as_slice(), caps[0].is_some()) {
        return open_one(only, overrides.router, true).await;
    }
    let mut ios = Vec::with_capacity(links.len());
    for link in &links {
        ios.push(open_one(link, overrides.router, links.len() == 1).await?);
    }
    let f = config.failover;
    let choice = LinkChoice::new(
        caps,
        std::time::Duration::from_secs_f64(f.link_timeout),
        std::time::Duration::from_secs_f64(f.probe_period),
    );
    tracing::info!(
        links = ios.len(),
        "links in order of preference, with failover"
    );
    Ok(Io::Failover {
        closed: vec![false; ios.len()],
        links: ios,
        choice,
    })
}

/// Opens one link. `--router` sets the router of a UDP link, and turns a
/// lone serial link into a UDP one (bench testing a radio robot).
async fn open_one(
    link: &LinkConfig,
    router: Option<SocketAddr>,
    alone: bool,
) -> Result<Io, LaunchError> {
    let router = match link {
        LinkConfig::Udp { router: configured } => Some(router.unwrap_or(*configured)),
        LinkConfig::Serial { .. } if alone => router,
        LinkConfig::Serial { .. } => None,
    };
    match (router, link) {
        (Some(router), _) => {
            let local = if router.ip().is_loopback() {
                SocketAddr::from(([127, 0, 0, 1], 0))
            } else {
                SocketAddr::from(([0, 0, 0, 0], 0))
            };
            let socket = UdpSocket::bind(local).await.map_err(LaunchError::Udp)?;
            tracing::info!(%router, local = ?socket.local_addr().ok(), "UDP link");
            Ok(Io::Udp { socket, router })
        }
        (None, LinkConfig::Serial { port, baud, .. }) => open_serial(port, *baud),
        (None, LinkConfig::Udp { .. }) => {
            Err(LaunchError::Udp(std::io::ErrorKind::InvalidInput.into()))
        }
    }
}

/// A serial link: its threads open the port, and open it again whenever
/// it fails, so a radio unplugged at start or later is taken up when it
/// returns (the robot runs on its other links meanwhile).
#[cfg(feature = "serial")]
fn open_serial(port: &str, baud: u32) -> Result<Io, LaunchError> {
    tracing::info!(port, baud, "serial link");
    Ok(crate::drivers::serial_link::open(port, baud))
}

#[cfg(not(feature = "serial"))]
fn open_serial(_port: &str, _baud: u32) -> Result<Io, LaunchError> {
    Err(LaunchError::Feature { feature: "serial" })
}

#[cfg(feature = "mavlink")]
fn open_autopilot(
    config: &crate::autopilot::AutopilotConfig,
    agent: Agent,
) -> Result<
    crate::autopilot::vehicle::AutopilotVehicle<crate::autopilot::link::MavlinkLink>,
    LaunchError,
> {
    use crate::autopilot::{link::MavlinkLink, session::Session, vehicle::AutopilotVehicle};
    tracing::info!(link = %config.link, "autopilot link");
    let link =
        MavlinkLink::open(&config.link).map_err(|e| LaunchError::Autopilot(e.to_string()))?;
    Ok(AutopilotVehicle::new(agent, Session::new(config), link))
}

#[cfg(not(feature = "mavlink"))]
fn open_autopilot(
    _config: &crate::autopilot::AutopilotConfig,
    _agent: Agent,
) -> Result<HardwareVehicle, LaunchError> {
    Err(LaunchError::Feature { feature: "mavlink" })
}

#[cfg(feature = "ros2")]
fn open_ros2_base(
    config: &crate::ros2_base::Ros2Config,
    agent: Agent,
    stamp_origin: u64,
) -> Result<crate::ros2_base::vehicle::Ros2Vehicle<crate::ros2_base::link::DdsBase>, LaunchError> {
    use crate::ros2_base::{link::DdsBase, session::BaseSession, vehicle::Ros2Vehicle};
    let env = std::env::var("ROS_DOMAIN_ID").ok();
    let domain = config.domain(env.as_deref()).map_err(LaunchError::Ros2)?;
    let robot = agent.name().to_string();
    tracing::info!(
        domain,
        cmd_vel = %config.resolve(&config.cmd_vel),
        odom = %config.resolve(&config.odom),
        "ROS 2 base"
    );
    let base =
        DdsBase::open(config, &robot, domain).map_err(|e| LaunchError::Ros2(e.to_string()))?;
    Ok(Ros2Vehicle::new(
        agent,
        BaseSession::new(config),
        base,
        stamp_origin,
    ))
}

#[cfg(not(feature = "ros2"))]
fn open_ros2_base(
    _config: &crate::ros2_base::Ros2Config,
    _agent: Agent,
    _stamp_origin: u64,
) -> Result<HardwareVehicle, LaunchError> {
    Err(LaunchError::Feature { feature: "ros2" })
}

fn open_actuators(config: &RobotConfig) -> Result<Box<dyn Actuators + Send>, LaunchError> {
    match config.actuators() {
        ActuatorConfig::None => Ok(Box::new(NoActuators::default())),
        #[cfg(feature = "rpi")]
        ActuatorConfig::L298 {
            channels,
            pwm_frequency,
            min_duty,
            max_duty,
            deadband,
        } => {
            let range = crate::drivers::l298::DutyRange {
                min_duty: *min_duty,
                max_duty: *max_duty,
                deadband: *deadband,
            };
            let l298 = crate::drivers::rpi::open_l298(channels, range, *pwm_frequency)
                .map_err(|e| LaunchError::Actuators(e.to_string()))?;
            Ok(Box::new(l298))
        }
        #[cfg(not(feature = "rpi"))]
        ActuatorConfig::L298 { .. } => Err(LaunchError::Feature { feature: "rpi" }),
    }
}

/// Opens the wheel encoders of `[encoders]` (GPIO interrupts on a Pi).
fn open_encoders(
    config: &RobotConfig,
    #[cfg_attr(not(feature = "rpi"), allow(unused_variables))] origin: Instant,
) -> Result<Option<Box<dyn WheelEncoders + Send>>, LaunchError> {
    let Some(e) = config.encoders() else {
        return Ok(None);
    };
    #[cfg(feature = "rpi")]
    {
        let encoders = crate::drivers::rpi::encoders::open_encoders(
            &e.channels,
            e.kind,
            e.pull_up,
            origin.into_std(),
        )
        .map_err(|err| LaunchError::Encoders(err.to_string()))?;
        tracing::info!(wheels = e.channels.len(), kind = ?e.kind, "wheel encoders");
        Ok(Some(Box::new(encoders)))
    }
    #[cfg(not(feature = "rpi"))]
    {
        let _ = e;
        Err(LaunchError::Feature { feature: "rpi" })
    }
}

type PositionRx = std::sync::mpsc::Receiver<Result<PositionSample, String>>;

#[cfg_attr(not(feature = "serial"), allow(unused_variables))]
fn open_position(config: &RobotConfig, origin: Instant) -> Result<Option<PositionRx>, LaunchError> {
    match config.position() {
        PositionConfig::None | PositionConfig::External | PositionConfig::Sim => Ok(None),
        #[cfg(feature = "serial")]
        PositionConfig::Pozyx {
            port,
            baud,
            heading_offset,
        } => {
            let stream = open_port(port, *baud)?;
            let settings = crate::drivers::pozyx::PozyxSettings {
                heading_offset: *heading_offset,
                ..Default::default()
            };
            Ok(Some(spawn_position(
                crate::drivers::pozyx::Pozyx::new(stream, settings),
                origin,
            )))
        }
        #[cfg(feature = "serial")]
        PositionConfig::Nmea {
            port,
            baud,
            origin: geo,
        } => {
            let stream = std::io::BufReader::new(open_port(port, *baud)?);
            let geo = crate::drivers::nmea_gps::GeoOrigin {
                latitude: geo.latitude,
                longitude: geo.longitude,
                altitude: geo.altitude,
            };
            Ok(Some(spawn_position(
                crate::drivers::nmea_gps::NmeaGps::new(stream, geo),
                origin,
            )))
        }
        #[cfg(not(feature = "serial"))]
        PositionConfig::Pozyx { .. } | PositionConfig::Nmea { .. } => {
            Err(LaunchError::Feature { feature: "serial" })
        }
    }
}

#[cfg(feature = "serial")]
fn open_port(port: &str, baud: u32) -> Result<Box<dyn serialport::SerialPort>, LaunchError> {
    serialport::new(port, baud)
        .timeout(std::time::Duration::from_secs(1))
        .open()
        .map_err(|e| LaunchError::Serial {
            port: port.to_string(),
            message: e.to_string(),
        })
}

/// Reads a blocking position source on its own thread; samples are stamped
/// with the agent's clock.
pub fn spawn_position<P>(mut source: P, origin: Instant) -> PositionRx
where
    P: PositionSource + Send + 'static,
{
    let (tx, rx) = std::sync::mpsc::channel();
    let origin = origin.into_std();
    std::thread::spawn(move || {
        loop {
            let sent = match source.read(origin.elapsed()) {
                Ok(Some(sample)) => tx.send(Ok(sample)),
                Ok(None) => Ok(()),
                Err(e) => {
                    let sent = tx.send(Err(format!("{e:?}")));
                    // Do not spin on a dead device.
                    std::thread::sleep(std::time::Duration::from_millis(500));
                    sent
                }
            };
            if sent.is_err() {
                break;
            }
        }
    });
    rx
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hal::{ErrorKind, ErrorType, HalError};
    use std::time::Duration;

    /// A source yielding two fixes, one error, then nothing (blocking briefly).
    #[derive(Debug)]
    struct Script(u32);

    impl ErrorType for Script {
        type Error = HalError;
    }

    impl PositionSource for Script {
        fn read(&mut self, now: Duration) -> Result<Option<PositionSample>, HalError> {
            self.0 += 1;
            match self.0 {
                1 | 2 => Ok(Some(PositionSample {
                    pose: Pose {
                        x: f64::from(self.0),
                        ..Pose::default()
                    },
                    stamp: now,
                    quality: 1.0,
                    has_heading: true,
                })),
                3 => Err(HalError::new(ErrorKind::Timeout, "no reply")),
                _ => {
                    std::thread::sleep(Duration::from_millis(5));
                    Ok(None)
                }
            }
        }
    }

    #[tokio::test]
    async fn position_thread_forwards_samples_and_errors() {
        let rx = spawn_position(Script(0), Instant::now());
        let next = || rx.recv_timeout(Duration::from_secs(5)).unwrap();
        assert_eq!(next().unwrap().pose.x, 1.0);
        assert_eq!(next().unwrap().pose.x, 2.0);
        assert!(next().unwrap_err().contains("no reply"));
        drop(rx);
    }
}
