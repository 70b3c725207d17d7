//! The bridge's section of the configuration (`[zenoh]` in the station's
//! file) and the Zenoh session configuration made from it.
//!
//! By default the bridge is a Zenoh *peer* that listens on loopback only,
//! connects nowhere and does not scout by multicast: nothing leaves the
//! machine until the configuration names the endpoints to listen on or
//! connect to. TLS, user/password authentication and access control are
//! Zenoh's own, from a Zenoh configuration file (`zenoh_config`).

use std::net::IpAddr;
use std::path::PathBuf;
use std::time::Duration;

use mech_core::ConfigError;
use serde::Deserialize;

use crate::keys::check_name;

/// Which route requests from other stations this station obeys.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum RouteRequests {
    /// Signed with an operator key this station lists in `[auth]` (so only
    /// when it authenticates).
    Signed,
    /// From anyone who reaches the bridge: for a trusted network only.
    Unsigned,
    /// None.
    Off,
}

/// `[zenoh]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ZenohConfig {
    /// This station's name on the network: the second chunk of each of its
    /// keys (`mech/<station>/...`). Unique among the stations that meet.
    pub station: String,
    /// `peer` (meets other peers directly) or `client` (through a `zenohd`
    /// router).
    pub mode: String,
    /// Endpoints to listen on (`tcp/0.0.0.0:7447`, `tls/...`).
    pub listen: Vec<String>,
    /// Endpoints of other stations or routers to connect to.
    pub connect: Vec<String>,
    /// Find peers by UDP multicast on the local network. Off: stations meet
    /// only through `listen` and `connect`.
    pub multicast_scouting: bool,
    /// A station silent this long is lost, with its robots (Zenoh's
    /// transport lease), seconds.
    #[serde(with = "mech_core::config::secs")]
    pub lease: Duration,
    /// Carry commands published on `mech/<station>/<robot>/cmd/<channel>`
    /// into the station.
    pub commands: bool,
    /// Sender name of those commands at the router. When the station
    /// authenticates, `[auth]` must list a key of this name: its role and
    /// channels limit what Zenoh may publish on.
    pub identity: String,
    /// Which route requests from other stations to obey.
    pub route_requests: RouteRequests,
    /// This station's operator key (`mech-gcs keygen`), to sign the route
    /// requests it sends other stations; they list it as an operator.
    pub operator_key: Option<PathBuf>,
    /// A Zenoh configuration file (JSON5) to start from: TLS certificates,
    /// user/password, access control. The settings above override it.
    pub zenoh_config: Option<PathBuf>,
}

impl Default for ZenohConfig {
    fn default() -> Self {
        ZenohConfig {
            station: "station".into(),
            mode: "peer".into(),
            listen: vec!["tcp/127.0.0.1:7447".into()],
            connect: Vec::new(),
            multicast_scouting: false,
            lease: Duration::from_secs(1),
            commands: true,
            identity: "zenoh".into(),
            route_requests: RouteRequests::Signed,
            operator_key: None,
            zenoh_config: None,
        }
    }
}

impl ZenohConfig {
    /// Checks names, mode and durations (not the files).
    pub fn validate(&self) -> Result<(), ConfigError> {
        check_name("station", &self.station)
            .map_err(|e| ConfigError(format!("zenoh.station: {e}")))?;
        if !matches!(self.mode.as_str(), "peer" | "client") {
            return Err(ConfigError(format!(
                "zenoh.mode must be \"peer\" or \"client\", got {:?}",
                self.mode
            )));
        }
        if !mech_core::config::is_channel_name(&self.identity) {
            return Err(ConfigError(format!(
                "zenoh.identity {:?} is not a sender name",
                self.identity
            )));
        }
        if self.lease < Duration::from_millis(100) {
            return Err(ConfigError::new("zenoh.lease must be at least 0.1 s"));
        }
        if self.mode == "client" && self.connect.is_empty() {
            return Err(ConfigError::new(
                "zenoh.mode = \"client\" needs a router in zenoh.connect",
            ));
        }
        Ok(())
    }

    /// Whether every endpoint is on this machine and nothing is scouted:
    /// then only programs here can reach the bridge.
    pub fn loopback_only(&self) -> bool {
        !self.multicast_scouting
            && self.zenoh_config.is_none()
            && self
                .listen
                .iter()
                .chain(&self.connect)
                .all(|e| is_loopback_endpoint(e))
    }

    /// The Zenoh session configuration.
    pub fn session(&self) -> Result<zenoh::Config, ConfigError> {
        let mut c = match &self.zenoh_config {
            Some(path) => zenoh::Config::from_file(path)
                .map_err(|e| ConfigError(format!("zenoh.zenoh_config {}: {e}", path.display())))?,
            None => zenoh::Config::default(),
        };
        let lease_ms = self.lease.as_millis().to_string();
        let json = |v: &[String]| serde_json::to_string(v).unwrap_or_default();
        let settings = [
            ("mode", format!("{:?}", self.mode)),
            (
                "scouting/multicast/enabled",
                self.multicast_scouting.to_string(),
            ),
            ("transport/link/tx/lease", lease_ms),
            ("transport/link/tx/keep_alive", "4".to_string()),
            ("listen/endpoints", json(&self.listen)),
            ("connect/endpoints", json(&self.connect)),
        ];
        for (key, value) in settings {
            c.insert_json5(key, &value)
                .map_err(|e| ConfigError(format!("zenoh setting {key} = {value}: {e}")))?;
        }
        Ok(c)
    }
}

/// Whether a Zenoh endpoint (`tcp/127.0.0.1:7447`, `tls/[::1]:7447#...`)
/// names an address of this machine.
pub fn is_loopback_endpoint(endpoint: &str) -> bool {
    let address = endpoint
        .split(['?', '#'])
        .next()
        .and_then(|e| e.split_once('/'))
        .map(|(_, a)| a)
        .unwrap_or_default();
    let host = address
        .rsplit_once(':')
        .map_or(address, |(h, _)| h)
        .trim_start_matches('[')
        .trim_end_matches(']');
    host == "localhost" || host.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_stay_on_this_machine() {
        let c = ZenohConfig::default();
        c.validate().unwrap();
        assert!(c.loopback_only());
        assert!(!c.multicast_scouting);
        let z = c.session().unwrap();
        assert_eq!(z.get_json("scouting/multicast/enabled").unwrap(), "false");
        assert_eq!(z.get_json("transport/link/tx/lease").unwrap(), "1000");
    }

    #[test]
    fn endpoints_beyond_loopback_are_seen() {
        for (e, local) in [
            ("tcp/127.0.0.1:7447", true),
            ("tcp/[::1]:7447", true),
            ("tls/localhost:7447#iface=lo", true),
            ("tcp/127.3.0.1:0?x=1", true),
            ("tcp/0.0.0.0:7447", false),
            ("tcp/192.168.1.4:7447", false),
            ("tls/site-a.example:7447", false),
            ("garbage", false),
        ] {
            assert_eq!(is_loopback_endpoint(e), local, "{e}");
        }
        let c = ZenohConfig {
            connect: vec!["tcp/10.0.0.2:7447".into()],
            ..ZenohConfig::default()
        };
        assert!(!c.loopback_only());
    }

    #[test]
    fn bad_settings_are_refused_with_their_name() {
        let station = ZenohConfig {
            station: "site/a".into(),
            ..ZenohConfig::default()
        };
        assert!(station.validate().unwrap_err().0.contains("zenoh.station"));
        let mode = ZenohConfig {
            mode: "router".into(),
            ..ZenohConfig::default()
        };
        assert!(mode.validate().unwrap_err().0.contains("zenoh.mode"));
        let client = ZenohConfig {
            mode: "client".into(),
            ..ZenohConfig::default()
        };
        assert!(client.validate().is_err());
        let parsed: ZenohConfig =
            toml::from_str("station = \"a\"\nlease = 0.5\nroute_requests = \"off\"").unwrap();
        assert_eq!(parsed.route_requests, RouteRequests::Off);
        assert_eq!(parsed.lease, Duration::from_millis(500));
        assert!(toml::from_str::<ZenohConfig>("statoin = \"a\"").is_err());
    }
}
