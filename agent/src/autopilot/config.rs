//! `[autopilot]` in a robot's config: where the autopilot is and how to
//! talk to it. Parsed in every build; only a build with the `mavlink`
//! feature (the default) can fly it.

use std::time::Duration;

use serde::Deserialize;

/// Which autopilot firmware: it decides how modes are named and numbered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Flavour {
    /// From the autopilot's HEARTBEAT (`MAV_AUTOPILOT_PX4` or
    /// `MAV_AUTOPILOT_ARDUPILOTMEGA`).
    #[default]
    Auto,
    Px4,
    Ardupilot,
}

/// `[autopilot]`: a PX4 or ArduPilot autopilot flies the vehicle; the agent
/// sends it velocity setpoints over MAVLink 2 and reads its position.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AutopilotConfig {
    /// The MAVLink link: `udpin:0.0.0.0:14540` (listen, as PX4's offboard
    /// port expects), `udpout:HOST:PORT`, `tcpout:HOST:PORT` or
    /// `serial:/dev/ttyAMA0:921600` (with the `serial` feature).
    pub link: String,
    #[serde(default)]
    pub flavour: Flavour,
    /// This agent's MAVLink system id: a companion computer shares its
    /// vehicle's (1).
    #[serde(default = "one")]
    pub system_id: u8,
    /// This agent's component id (191, `MAV_COMP_ID_ONBOARD_COMPUTER`).
    #[serde(default = "onboard_computer")]
    pub component_id: u8,
    /// The autopilot's system id; 0 takes the first autopilot heard.
    #[serde(default)]
    pub target_system: u8,
    /// Seconds without the autopilot's HEARTBEAT before it counts as lost.
    #[serde(default = "two")]
    pub heartbeat_timeout: f64,
}

fn one() -> u8 {
    1
}

fn onboard_computer() -> u8 {
    191
}

fn two() -> f64 {
    2.0
}

/// Link address prefixes the `mavlink` crate opens.
pub const LINK_KINDS: [&str; 5] = ["udpin:", "udpout:", "udpbcast:", "tcpout:", "serial:"];

impl AutopilotConfig {
    /// Checks the values; `Err` says which is wrong.
    pub fn validate(&self) -> Result<(), String> {
        if !LINK_KINDS.iter().any(|k| self.link.starts_with(k)) {
            return Err(format!(
                "[autopilot] link {:?}: expected udpin:ADDR:PORT, udpout:HOST:PORT, tcpout:HOST:PORT or serial:DEVICE:BAUD",
                self.link
            ));
        }
        let t = self.heartbeat_timeout;
        if !(t.is_finite() && t > 0.0 && t <= 60.0) {
            return Err(format!(
                "[autopilot] `heartbeat_timeout` = {t}: expected seconds in (0, 60]"
            ));
        }
        if self.system_id == 0 {
            return Err("[autopilot] `system_id` 0 is a broadcast id; use 1 to 255".to_string());
        }
        Ok(())
    }

    pub fn heartbeat_timeout(&self) -> Duration {
        Duration::from_secs_f64(self.heartbeat_timeout)
    }
}

#[cfg(test)]
mod tests {
    use crate::config::RobotConfig;

    const DRONE: &str = "name = \"d\"\n[platform]\nkind = \"quadcopter\"\nmax_speed = 1.0\n\
                         max_climb = 0.5\nmax_yaw_rate = 1.0\n";

    fn error(extra: &str) -> String {
        RobotConfig::parse(&format!("{DRONE}{extra}"), "d.toml")
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn an_autopilot_section_parses_with_defaults_and_is_checked() {
        let c = RobotConfig::parse(
            &format!("{DRONE}[autopilot]\nlink = \"udpin:0.0.0.0:14540\"\n"),
            "d.toml",
        )
        .unwrap();
        let a = c.autopilot().unwrap();
        assert_eq!((a.system_id, a.component_id, a.target_system), (1, 191, 0));
        assert_eq!(a.flavour, super::Flavour::Auto);
        let e = error("[autopilot]\nlink = \"com3\"\n");
        assert!(e.starts_with("d.toml:7:1:") && e.contains("udpin:"), "{e}");
        let e = error("[autopilot]\nlink = \"udpin:0.0.0.0:14540\"\nheartbeat_timeout = 0\n");
        assert!(e.contains("heartbeat_timeout"), "{e}");
        let e = error("[autopilot]\nlink = \"udpin:0.0.0.0:14540\"\nflavour = \"inav\"\n");
        assert!(e.contains("inav"), "{e}");
        let e =
            error("[autopilot]\nlink = \"udpin:0.0.0.0:14540\"\n[position]\nkind = \"external\"\n");
        assert!(e.contains("leave out [position]"), "{e}");
    }
}
