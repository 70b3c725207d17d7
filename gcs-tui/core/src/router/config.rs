//! The router's section of the configuration (`[router]`): endpoints,
//! link-state thresholds, retry periods, queues and sockets. Every field has
//! a default, so an empty section gives a working router on port 7400.

use std::net::SocketAddr;
use std::time::Duration;

use serde::Deserialize;

use crate::config::{ConfigError, is_channel_name, secs};

/// Router endpoints and timing. Durations are in seconds in the file.
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct RouterConfig {
    /// UDP endpoint for agents and controllers.
    pub udp: SocketAddr,
    /// TCP endpoint (length-prefixed frames) for controllers and tools;
    /// `None` disables it.
    pub tcp: Option<SocketAddr>,
    /// Name the router uses as sender of the messages it originates.
    pub name: String,
    /// Silence after which a robot is shown as stale (seconds).
    #[serde(with = "secs")]
    pub stale_after: Duration,
    /// Silence after which a robot is declared lost (seconds). The 2017 UI
    /// showed a robot as disconnected after about one second.
    #[serde(with = "secs")]
    pub lost_after: Duration,
    /// Period of the router's heartbeat to every robot. Agents declare the
    /// router lost after their `router_timeout` (1 s) without one.
    #[serde(with = "secs")]
    pub heartbeat_period: Duration,
    /// Resend period of an unacknowledged route change.
    #[serde(with = "secs")]
    pub route_retry: Duration,
    /// Resend period of an unacknowledged mission.
    #[serde(with = "secs")]
    pub mission_retry: Duration,
    /// A mission not acknowledged within this time is reported failed.
    #[serde(with = "secs")]
    pub mission_give_up: Duration,
    /// Resend period of an unacknowledged e-stop or release.
    #[serde(with = "secs")]
    pub estop_retry: Duration,
    /// Resend period of an unacknowledged arena (a change of the arena or
    /// of a robot's safety switch).
    #[serde(with = "secs")]
    pub arena_retry: Duration,
    /// Resolution of the router's timers (link state, retries).
    #[serde(with = "secs")]
    pub tick: Duration,
    /// An external telemetry subscription lapses unless renewed within this.
    #[serde(with = "secs")]
    pub subscriber_timeout: Duration,
    /// A channel silent for longer is no longer listed as live.
    #[serde(with = "secs")]
    pub channel_live_for: Duration,
    /// TCP peers served at once (each holds a file descriptor): the
    /// router's descriptor budget. When it is taken, the oldest peer that
    /// has sent no valid message yet is closed to make room; if every
    /// peer has, the new connection is closed. Lowered at start, with a
    /// warning, if the process may not open that many files.
    pub tcp_max_peers: usize,
    /// TCP peers served at once from one IP address, with the same rule
    /// within the address.
    pub tcp_peers_per_address: usize,
    /// A TCP peer that sends no valid message (signed by a listed key,
    /// when the station authenticates) within this long of connecting is
    /// closed (seconds).
    #[serde(with = "secs")]
    pub tcp_idle: Duration,
    /// Queue length of each subscriber (in-process or TCP); a full queue
    /// drops that subscriber's events and counts them, never blocks routing.
    pub subscriber_queue: usize,
    /// Route given to a robot that registers for the first time; `None`
    /// (the default) routes it to none, so it holds still.
    pub default_route: Option<String>,
    /// UDP workers: threads, each with its own socket on the UDP endpoint
    /// (the kernel spreads senders over them; one sender always reaches the
    /// same worker, so its messages stay in order).
    pub udp_workers: usize,
    /// While datagrams follow each other closer than a wake-up costs, a
    /// UDP worker polls its socket for up to this long after a batch
    /// before it sleeps (seconds; at most 0.001, 0 turns polling off).
    /// Sparing busy senders a wake-up per datagram raises what the router
    /// forwards on two cores by up to 40 %; traffic whose datagrams come
    /// further apart (a 2 kHz controller, a fleet's telemetry, even a
    /// steady 64 kHz stream) is never polled for, and polls that catch
    /// nothing back off, so such traffic costs no polling CPU.
    #[serde(with = "secs")]
    pub udp_poll: Duration,
    /// Kernel receive and send buffer of the UDP socket, bytes (capped by
    /// the system's `net.core.rmem_max`). Large, so that a burst of
    /// telemetry from a big fleet is queued rather than lost.
    pub socket_buffer: usize,
    /// Serial radios (`[[router.serial]]`): one radio carries many robots.
    pub serial: Vec<SerialEndpoint>,
    /// A robot's link (UDP or radio) counts as live while the router has
    /// heard from the robot on it within this (seconds). Commands go out
    /// on UDP while it is live, else on the radio: so when Wi-Fi goes
    /// silent the radio takes over after this long.
    #[serde(with = "secs")]
    pub link_timeout: Duration,
}

/// A serial port with a radio (XBee transparent mode, SiK, any UART) on it.
#[derive(Debug, Clone, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SerialEndpoint {
    /// The device, e.g. `/dev/ttyUSB0`.
    pub port: String,
    /// The radio's serial rate, bits per second: also the air rate the
    /// router paces its sending to, so that queues form here (where an
    /// e-stop can jump them) and not in the radio.
    #[serde(default = "default_baud")]
    pub baud: u32,
}

fn default_baud() -> u32 {
    57_600
}

impl Default for RouterConfig {
    fn default() -> Self {
        RouterConfig {
            udp: SocketAddr::from(([0, 0, 0, 0], 7400)),
            tcp: Some(SocketAddr::from(([127, 0, 0, 1], 7401))),
            name: mech_proto::ROUTER.to_string(),
            stale_after: Duration::from_millis(500),
            lost_after: Duration::from_millis(1000),
            heartbeat_period: Duration::from_millis(250),
            route_retry: Duration::from_millis(100),
            mission_retry: Duration::from_millis(200),
            mission_give_up: Duration::from_secs(5),
            // Short: each resend is another chance through a lossy link
            // (at 50% loss, 20 tries a second miss with odds of 1e-6).
            estop_retry: Duration::from_millis(50),
            arena_retry: Duration::from_millis(100),
            tick: Duration::from_millis(20),
            subscriber_timeout: Duration::from_secs(5),
            channel_live_for: Duration::from_secs(3),
            tcp_max_peers: 1024,
            tcp_peers_per_address: 16,
            tcp_idle: Duration::from_secs(10),
            subscriber_queue: 4096,
            default_route: None,
            udp_workers: 2,
            udp_poll: Duration::from_micros(30),
            socket_buffer: 4 << 20,
            serial: Vec::new(),
            link_timeout: Duration::from_millis(300),
        }
    }
}

impl RouterConfig {
    /// Rejects settings that would make the router misbehave.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.stale_after >= self.lost_after {
            return Err(ConfigError(format!(
                "router.stale_after ({:?}) must be shorter than router.lost_after ({:?})",
                self.stale_after, self.lost_after
            )));
        }
        for (name, d) in [
            ("tick", self.tick),
            ("heartbeat_period", self.heartbeat_period),
            ("route_retry", self.route_retry),
            ("mission_retry", self.mission_retry),
            ("estop_retry", self.estop_retry),
            ("arena_retry", self.arena_retry),
            ("link_timeout", self.link_timeout),
        ] {
            if d.is_zero() {
                return Err(ConfigError(format!("router.{name} must be positive")));
            }
        }
        if self.tcp_max_peers == 0 || self.tcp_peers_per_address == 0 {
            return Err(ConfigError::new(
                "router.tcp_max_peers and router.tcp_peers_per_address must be at least 1",
            ));
        }
        if self.tcp_idle.is_zero() {
            return Err(ConfigError::new("router.tcp_idle must be positive"));
        }
        // Added to the clock as the router runs: an hour at most.
        for (name, d) in [
            ("tcp_idle", self.tcp_idle),
            ("subscriber_timeout", self.subscriber_timeout),
        ] {
            if d > Duration::from_secs(3600) {
                return Err(ConfigError(format!(
                    "router.{name} ({} s) must be at most 3600 s",
                    d.as_secs_f64()
                )));
            }
        }
        if self.subscriber_queue == 0 {
            return Err(ConfigError::new(
                "router.subscriber_queue must be at least 1",
            ));
        }
        if self.udp_poll > Duration::from_millis(1) {
            return Err(ConfigError(format!(
                "router.udp_poll ({:?}) must be at most 0.001 s: polling longer only burns CPU",
                self.udp_poll
            )));
        }
        if self.udp_workers == 0 {
            return Err(ConfigError::new("router.udp_workers must be at least 1"));
        }
        for s in &self.serial {
            if s.port.is_empty() || !(300..=4_000_000).contains(&s.baud) {
                return Err(ConfigError(format!(
                    "router.serial: port {:?} at {} baud: expected a device path and 300 to 4000000 baud",
                    s.port, s.baud
                )));
            }
        }
        if self.serial.len() > usize::from(u16::MAX) {
            return Err(ConfigError::new("router.serial: too many ports"));
        }
        if let Some(route) = &self.default_route {
            if !is_channel_name(route) {
                return Err(ConfigError(format!(
                    "router.default_route {route:?} is not a channel name"
                )));
            }
        }
        Ok(())
    }
}
