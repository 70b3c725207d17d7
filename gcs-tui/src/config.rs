//! GCS configuration (`gcs.toml`): router endpoints, link-state thresholds,
//! retry periods, subscriber queues and log files. Every field has a default,
//! so an empty file (or none) gives a working ground station on port 7400.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;

/// Why a configuration could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    #[error("cannot read {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {source}")]
    Parse {
        path: PathBuf,
        source: Box<toml::de::Error>,
    },
    #[error("{0}")]
    Invalid(String),
}

/// The whole GCS configuration.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GcsConfig {
    pub router: RouterConfig,
    pub log: LogConfig,
    pub fleet: FleetConfig,
}

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
    /// Resolution of the router's timers (link state, retries).
    #[serde(with = "secs")]
    pub tick: Duration,
    /// An external telemetry subscription lapses unless renewed within this.
    #[serde(with = "secs")]
    pub subscriber_timeout: Duration,
    /// A channel silent for longer is no longer listed as live.
    #[serde(with = "secs")]
    pub channel_live_for: Duration,
    /// Queue length of each subscriber (in-process or TCP); a full queue
    /// drops that subscriber's events and counts them, never blocks routing.
    pub subscriber_queue: usize,
    /// Route given to a robot that registers for the first time; `None`
    /// (the default) routes it to none, so it holds still.
    pub default_route: Option<String>,
    /// Number of tasks receiving on the UDP socket.
    pub udp_workers: usize,
    /// Kernel receive and send buffer of the UDP socket, bytes (capped by
    /// the system's `net.core.rmem_max`). Large, so that a burst of
    /// telemetry from a big fleet is queued rather than lost.
    pub socket_buffer: usize,
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
            estop_retry: Duration::from_millis(100),
            tick: Duration::from_millis(20),
            subscriber_timeout: Duration::from_secs(5),
            channel_live_for: Duration::from_secs(3),
            subscriber_queue: 4096,
            default_route: None,
            udp_workers: 2,
            socket_buffer: 4 << 20,
        }
    }
}

/// Log files (tracing-appender, rolled daily).
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LogConfig {
    /// Directory of the rolling log files; `None` disables file logging.
    pub dir: Option<PathBuf>,
    /// File name prefix (`mech-gcs.log.2026-11-22`).
    pub prefix: String,
    /// `debug`, `info`, `warn` or `error` (or any `tracing` filter).
    pub level: String,
}

impl Default for LogConfig {
    fn default() -> Self {
        LogConfig {
            dir: default_log_dir(),
            prefix: "mech-gcs.log".into(),
            level: "info".into(),
        }
    }
}

/// `$XDG_STATE_HOME/mech` or `~/.local/state/mech`: outside the working
/// directory, so running a script never litters it.
fn default_log_dir() -> Option<PathBuf> {
    if let Some(d) = std::env::var_os("XDG_STATE_HOME").filter(|d| !d.is_empty()) {
        return Some(PathBuf::from(d).join("mech"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/state/mech"))
}

/// Fleet-model settings.
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FleetConfig {
    /// Poses kept per robot for the map trail.
    pub path_history: usize,
    /// Minimum distance (m) between two kept trail points.
    pub path_spacing: f64,
    /// Entries kept in the event log.
    pub event_log: usize,
    /// Channel the GCS sends missions on.
    pub mission_channel: String,
    /// Channel the command line's `drive` publishes on.
    pub command_channel: String,
    /// Arrival radius (m) of missions sent from the GCS.
    pub arrival_radius: f64,
}

impl Default for FleetConfig {
    fn default() -> Self {
        FleetConfig {
            path_history: 500,
            path_spacing: 0.02,
            event_log: 500,
            mission_channel: "wp/gcs".into(),
            command_channel: "cmd/gcs".into(),
            arrival_radius: 0.1,
        }
    }
}

impl GcsConfig {
    /// Reads and checks a TOML file.
    pub fn load(path: &Path) -> Result<GcsConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|source| ConfigError::Read {
            path: path.to_owned(),
            source,
        })?;
        let cfg = GcsConfig::parse(&text).map_err(|e| match e {
            ConfigError::Parse { source, .. } => ConfigError::Parse {
                path: path.to_owned(),
                source,
            },
            other => other,
        })?;
        Ok(cfg)
    }

    /// Parses and checks TOML text.
    pub fn parse(text: &str) -> Result<GcsConfig, ConfigError> {
        let cfg: GcsConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: PathBuf::from("<config>"),
            source: Box::new(e),
        })?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Rejects settings that would make the router misbehave.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let r = &self.router;
        if r.stale_after >= r.lost_after {
            return Err(ConfigError::Invalid(format!(
                "router.stale_after ({:?}) must be shorter than router.lost_after ({:?})",
                r.stale_after, r.lost_after
            )));
        }
        for (name, d) in [
            ("tick", r.tick),
            ("heartbeat_period", r.heartbeat_period),
            ("route_retry", r.route_retry),
            ("mission_retry", r.mission_retry),
            ("estop_retry", r.estop_retry),
        ] {
            if d.is_zero() {
                return Err(ConfigError::Invalid(format!(
                    "router.{name} must be positive"
                )));
            }
        }
        if r.subscriber_queue == 0 {
            return Err(ConfigError::Invalid(
                "router.subscriber_queue must be at least 1".into(),
            ));
        }
        if r.udp_workers == 0 {
            return Err(ConfigError::Invalid(
                "router.udp_workers must be at least 1".into(),
            ));
        }
        if let Some(route) = &r.default_route {
            if route.is_empty() || route.chars().any(char::is_whitespace) {
                return Err(ConfigError::Invalid(format!(
                    "router.default_route {route:?} is not a channel name"
                )));
            }
        }
        if self.fleet.arrival_radius.is_nan() || self.fleet.arrival_radius <= 0.0 {
            return Err(ConfigError::Invalid(
                "fleet.arrival_radius must be positive".into(),
            ));
        }
        Ok(())
    }
}

/// Durations written as seconds (`0.5`, `2`) in TOML.
mod secs {
    use std::time::Duration;

    use serde::{Deserialize, Deserializer};

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Duration, D::Error> {
        let s = f64::deserialize(d)?;
        Duration::try_from_secs_f64(s)
            .map_err(|_| serde::de::Error::custom(format!("{s} is not a duration in seconds")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_file_gives_defaults_on_port_7400() {
        let cfg = GcsConfig::parse("").unwrap();
        assert_eq!(cfg.router.udp.port(), 7400);
        assert_eq!(cfg.router.lost_after, Duration::from_secs(1));
        assert!(cfg.router.default_route.is_none());
    }

    #[test]
    fn seconds_and_default_route_are_read() {
        let cfg = GcsConfig::parse(
            "[router]\nlost_after = 2.5\nstale_after = 1\ndefault_route = \"joy/0\"\n",
        )
        .unwrap();
        assert_eq!(cfg.router.lost_after, Duration::from_millis(2500));
        assert_eq!(cfg.router.default_route.as_deref(), Some("joy/0"));
    }

    #[test]
    fn bad_values_are_errors() {
        assert!(GcsConfig::parse("[router]\nstale_after = 3\n").is_err());
        assert!(GcsConfig::parse("[router]\nbogus = 1\n").is_err());
        assert!(GcsConfig::parse("[router]\ntick = -1\n").is_err());
    }

    #[test]
    fn shipped_config_parses() {
        let text = include_str!("../../config/gcs.toml");
        GcsConfig::parse(text).unwrap();
    }
}
