//! GCS configuration (`gcs.toml`): router endpoints, link-state thresholds,
//! retry periods, subscriber queues, log files and gamepad teleop. Every field has a default,
//! so an empty file (or none) gives a working ground station on port 7400.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use serde::Deserialize;

use crate::gamepad::{Limits, PadButton, Shaping, TeleopConfig, TeleopMode};

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
    /// Clusters defined at start-up (`[[cluster]]` tables: name, members,
    /// formation, spacing, offsets).
    pub cluster: Vec<crate::control::ClusterSpec>,
    /// Gamepad teleop: shaping, dead-man and other buttons, rate, limits.
    pub gamepad: GamepadConfig,
}

/// Gamepad settings as written in `[gamepad]`; [`GamepadConfig::teleop`]
/// turns them into the station's [`TeleopConfig`].
///
/// Button names: south east north west left-bumper right-bumper
/// left-trigger right-trigger select start mode left-thumb right-thumb
/// dpad-up dpad-down dpad-left dpad-right. Modes: steering-throttle
/// velocity-heading tank twist cluster.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GamepadConfig {
    /// Fraction of stick travel around centre that reads as zero, `[0, 1)`.
    pub deadzone: f64,
    /// Blend between linear (0) and cubic (1) stick response, `[0, 1]`.
    pub expo: f64,
    /// Button held to drive (the dead-man), or `"none"` to drive whenever a
    /// pad is connected (not recommended: a dropped pad keeps its stick).
    pub deadman: String,
    /// Button that cycles the teleop mode.
    pub mode_button: String,
    /// Button that engages the fleet e-stop.
    pub estop_button: String,
    /// Mode a newly connected pad starts in.
    pub initial_mode: String,
    /// Steady publish rate while the dead-man is held, Hz. Agents stop a
    /// silent channel after 0.5 s, so keep it well above 2 Hz.
    pub rate_hz: f64,
    /// m/s at full stick (velocity-level modes and cluster translation).
    pub max_speed: f64,
    /// rad/s at full stick.
    pub max_yaw_rate: f64,
    /// Formation growth rate at full stick, 1/s (cluster mode).
    pub max_scale_rate: f64,
}

impl Default for GamepadConfig {
    fn default() -> Self {
        let t = TeleopConfig::default();
        GamepadConfig {
            deadzone: t.shaping.deadzone,
            expo: t.shaping.expo,
            deadman: t.deadman.map_or("none", button_name).to_string(),
            mode_button: button_name(t.mode_button).to_string(),
            estop_button: button_name(t.estop_button).to_string(),
            initial_mode: mode_name(t.initial_mode).to_string(),
            rate_hz: t.rate_hz,
            max_speed: t.limits.max_speed,
            max_yaw_rate: t.limits.max_yaw_rate,
            max_scale_rate: t.limits.max_scale_rate,
        }
    }
}

const BUTTONS: [(&str, PadButton); 17] = [
    ("south", PadButton::South),
    ("east", PadButton::East),
    ("north", PadButton::North),
    ("west", PadButton::West),
    ("left-bumper", PadButton::LeftBumper),
    ("right-bumper", PadButton::RightBumper),
    ("left-trigger", PadButton::LeftTrigger),
    ("right-trigger", PadButton::RightTrigger),
    ("select", PadButton::Select),
    ("start", PadButton::Start),
    ("mode", PadButton::Mode),
    ("left-thumb", PadButton::LeftThumb),
    ("right-thumb", PadButton::RightThumb),
    ("dpad-up", PadButton::DPadUp),
    ("dpad-down", PadButton::DPadDown),
    ("dpad-left", PadButton::DPadLeft),
    ("dpad-right", PadButton::DPadRight),
];

const MODES: [(&str, TeleopMode); 5] = [
    ("steering-throttle", TeleopMode::SteeringThrottle),
    ("velocity-heading", TeleopMode::VelocityHeading),
    ("tank", TeleopMode::Tank),
    ("twist", TeleopMode::Twist),
    ("cluster", TeleopMode::Cluster),
];

fn button_name(b: PadButton) -> &'static str {
    BUTTONS
        .iter()
        .find(|(_, x)| *x == b)
        .map_or("?", |(n, _)| n)
}

fn mode_name(m: TeleopMode) -> &'static str {
    MODES.iter().find(|(_, x)| *x == m).map_or("?", |(n, _)| n)
}

fn button(key: &str, name: &str) -> Result<PadButton, ConfigError> {
    BUTTONS
        .iter()
        .find(|(n, _)| *n == name)
        .map(|(_, b)| *b)
        .ok_or_else(|| {
            let names: Vec<&str> = BUTTONS.iter().map(|(n, _)| *n).collect();
            ConfigError::Invalid(format!(
                "gamepad.{key}: unknown button {name:?}; buttons are {}",
                names.join(", ")
            ))
        })
}

impl GamepadConfig {
    /// The teleop settings these values describe, or the first value at
    /// fault.
    pub fn teleop(&self) -> Result<TeleopConfig, ConfigError> {
        let bad = |m: String| Err(ConfigError::Invalid(m));
        if !(self.deadzone.is_finite() && (0.0..1.0).contains(&self.deadzone)) {
            return bad(format!(
                "gamepad.deadzone must be in [0, 1), found {}",
                self.deadzone
            ));
        }
        if !(self.expo.is_finite() && (0.0..=1.0).contains(&self.expo)) {
            return bad(format!(
                "gamepad.expo must be in [0, 1], found {}",
                self.expo
            ));
        }
        if !(self.rate_hz.is_finite() && self.rate_hz > 2.0 && self.rate_hz <= 200.0) {
            return bad(format!(
                "gamepad.rate_hz must be above 2 (agents stop a channel silent for 0.5 s) \
                 and at most 200, found {}",
                self.rate_hz
            ));
        }
        for (key, v) in [
            ("max_speed", self.max_speed),
            ("max_yaw_rate", self.max_yaw_rate),
            ("max_scale_rate", self.max_scale_rate),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return bad(format!("gamepad.{key} must be positive, found {v}"));
            }
        }
        let deadman = match self.deadman.as_str() {
            "none" => None,
            name => Some(button("deadman", name)?),
        };
        let mode_button = button("mode_button", &self.mode_button)?;
        let estop_button = button("estop_button", &self.estop_button)?;
        let pairs = [
            ("deadman", deadman, "mode_button", Some(mode_button)),
            ("deadman", deadman, "estop_button", Some(estop_button)),
            (
                "mode_button",
                Some(mode_button),
                "estop_button",
                Some(estop_button),
            ),
        ];
        for (a, x, b, y) in pairs {
            if x.is_some() && x == y {
                return bad(format!(
                    "gamepad.{a} and gamepad.{b} must be different buttons"
                ));
            }
        }
        let initial_mode = MODES
            .iter()
            .find(|(n, _)| *n == self.initial_mode)
            .map(|(_, m)| *m)
            .ok_or_else(|| {
                let names: Vec<&str> = MODES.iter().map(|(n, _)| *n).collect();
                ConfigError::Invalid(format!(
                    "gamepad.initial_mode: unknown mode {:?}; modes are {}",
                    self.initial_mode,
                    names.join(", ")
                ))
            })?;
        Ok(TeleopConfig {
            deadman,
            mode_button,
            estop_button,
            rate_hz: self.rate_hz,
            shaping: Shaping {
                deadzone: self.deadzone,
                expo: self.expo,
            },
            limits: Limits {
                max_speed: self.max_speed,
                max_yaw_rate: self.max_yaw_rate,
                max_scale_rate: self.max_scale_rate,
            },
            initial_mode,
        })
    }
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
        for (name, channel) in [
            ("fleet.mission_channel", &self.fleet.mission_channel),
            ("fleet.command_channel", &self.fleet.command_channel),
        ] {
            // An empty channel is "none": commands or missions on it would
            // reach robots nobody routed.
            if channel.is_empty() || channel.chars().any(|c| c.is_whitespace() || c.is_control()) {
                return Err(ConfigError::Invalid(format!(
                    "{name} must be a channel name without spaces, got {channel:?}"
                )));
            }
        }
        for c in &self.cluster {
            c.formation()
                .map_err(|e| ConfigError::Invalid(format!("cluster {:?}: {e}", c.name)))?;
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
        self.gamepad.teleop()?;
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
    fn gamepad_section_reaches_the_teleop_settings() {
        let cfg = GcsConfig::parse(
            "[gamepad]\ndeadzone = 0.2\nexpo = 0\ndeadman = \"right-bumper\"\n\
             mode_button = \"north\"\nestop_button = \"mode\"\nrate_hz = 50\n\
             initial_mode = \"cluster\"\nmax_speed = 0.8\n",
        )
        .unwrap();
        let t = cfg.gamepad.teleop().unwrap();
        assert_eq!(t.deadman, Some(PadButton::RightBumper));
        assert_eq!(t.mode_button, PadButton::North);
        assert_eq!(t.estop_button, PadButton::Mode);
        assert_eq!(t.rate_hz, 50.0);
        assert_eq!(t.initial_mode, TeleopMode::Cluster);
        assert_eq!(
            t.shaping,
            Shaping {
                deadzone: 0.2,
                expo: 0.0
            }
        );
        assert_eq!(t.limits.max_speed, 0.8);
        assert_eq!(t.limits.max_yaw_rate, Limits::default().max_yaw_rate);
        let none = GcsConfig::parse("[gamepad]\ndeadman = \"none\"\n").unwrap();
        assert_eq!(none.gamepad.teleop().unwrap().deadman, None);
        assert_eq!(
            GcsConfig::default().gamepad.teleop().unwrap(),
            TeleopConfig::default()
        );
    }

    #[test]
    fn bad_gamepad_values_say_what_is_wrong() {
        let err = |text: &str| GcsConfig::parse(text).unwrap_err().to_string();
        assert!(err("[gamepad]\ndeadzone = 1.0\n").contains("gamepad.deadzone"));
        assert!(err("[gamepad]\nexpo = -0.1\n").contains("gamepad.expo"));
        assert!(err("[gamepad]\nrate_hz = 1\n").contains("gamepad.rate_hz"));
        assert!(err("[gamepad]\nmax_speed = 0\n").contains("gamepad.max_speed"));
        let e = err("[gamepad]\ndeadman = \"LB\"\n");
        assert!(
            e.contains("unknown button \"LB\"") && e.contains("left-bumper"),
            "{e}"
        );
        assert!(err("[gamepad]\nestop_button = \"left-bumper\"\n").contains("different"));
        assert!(err("[gamepad]\ninitial_mode = \"fly\"\n").contains("modes are"));
        assert!(err("[gamepad]\nbogus = 1\n").contains("bogus"));
    }

    #[test]
    fn gcs_channels_must_be_names() {
        let err = |text: &str| GcsConfig::parse(text).unwrap_err().to_string();
        assert!(err("[fleet]\nmission_channel = \"\"\n").contains("fleet.mission_channel"));
        assert!(err("[fleet]\ncommand_channel = \"cmd gcs\"\n").contains("fleet.command_channel"));
    }

    #[test]
    fn shipped_config_parses() {
        let text = include_str!("../../config/gcs.toml");
        GcsConfig::parse(text).unwrap();
    }
}
