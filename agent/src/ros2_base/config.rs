//! `[ros2]` in a robot's config: the ROS 2 mobile base the agent drives,
//! by its topics. Parsed in every build; only a build with the `ros2`
//! feature can drive it.

use std::time::Duration;

use serde::Deserialize;

/// What the base's `cmd_vel` carries.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum CmdVelType {
    /// `geometry_msgs/Twist` (TurtleBot 3, most bases up to Humble).
    #[default]
    Twist,
    /// `geometry_msgs/TwistStamped` (TurtleBot 4 on Jazzy, ros2_control's
    /// diff_drive_controller with `use_stamped_vel`).
    TwistStamped,
}

/// The reliability the odometry subscription asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum OdomQos {
    /// Best effort (`SensorDataQoS`): matches best-effort and reliable
    /// publishers alike.
    #[default]
    BestEffort,
    /// Reliable: matches reliable publishers only.
    Reliable,
}

/// Where the odometry (or map) frame lies in the arena: the arena pose of
/// its origin. A base's odometry starts where it was switched on.
#[derive(Debug, Clone, Copy, PartialEq, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Origin {
    #[serde(default)]
    pub x: f64,
    #[serde(default)]
    pub y: f64,
    /// rad, counter-clockwise from the arena's x axis.
    #[serde(default)]
    pub heading: f64,
}

/// `[ros2]`: a ROS 2 mobile base takes the agent's velocity commands on
/// its `cmd_vel` and gives its pose on `odom` (and `/tf`); see
/// `docs/ros2.md`, "A ROS 2 robot as a MECH robot".
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Config {
    /// The base's namespace (`/tb3_1`), empty for none. Relative topic
    /// names are resolved in it, as ROS 2 resolves them.
    #[serde(default)]
    pub namespace: String,
    /// The DDS domain; without it `ROS_DOMAIN_ID`, else 0.
    #[serde(default)]
    pub domain_id: Option<u16>,
    #[serde(default = "cmd_vel")]
    pub cmd_vel: String,
    #[serde(default)]
    pub cmd_vel_type: CmdVelType,
    /// `header.frame_id` of a `TwistStamped`.
    #[serde(default = "base_link")]
    pub cmd_vel_frame: String,
    /// `nav_msgs/Odometry`: the base's pose and velocity.
    #[serde(default = "odom")]
    pub odom: String,
    #[serde(default)]
    pub odom_qos: OdomQos,
    /// `sensor_msgs/BatteryState`; empty for a base without one.
    #[serde(default = "battery_state")]
    pub battery: String,
    /// A localised robot: its pose is `map_frame` -> the odometry's frame
    /// (from `tf`, e.g. AMCL's `map` -> `odom`) composed with the
    /// odometry. Empty: the odometry's own frame.
    #[serde(default)]
    pub map_frame: String,
    /// The transform topic (`/tf`; `tf` for a namespaced TurtleBot 4).
    #[serde(default = "tf")]
    pub tf: String,
    /// The arena pose of the odometry's (or the map's) frame.
    #[serde(default)]
    pub origin: Origin,
    /// Seconds without odometry before the base counts as lost (outputs
    /// held at zero, the station told).
    #[serde(default = "two")]
    pub odom_timeout: f64,
}

fn cmd_vel() -> String {
    "cmd_vel".into()
}
fn base_link() -> String {
    "base_link".into()
}
fn odom() -> String {
    "odom".into()
}
fn battery_state() -> String {
    "battery_state".into()
}
fn tf() -> String {
    "/tf".into()
}
fn two() -> f64 {
    2.0
}

/// A ROS 2 name's characters: letters, digits, `_` and `/` separators, no
/// empty or digit-led token (the `rcl` rules, without `~` and `{}`).
fn name_ok(name: &str) -> bool {
    let body = name.strip_prefix('/').unwrap_or(name);
    !body.is_empty()
        && body.split('/').all(|token| {
            token
                .chars()
                .next()
                .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
                && token.chars().all(|c| c.is_ascii_alphanumeric() || c == '_')
        })
}

impl Ros2Config {
    /// Checks the values; `Err` says which is wrong.
    pub fn validate(&self) -> Result<(), String> {
        let namespace_ok = self.namespace.is_empty()
            || (self.namespace.starts_with('/') && name_ok(&self.namespace));
        if !namespace_ok {
            return Err(format!(
                "[ros2] namespace {:?}: expected empty or an absolute ROS 2 name such as \"/tb3_1\"",
                self.namespace
            ));
        }
        let topics = [
            ("cmd_vel", &self.cmd_vel),
            ("odom", &self.odom),
            ("tf", &self.tf),
        ];
        for (key, name) in topics {
            if !name_ok(name) {
                return Err(format!("[ros2] {key} {name:?}: not a ROS 2 topic name"));
            }
        }
        if !self.battery.is_empty() && !name_ok(&self.battery) {
            return Err(format!(
                "[ros2] battery {:?}: not a ROS 2 topic name",
                self.battery
            ));
        }
        for (key, frame) in [
            ("cmd_vel_frame", &self.cmd_vel_frame),
            ("map_frame", &self.map_frame),
        ] {
            if frame.chars().any(|c| c.is_whitespace() || c.is_control()) {
                return Err(format!(
                    "[ros2] {key} {frame:?}: a frame name has no spaces"
                ));
            }
        }
        if let Some(d) = self.domain_id
            && d > 232
        {
            return Err(format!("[ros2] domain_id {d}: ROS 2 domains are 0 to 232"));
        }
        let t = self.odom_timeout;
        if !(t.is_finite() && t > 0.0 && t <= 60.0) {
            return Err(format!(
                "[ros2] `odom_timeout` = {t}: expected seconds in (0, 60]"
            ));
        }
        let o = self.origin;
        if ![o.x, o.y, o.heading]
            .iter()
            .all(|v| v.is_finite() && v.abs() <= 1e5)
        {
            return Err("[ros2] origin: x, y and heading must be finite numbers".to_string());
        }
        Ok(())
    }

    pub fn odom_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.odom_timeout)
    }

    /// The DDS domain: the config's, else `ROS_DOMAIN_ID` (`env`), else 0.
    pub fn domain(&self, env: Option<&str>) -> Result<u16, String> {
        match (self.domain_id, env.map(str::trim).filter(|v| !v.is_empty())) {
            (Some(d), _) => Ok(d),
            (None, None) => Ok(0),
            (None, Some(v)) => v
                .parse::<u16>()
                .ok()
                .filter(|d| *d <= 232)
                .ok_or_else(|| format!("ROS_DOMAIN_ID={v:?}: expected a domain 0 to 232")),
        }
    }

    /// A topic's full name: absolute names as they are, relative ones in
    /// the namespace (`cmd_vel` in `/tb3_1` is `/tb3_1/cmd_vel`).
    pub fn resolve(&self, topic: &str) -> String {
        if topic.starts_with('/') {
            topic.to_string()
        } else {
            format!("{}/{topic}", self.namespace)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Ros2Config {
        toml::from_str(text).unwrap()
    }

    #[test]
    fn defaults_are_a_turtlebot_3s_topics() {
        let c = parse("");
        c.validate().unwrap();
        assert_eq!(c.resolve(&c.cmd_vel), "/cmd_vel");
        assert_eq!(c.resolve(&c.odom), "/odom");
        assert_eq!(c.resolve(&c.tf), "/tf");
        assert_eq!(c.cmd_vel_type, CmdVelType::Twist);
        assert_eq!(c.odom_qos, OdomQos::BestEffort);
        assert_eq!(c.odom_timeout(), Duration::from_secs(2));
    }

    #[test]
    fn relative_names_resolve_in_the_namespace() {
        let c = parse("namespace = \"/tb4_1\"\ntf = \"tf\"\ncmd_vel_type = \"twist-stamped\"");
        c.validate().unwrap();
        assert_eq!(c.resolve(&c.cmd_vel), "/tb4_1/cmd_vel");
        assert_eq!(c.resolve(&c.tf), "/tb4_1/tf");
        assert_eq!(c.resolve("/diagnostics"), "/diagnostics");
    }

    #[test]
    fn bad_values_are_refused_with_the_key() {
        for (text, key) in [
            ("namespace = \"tb3\"", "namespace"),
            ("namespace = \"/tb 3\"", "namespace"),
            ("cmd_vel = \"/a//b\"", "cmd_vel"),
            ("odom = \"1odom\"", "odom"),
            ("domain_id = 300", "domain_id"),
            ("odom_timeout = 0.0", "odom_timeout"),
            ("odom_timeout = nan", "odom_timeout"),
            ("map_frame = \"my map\"", "map_frame"),
            ("[origin]\nx = inf", "origin"),
        ] {
            let e = parse(text).validate().unwrap_err();
            assert!(e.contains(key), "{text}: {e}");
        }
        assert!(toml::from_str::<Ros2Config>("odom_topic = \"x\"").is_err());
    }

    #[test]
    fn the_domain_is_the_configs_else_the_environments() {
        assert_eq!(parse("domain_id = 7").domain(Some("3")), Ok(7));
        assert_eq!(parse("").domain(Some("3")), Ok(3));
        assert_eq!(parse("").domain(None), Ok(0));
        assert_eq!(parse("").domain(Some(" ")), Ok(0));
        assert!(
            parse("")
                .domain(Some("x"))
                .unwrap_err()
                .contains("ROS_DOMAIN_ID")
        );
    }
}
