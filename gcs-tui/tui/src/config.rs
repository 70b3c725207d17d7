//! The station's configuration file (`gcs.toml`), assembled from the
//! sections each layer owns: `[router]`, `[fleet]`, `[auth]` and `[record]`
//! (mech-core), `[[cluster]]` (mech-control), `[log]`, `[gamepad]`,
//! `[station]` and `[foxglove]` (this binary).
//! Every field has a default, so an empty file (or none) gives a working
//! ground station on port 7400.

use std::path::{Path, PathBuf};

use mech_control::ClusterSpec;
use mech_core::auth::AuthConfig;
use mech_core::{CoreConfig, FleetConfig, RecordConfig, RouterConfig};
use serde::Deserialize;

use crate::foxglove::FoxgloveConfig;
use crate::gamepad::GamepadConfig;
use crate::logging::LogConfig;
use crate::station::StationConfig;

/// Why a configuration could not be loaded.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    // The causes are printed in the message, not chained as sources, so a
    // report that prints the chain does not say them twice.
    #[error("cannot read {path}: {error}")]
    Read {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("{path}: {error}")]
    Parse {
        path: PathBuf,
        error: Box<toml::de::Error>,
    },
    #[error(transparent)]
    Invalid(#[from] mech_core::ConfigError),
}

/// The whole GCS configuration.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct GcsConfig {
    pub router: RouterConfig,
    pub log: LogConfig,
    pub fleet: FleetConfig,
    /// Keys and roles of the authenticated control plane.
    pub auth: AuthConfig,
    /// Clusters defined at start-up (`[[cluster]]` tables: name, members,
    /// formation, spacing, offsets).
    pub cluster: Vec<ClusterSpec>,
    /// Gamepad teleop: shaping, dead-man and other buttons, rate, limits.
    pub gamepad: GamepadConfig,
    /// Recordings: directory, file size cap, rotation, queue.
    pub record: RecordConfig,
    /// Where a served station listens for TUIs and scripts.
    pub station: StationConfig,
    /// The Foxglove live view (`--foxglove`).
    pub foxglove: FoxgloveConfig,
}

/// The command line's settings that override the configuration file's.
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    /// `--demo` without `--config`: the simulated fleet lives in this
    /// process, so the router is not exposed beyond this machine.
    pub demo_without_file: bool,
    /// `--udp`, `--tcp`: the router's endpoints.
    pub udp: Option<std::net::SocketAddr>,
    pub tcp: Option<std::net::SocketAddr>,
    /// `--socket`: the station's control socket.
    pub socket: Option<PathBuf>,
}

impl GcsConfig {
    /// Applies the command line's settings over the file's.
    pub fn override_with(&mut self, o: &Overrides) {
        if o.demo_without_file {
            self.router.udp.set_ip(std::net::Ipv4Addr::LOCALHOST.into());
        }
        if let Some(udp) = o.udp {
            self.router.udp = udp;
        }
        if let Some(tcp) = o.tcp {
            self.router.tcp = Some(tcp);
        }
        if let Some(socket) = &o.socket {
            self.station.socket = Some(socket.clone());
        }
    }

    /// Reads and checks a TOML file.
    pub fn load(path: &Path) -> Result<GcsConfig, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Read {
            path: path.to_owned(),
            error,
        })?;
        let mut cfg = GcsConfig::parse_at(&text, path)?;
        // Key files are found next to the configuration that names them.
        let dir = path.parent().unwrap_or(Path::new("."));
        for k in &mut cfg.auth.keys {
            if k.file.is_relative() {
                k.file = dir.join(&k.file);
            }
        }
        Ok(cfg)
    }

    /// Parses and checks TOML text.
    pub fn parse(text: &str) -> Result<GcsConfig, ConfigError> {
        GcsConfig::parse_at(text, Path::new("<config>"))
    }

    fn parse_at(text: &str, path: &Path) -> Result<GcsConfig, ConfigError> {
        let cfg: GcsConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: path.to_owned(),
            error: Box::new(e),
        })?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// The sections the station core runs with.
    pub fn core(&self) -> CoreConfig {
        CoreConfig {
            router: self.router.clone(),
            fleet: self.fleet.clone(),
            auth: self.auth.clone(),
            record: self.record.clone(),
        }
    }

    /// Checks every section, each by the layer that owns it.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.core().validate()?;
        for c in &self.cluster {
            c.formation()
                .map_err(|e| mech_core::ConfigError(format!("cluster {:?}: {e}", c.name)))?;
        }
        self.gamepad.teleop()?;
        self.station.validate()?;
        self.foxglove.validate()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gamepad::{Limits, PadButton, Shaping, TeleopConfig, TeleopMode};
    use std::time::Duration;

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
        let e = GcsConfig::parse("[router]\nudp_poll = 0.01\n").unwrap_err();
        assert!(e.to_string().contains("router.udp_poll"), "{e}");
    }

    #[test]
    fn udp_polling_is_read_and_can_be_turned_off() {
        let cfg = GcsConfig::parse("[router]\nudp_poll = 0.00005\n").unwrap();
        assert_eq!(cfg.router.udp_poll, Duration::from_micros(50));
        let off = GcsConfig::parse("[router]\nudp_poll = 0\n").unwrap();
        assert!(off.router.udp_poll.is_zero());
        // The shipped file says what the default is.
        let shipped = GcsConfig::parse(include_str!("../../../config/gcs.toml")).unwrap();
        assert_eq!(
            shipped.router.udp_poll,
            GcsConfig::parse("").unwrap().router.udp_poll
        );
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
        let text = include_str!("../../../config/gcs.toml");
        GcsConfig::parse(text).unwrap();
    }
}
