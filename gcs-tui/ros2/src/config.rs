//! The bridge's settings: the `[ros2]` section of a TOML file, every key
//! optional, and the checks that refuse a setting the bridge cannot use.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use serde::Deserialize;

/// What a cmd_vel topic carries: the plain twist most nodes publish, or
/// the stamped one (`teleop_twist_keyboard --ros-args -p stamped:=true`,
/// nav2 with `enable_stamped_cmd_vel`). A DDS topic has one type, so the
/// bridge takes one of them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CmdVelType {
    Twist,
    Stamped,
}

/// How the `/mech/estop` service (std_srvs/Trigger) maps onto DDS. ROS 2
/// services have no one DDS mapping: it depends on the RMW of the node that
/// calls (ROS 2's default, Fast DDS, uses the RPC-over-DDS "enhanced"
/// mapping; `rmw_cyclonedds` its own).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum EStopService {
    Enhanced,
    Cyclone,
    Basic,
    /// No service: the `/mech/estop` topic only.
    Off,
}

/// `[ros2]`: where the station is, who the bridge is there, and what it
/// accepts from ROS 2.
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Ros2Config {
    /// The station's router, UDP.
    pub router: SocketAddr,
    /// The bridge's sender name at the router; with `key`, the key's name.
    pub name: String,
    /// Controller key file (`mech-gcs keygen ros2`), listed in the station's
    /// `[auth]` with the channels `ros2/*` and `ros2goal/*`. None: unsigned,
    /// for a station that runs unauthenticated (the loopback demo).
    pub key: Option<PathBuf>,
    /// E-stop key file (role `estop` in the station's `[auth]`): with it,
    /// `/mech/estop` engages the e-stop of every robot. Without it the
    /// bridge engages only at an unauthenticated station, under `name`.
    pub estop_key: Option<PathBuf>,
    /// DDS domain (`ROS_DOMAIN_ID`). None: the environment's, else 0.
    pub domain_id: Option<u16>,
    /// cmd_vel of robot R is published on `<channel_prefix>R`.
    pub channel_prefix: String,
    /// goal_pose of robot R becomes a mission on `<goal_prefix>R`.
    pub goal_prefix: String,
    pub cmd_vel: CmdVelType,
    /// The world frame: odometry's and TF's parent, and the only frame a
    /// goal may be given in.
    pub map_frame: String,
    /// m/s: a cmd_vel whose linear speed is larger is refused.
    pub max_speed: f64,
    /// rad/s: a cmd_vel whose |angular.z| is larger is refused.
    pub max_yaw_rate: f64,
    /// m: a goal farther than this from the map's origin is refused.
    pub max_goal_distance: f64,
    /// m: a goal counts as reached within this distance.
    pub arrival_radius: f64,
    /// Take e-stop engage requests on the `/mech/estop` topic.
    pub estop: bool,
    /// ... and on the `/mech/estop` service, in this mapping.
    pub estop_service: EStopService,
    /// s: a robot whose telemetry has not arrived for this long is shown
    /// stale on `/diagnostics`.
    pub stale_after: f64,
    /// s between the summary lines in the log (0: none).
    pub summary_every: f64,
    /// The station to attach to for what the protocol does not carry
    /// (each robot's link quality, the arena): its control socket (a path)
    /// or `tcp:HOST:PORT` (with `attach_key`). None: not attached.
    pub attach: Option<String>,
    /// Operator key file for a station's TCP attach port.
    pub attach_key: Option<PathBuf>,
}

impl Default for Ros2Config {
    fn default() -> Self {
        Ros2Config {
            router: SocketAddr::from(([127, 0, 0, 1], 7400)),
            name: "ros2".into(),
            key: None,
            estop_key: None,
            domain_id: None,
            channel_prefix: "ros2/".into(),
            goal_prefix: "ros2goal/".into(),
            cmd_vel: CmdVelType::Twist,
            map_frame: "map".into(),
            max_speed: 5.0,
            max_yaw_rate: 10.0,
            max_goal_distance: 1000.0,
            arrival_radius: 0.1,
            estop: true,
            estop_service: EStopService::Enhanced,
            stale_after: 1.0,
            summary_every: 10.0,
            attach: None,
            attach_key: None,
        }
    }
}

/// The file's shape: only `[ros2]` is read, other sections are the
/// station's and are ignored, so the bridge can share `gcs.toml`.
#[derive(Debug, Default, Deserialize)]
struct File {
    #[serde(default)]
    ros2: Ros2Config,
}

impl Ros2Config {
    /// Reads `[ros2]` from a TOML file; key paths are relative to it.
    pub fn load(path: &Path) -> Result<Ros2Config, String> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        let mut config =
            Ros2Config::parse(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        let dir = path.parent().unwrap_or(Path::new("."));
        for key in [
            &mut config.key,
            &mut config.estop_key,
            &mut config.attach_key,
        ]
        .into_iter()
        .flatten()
        {
            if key.is_relative() {
                *key = dir.join(&*key);
            }
        }
        Ok(config)
    }

    /// The operator a bridge named `name` attaches to the station as (over
    /// its control socket; over TCP the operator key's name is used).
    pub fn attach_operator(name: &str) -> String {
        format!("{name}-bridge")
    }

    /// Reads `[ros2]` from TOML text and checks it.
    pub fn parse(text: &str) -> Result<Ros2Config, String> {
        let file: File = toml::from_str(text).map_err(|e| e.to_string())?;
        file.ros2.check()?;
        Ok(file.ros2)
    }

    /// Refuses settings that would make the bridge refuse everything, or
    /// pass anything.
    pub fn check(&self) -> Result<(), String> {
        let positive = [
            ("max_speed", self.max_speed),
            ("max_yaw_rate", self.max_yaw_rate),
            ("max_goal_distance", self.max_goal_distance),
            ("arrival_radius", self.arrival_radius),
            ("stale_after", self.stale_after),
        ];
        for (what, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("ros2.{what} must be a positive number, not {v}"));
            }
        }
        if !(self.summary_every.is_finite() && self.summary_every >= 0.0) {
            return Err("ros2.summary_every must be 0 or more seconds".into());
        }
        // Seconds the bridge waits: an hour at most.
        for (what, v) in [
            ("stale_after", self.stale_after),
            ("summary_every", self.summary_every),
        ] {
            if v > 3600.0 {
                return Err(format!("ros2.{what} must be 3600 s or less, not {v}"));
            }
        }
        if self.channel_prefix.is_empty() || self.goal_prefix.is_empty() {
            return Err("ros2.channel_prefix and ros2.goal_prefix must not be empty".into());
        }
        if self.channel_prefix == self.goal_prefix {
            return Err(
                "ros2.channel_prefix and ros2.goal_prefix must differ: cmd_vel and goals are two controllers"
                    .into(),
            );
        }
        if self.map_frame.is_empty() {
            return Err("ros2.map_frame must not be empty".into());
        }
        if self.attach.as_deref().is_some_and(str::is_empty) {
            return Err("ros2.attach must name the station's socket or tcp:HOST:PORT".into());
        }
        let tcp = self.attach.as_deref().is_some_and(|a| {
            matches!(
                mech_station::client::Address::parse(a),
                mech_station::client::Address::Tcp(_)
            )
        });
        if self.attach.is_none() && self.attach_key.is_some() {
            return Err("ros2.attach_key is for ros2.attach, which is not set".into());
        }
        if self.attach.is_some() && !tcp {
            mech_station::check_operator(&Ros2Config::attach_operator(&self.name))
                .map_err(|e| format!("ros2.name, as the station's operator when attached: {e}"))?;
        }
        if tcp && self.attach_key.is_none() {
            return Err(
                "ros2.attach over TCP needs an operator key: set ros2.attach_key (a key the station lists as an operator)"
                    .into(),
            );
        }
        Ok(())
    }

    /// The channel robot `robot`'s cmd_vel is published on.
    pub fn cmd_channel(&self, robot: &str) -> String {
        format!("{}{robot}", self.channel_prefix)
    }

    /// The channel robot `robot`'s goals are sent on.
    pub fn goal_channel(&self, robot: &str) -> String {
        format!("{}{robot}", self.goal_prefix)
    }

    /// The DDS domain: the setting, else `ROS_DOMAIN_ID`, else 0.
    pub fn domain(&self) -> Result<u16, String> {
        if let Some(d) = self.domain_id {
            return Ok(d);
        }
        match std::env::var("ROS_DOMAIN_ID") {
            Ok(v) if !v.trim().is_empty() => v
                .trim()
                .parse()
                .map_err(|_| format!("ROS_DOMAIN_ID={v:?} is not a domain number")),
            _ => Ok(0),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_key_is_optional_and_other_sections_are_ignored() {
        let c = Ros2Config::parse("[router]\nudp = \"0.0.0.0:7400\"\n").unwrap();
        assert_eq!(c.router, SocketAddr::from(([127, 0, 0, 1], 7400)));
        assert_eq!(c.cmd_channel("robot_1"), "ros2/robot_1");
        assert_eq!(c.goal_channel("robot_1"), "ros2goal/robot_1");
        assert_eq!(c.cmd_vel, CmdVelType::Twist);
    }

    #[test]
    fn settings_are_read_and_bad_ones_refused() {
        let c = Ros2Config::parse(
            "[ros2]\nrouter = \"127.0.0.1:7500\"\ncmd_vel = \"stamped\"\nmax_speed = 1.5\ndomain_id = 7\n",
        )
        .unwrap();
        assert_eq!(
            (c.router.port(), c.cmd_vel, c.max_speed),
            (7500, CmdVelType::Stamped, 1.5)
        );
        assert_eq!(c.domain(), Ok(7));
        let e = |t: &str| Ros2Config::parse(t).unwrap_err();
        assert!(e("[ros2]\nmax_speed = -1.0\n").contains("max_speed"));
        assert!(e("[ros2]\nmax_yaw_rate = nan\n").contains("max_yaw_rate"));
        assert!(e("[ros2]\nstale_after = 1e20\n").contains("stale_after"));
        assert!(e("[ros2]\nsummary_every = 1e20\n").contains("summary_every"));
        assert!(e("[ros2]\ngoal_prefix = \"ros2/\"\n").contains("must differ"));
        assert!(e("[ros2]\nspeed = 1.0\n").contains("unknown field"));
        assert!(e("[ros2]\ncmd_vel = \"twist_stamped\"\n").contains("unknown variant"));
        let c = Ros2Config::parse("[ros2]\nestop_service = \"cyclone\"\n").unwrap();
        assert_eq!(c.estop_service, EStopService::Cyclone);
    }

    #[test]
    fn attaching_over_tcp_needs_an_operator_key() {
        let c = Ros2Config::parse("[ros2]\nattach = \"/run/mech/gcs.sock\"\n").unwrap();
        assert_eq!(c.attach.as_deref(), Some("/run/mech/gcs.sock"));
        let e = Ros2Config::parse("[ros2]\nattach = \"tcp:10.0.0.2:7401\"\n").unwrap_err();
        assert!(e.contains("attach_key"), "{e}");
        let c =
            Ros2Config::parse("[ros2]\nattach = \"tcp:10.0.0.2:7401\"\nattach_key = \"ops.key\"\n")
                .unwrap();
        assert_eq!(c.attach_key.as_deref(), Some(Path::new("ops.key")));
        assert!(Ros2Config::parse("[ros2]\nattach = \"\"\n").is_err());
        let e = Ros2Config::parse("[ros2]\nattach_key = \"ops.key\"\n").unwrap_err();
        assert!(e.contains("not set"), "{e}");
        let long = format!(
            "[ros2]\nname = \"{}\"\nattach = \"/run/gcs.sock\"\n",
            "r".repeat(30)
        );
        assert!(Ros2Config::parse(&long).unwrap_err().contains("operator"));
    }

    #[test]
    fn key_paths_are_relative_to_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bridge.toml");
        std::fs::write(&path, "[ros2]\nkey = \"keys/ros2.key\"\n").unwrap();
        let c = Ros2Config::load(&path).unwrap();
        assert_eq!(c.key, Some(dir.path().join("keys/ros2.key")));
    }
}
