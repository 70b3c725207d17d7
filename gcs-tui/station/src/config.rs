//! The station's configuration file (`gcs.toml`), assembled from the
//! sections each layer owns: `[router]`, `[fleet]`, `[auth]`, `[record]`,
//! `[arena]` and `[neighbours]` (mech-core), `[[cluster]]` (mech-control),
//! `[log]`, `[station]` and
//! `[foxglove]` (this crate). The sections of the programs on top of the
//! station, `[gamepad]` (mech-gcs's TUI), `[zenoh]` (mech-zenoh's bridge)
//! and `[ros2]` (mech-ros2's bridge), are carried as written ([`ProgramSection`]), each read and
//! checked by the program that uses it, so one file serves every program
//! of a site.
//! Every field has a default, so an empty file (or none) gives a working
//! ground station on port 7400.

use std::path::{Path, PathBuf};

use mech_control::ClusterSpec;
use mech_core::auth::AuthConfig;
use mech_core::{
    ArenaConfig, CoreConfig, FleetConfig, NeighbourConfig, RecordConfig, RouterConfig,
};
use serde::Deserialize;
use serde::de::DeserializeOwned;

use crate::foxglove::FoxgloveConfig;
use crate::logging::LogConfig;
use crate::server::StationConfig;

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
    /// A program's section (`[gamepad]`, `[zenoh]`, `[ros2]`) that its program
    /// cannot read.
    #[error("[{name}]: {error}")]
    Section {
        name: String,
        error: Box<toml::de::Error>,
    },
    #[error(transparent)]
    Invalid(#[from] mech_core::ConfigError),
}

/// The station's whole configuration: every section of the file.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ConfigFile {
    pub router: RouterConfig,
    pub log: LogConfig,
    pub fleet: FleetConfig,
    /// Keys and roles of the authenticated control plane.
    pub auth: AuthConfig,
    /// Clusters defined at start-up (`[[cluster]]` tables: name, members,
    /// formation, spacing, offsets).
    pub cluster: Vec<ClusterSpec>,
    /// Recordings: directory, file size cap, rotation, queue.
    pub record: RecordConfig,
    /// The arena robots are kept inside (fleet safety, `docs/safety.md`),
    /// or a file holding it; none unless written (`--demo` uses the
    /// simulator's).
    pub arena: Option<ArenaConfig>,
    /// How robots are told about their neighbours while there is an arena.
    pub neighbours: NeighbourConfig,
    /// Where a served station listens for TUIs and scripts.
    pub station: StationConfig,
    /// The Foxglove live view (`--foxglove`).
    pub foxglove: FoxgloveConfig,
    /// Gamepad teleop (shaping, dead-man and other buttons, rate, limits):
    /// read by mech-gcs's TUI, which drives the pads.
    pub gamepad: ProgramSection,
    /// The bridge to other stations: read by mech-zenoh.
    pub zenoh: ProgramSection,
    /// The ROS 2 bridge: read by mech-ros2.
    pub ros2: ProgramSection,
}

/// A section that a program on top of the station reads (`[gamepad]`,
/// `[zenoh]`, `[ros2]`), kept as the file wrote it: the station neither uses nor
/// checks it, the program does, with [`ProgramSection::read`].
#[derive(Debug, Clone, Default, PartialEq, Deserialize)]
#[serde(transparent)]
pub struct ProgramSection(Option<toml::Table>);

impl ProgramSection {
    /// The section as the program's type `T`; `T`'s defaults when the file
    /// has none. `name` is the section's, for the error.
    pub fn read<T: DeserializeOwned + Default>(&self, name: &str) -> Result<T, ConfigError> {
        match &self.0 {
            None => Ok(T::default()),
            Some(table) => toml::Value::Table(table.clone())
                .try_into()
                .map_err(|error| ConfigError::Section {
                    name: name.to_string(),
                    error: Box::new(error),
                }),
        }
    }
}

/// The command line's settings that override the configuration file's.
#[derive(Debug, Clone, Default)]
pub struct Overrides {
    /// `--demo` without `--config`: the simulated fleet lives in this
    /// process, so the router is not exposed beyond this machine.
    pub demo_without_file: bool,
    /// `--demo`: without an `[arena]`, the simulator's arena.
    pub demo: bool,
    /// `--udp`, `--tcp`: the router's endpoints.
    pub udp: Option<std::net::SocketAddr>,
    pub tcp: Option<std::net::SocketAddr>,
    /// `--socket`: the station's control socket.
    pub socket: Option<PathBuf>,
}

impl ConfigFile {
    /// Applies the command line's settings over the file's.
    pub fn override_with(&mut self, o: &Overrides) {
        if o.demo_without_file {
            self.router.udp.set_ip(std::net::Ipv4Addr::LOCALHOST.into());
        }
        if o.demo && self.arena.is_none() {
            self.arena = Some(ArenaConfig::demo());
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
    pub fn load(path: &Path) -> Result<ConfigFile, ConfigError> {
        let text = std::fs::read_to_string(path).map_err(|error| ConfigError::Read {
            path: path.to_owned(),
            error,
        })?;
        let mut cfg = ConfigFile::parse_at(&text, path)?;
        // Key and arena files are found next to the configuration that
        // names them.
        let dir = path.parent().unwrap_or(Path::new("."));
        for k in &mut cfg.auth.keys {
            if k.file.is_relative() {
                k.file = dir.join(&k.file);
            }
        }
        if let Some(arena) = &cfg.arena {
            cfg.arena = Some(arena.resolve(dir)?);
        }
        Ok(cfg)
    }

    /// Parses and checks TOML text.
    pub fn parse(text: &str) -> Result<ConfigFile, ConfigError> {
        ConfigFile::parse_at(text, Path::new("<config>"))
    }

    fn parse_at(text: &str, path: &Path) -> Result<ConfigFile, ConfigError> {
        let cfg: ConfigFile = toml::from_str(text).map_err(|e| ConfigError::Parse {
            path: path.to_owned(),
            error: Box::new(e),
        })?;
        // The arena's mistakes are located in the text (`file:line:col`).
        if let Some(arena) = &cfg.arena {
            arena
                .validate()
                .map_err(|m| mech_core::ConfigError(m.locate(&path.display().to_string(), text)))?;
        }
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
            arena: self.arena.clone(),
            neighbours: self.neighbours,
        }
    }

    /// Checks every section the station reads, each by the layer that owns
    /// it (the programs' sections are their programs' to check).
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.core().validate()?;
        for c in &self.cluster {
            c.formation()
                .map_err(|e| mech_core::ConfigError(format!("cluster {:?}: {e}", c.name)))?;
        }
        self.station.validate()?;
        self.foxglove.validate()?;
        Ok(())
    }

    /// Where `record start` without a file name records: `[record] dir`,
    /// else the log directory.
    pub fn record_dir(&self) -> Option<PathBuf> {
        self.record.dir.clone().or_else(|| self.log.dir.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn empty_file_gives_defaults_on_port_7400() {
        let cfg = ConfigFile::parse("").unwrap();
        assert_eq!(cfg.router.udp.port(), 7400);
        assert_eq!(cfg.router.lost_after, Duration::from_secs(1));
        assert!(cfg.router.default_route.is_none());
    }

    #[test]
    fn seconds_and_default_route_are_read() {
        let cfg = ConfigFile::parse(
            "[router]\nlost_after = 2.5\nstale_after = 1\ndefault_route = \"joy/0\"\n",
        )
        .unwrap();
        assert_eq!(cfg.router.lost_after, Duration::from_millis(2500));
        assert_eq!(cfg.router.default_route.as_deref(), Some("joy/0"));
    }

    #[test]
    fn bad_values_are_errors() {
        assert!(ConfigFile::parse("[router]\nstale_after = 3\n").is_err());
        assert!(ConfigFile::parse("[router]\nbogus = 1\n").is_err());
        assert!(ConfigFile::parse("[router]\ntick = -1\n").is_err());
        let e = ConfigFile::parse("[router]\nudp_poll = 0.01\n").unwrap_err();
        assert!(e.to_string().contains("router.udp_poll"), "{e}");
    }

    #[test]
    fn udp_polling_is_read_and_can_be_turned_off() {
        let cfg = ConfigFile::parse("[router]\nudp_poll = 0.00005\n").unwrap();
        assert_eq!(cfg.router.udp_poll, Duration::from_micros(50));
        let off = ConfigFile::parse("[router]\nudp_poll = 0\n").unwrap();
        assert!(off.router.udp_poll.is_zero());
        // The shipped file says what the default is.
        let shipped = ConfigFile::parse(include_str!("../../../config/gcs.toml")).unwrap();
        assert_eq!(
            shipped.router.udp_poll,
            ConfigFile::parse("").unwrap().router.udp_poll
        );
    }

    #[test]
    fn router_tcp_limits_are_read_and_the_shipped_file_says_the_defaults() {
        let cfg = ConfigFile::parse(
            "[router]\ntcp_max_peers = 8\ntcp_peers_per_address = 2\ntcp_idle = 0.5\n",
        )
        .unwrap();
        let r = &cfg.router;
        assert_eq!(
            (r.tcp_max_peers, r.tcp_peers_per_address, r.tcp_idle),
            (8, 2, Duration::from_millis(500))
        );
        let limits = |c: &ConfigFile| {
            let r = &c.router;
            (r.tcp_max_peers, r.tcp_peers_per_address, r.tcp_idle)
        };
        let shipped = ConfigFile::parse(include_str!("../../../config/gcs.toml")).unwrap();
        assert_eq!(limits(&shipped), limits(&ConfigFile::parse("").unwrap()));
        for bad in [
            "tcp_max_peers = 0",
            "tcp_peers_per_address = 0",
            "tcp_idle = 0",
            // Durations the router adds to its clock: an hour at most (a
            // finite 1e19 s ended every TCP peer's task, and the router on
            // the first subscription).
            "tcp_idle = 1e19",
            "subscriber_timeout = 1e19",
            "subscriber_timeout = 3601",
        ] {
            assert!(
                ConfigFile::parse(&format!("[router]\n{bad}\n")).is_err(),
                "{bad}"
            );
        }
    }

    #[test]
    fn gcs_channels_must_be_names() {
        let err = |text: &str| ConfigFile::parse(text).unwrap_err().to_string();
        assert!(err("[fleet]\nmission_channel = \"\"\n").contains("fleet.mission_channel"));
        assert!(err("[fleet]\ncommand_channel = \"cmd gcs\"\n").contains("fleet.command_channel"));
    }

    #[test]
    fn shipped_config_parses() {
        let text = include_str!("../../../config/gcs.toml");
        ConfigFile::parse(text).unwrap();
    }

    /// A section the station does not read but a program on top of it
    /// does, with a stand-in for the program's type.
    #[derive(Debug, Default, PartialEq, serde::Deserialize)]
    #[serde(default, deny_unknown_fields)]
    struct Pads {
        deadzone: f64,
    }

    #[test]
    fn the_programs_sections_are_carried_for_them_to_read() {
        let cfg = ConfigFile::parse(
            "[gamepad]\ndeadzone = 0.2\n[zenoh]\nstation = \"a\"\n[ros2]\nmax_speed = 0.5\n",
        )
        .unwrap();
        let ros2: toml::Table = cfg.ros2.read("ros2").unwrap();
        assert_eq!(ros2["max_speed"].as_float(), Some(0.5));
        assert_eq!(cfg.gamepad.read::<Pads>("gamepad").unwrap().deadzone, 0.2);
        let zenoh: toml::Table = cfg.zenoh.read("zenoh").unwrap();
        assert_eq!(zenoh["station"].as_str(), Some("a"));
        let none = ConfigFile::parse("").unwrap();
        assert_eq!(
            none.gamepad.read::<Pads>("gamepad").unwrap(),
            Pads::default()
        );
        // The program's type decides what its section may hold.
        let bad = ConfigFile::parse("[gamepad]\nbogus = 1\n").unwrap();
        let e = bad.gamepad.read::<Pads>("gamepad").unwrap_err().to_string();
        assert!(e.contains("[gamepad]") && e.contains("bogus"), "{e}");
        // Sections nobody owns are still refused.
        let e = ConfigFile::parse("[gamepda]\ndeadzone = 0.2\n").unwrap_err();
        assert!(e.to_string().contains("gamepda"), "{e}");
    }

    #[test]
    fn the_arena_is_read_from_its_section_or_its_file_and_demo_has_one() {
        assert!(ConfigFile::parse("").unwrap().arena.is_none());
        let cfg = ConfigFile::parse("[arena]\nboundary = [[0, 0], [5, 0], [5, 4]]\nmargin = 0.2\n")
            .unwrap();
        assert_eq!(cfg.core().arena.unwrap().shape().margin, 0.2);
        let e = ConfigFile::parse("[arena]\nboundary = [[0, 0], [5, 0]]\n").unwrap_err();
        assert!(
            e.to_string().starts_with("<config>:2:12: arena.boundary"),
            "{e}"
        );
        let e = ConfigFile::parse("[neighbours]\nrate_hz = 2\n").unwrap_err();
        assert!(e.to_string().contains("neighbours.rate_hz"), "{e}");
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(
            dir.path().join("lab.toml"),
            "boundary = [[0, 0], [6, 0], [6, 6], [0, 6]]\n",
        )
        .unwrap();
        let file = dir.path().join("gcs.toml");
        std::fs::write(&file, "[arena]\nfile = \"lab.toml\"\n").unwrap();
        let cfg = ConfigFile::load(&file).unwrap();
        let arena = cfg.arena.as_ref().unwrap().shape();
        assert_eq!(
            arena.bounds(),
            Some([0.0, 0.0, 6.0, 6.0]),
            "next to gcs.toml"
        );
        // --demo: the simulator's arena unless the file has one.
        let demo = Overrides {
            demo: true,
            ..Overrides::default()
        };
        let mut with_file = cfg.clone();
        with_file.override_with(&demo);
        assert_eq!(with_file.arena, cfg.arena);
        let mut none = ConfigFile::default();
        none.override_with(&demo);
        assert_eq!(none.arena, Some(ArenaConfig::demo()));
    }

    #[test]
    fn record_start_records_in_the_record_or_else_the_log_directory() {
        let cfg = ConfigFile::parse("[log]\ndir = \"/l\"\n").unwrap();
        assert_eq!(cfg.record_dir(), Some(PathBuf::from("/l")));
        let cfg = ConfigFile::parse("[log]\ndir = \"/l\"\n[record]\ndir = \"/r\"\n").unwrap();
        assert_eq!(cfg.record_dir(), Some(PathBuf::from("/r")));
    }
}
