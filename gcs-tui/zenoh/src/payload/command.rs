//! `mech/<station>/<robot>/cmd/<channel>`: one command, as JSON with one
//! key naming its kind (the command kinds' names in the command language):
//!
//! ```json
//! {"twist": {"vx": 0.2, "wz": 0.1}}
//! {"steering-throttle": {"steering": 0.1, "throttle": 0.5}}
//! {"velocity-heading": {"speed": 0.3, "heading": 1.57}}
//! {"actuators": {"outputs": [0.2, -0.2]}}
//! {"stop": {}}
//! ```
//!
//! Twist components left out are zero; every other field is required, and
//! an unknown field or kind is an error.

use mech_proto::{Actuators, Command, SteeringThrottle, Stop, Twist, VelocityHeading};
use serde::{Deserialize, Serialize};

use super::PayloadError;

/// One command as JSON.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case", deny_unknown_fields)]
pub enum CommandMsg {
    /// Body frame: m/s and rad/s.
    Twist {
        #[serde(default)]
        vx: f64,
        #[serde(default)]
        vy: f64,
        #[serde(default)]
        vz: f64,
        #[serde(default)]
        wz: f64,
    },
    /// Both in [-1, 1]; steering > 0 turns left.
    SteeringThrottle { steering: f64, throttle: f64 },
    /// m/s and rad (world frame).
    VelocityHeading { speed: f64, heading: f64 },
    /// One output per motor, each in [-1, 1].
    Actuators { outputs: Vec<f64> },
    /// Controlled stop (not latched).
    Stop {},
}

impl CommandMsg {
    /// Reads a command payload and checks it as the protocol checks a
    /// received command (finite, in range).
    pub fn read(bytes: &[u8]) -> Result<Command, PayloadError> {
        let msg: CommandMsg = super::from_json("command", bytes)?;
        let command = msg.command();
        command.validate().map_err(|e| PayloadError::Invalid {
            what: "command",
            detail: e.to_string(),
        })?;
        Ok(command)
    }

    pub fn command(&self) -> Command {
        match self {
            CommandMsg::Twist { vx, vy, vz, wz } => Command::Twist(Twist {
                vx: *vx,
                vy: *vy,
                vz: *vz,
                wz: *wz,
            }),
            CommandMsg::SteeringThrottle { steering, throttle } => {
                Command::SteeringThrottle(SteeringThrottle {
                    steering: *steering,
                    throttle: *throttle,
                })
            }
            CommandMsg::VelocityHeading { speed, heading } => {
                Command::VelocityHeading(VelocityHeading {
                    speed: *speed,
                    heading: *heading,
                })
            }
            CommandMsg::Actuators { outputs } => Command::Actuators(Actuators {
                outputs: outputs.clone(),
            }),
            CommandMsg::Stop {} => Command::Stop(Stop {}),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_kind_reads_as_its_command() {
        let read = |s: &str| CommandMsg::read(s.as_bytes());
        assert_eq!(
            read(r#"{"twist": {"vx": 0.2, "wz": 0.1}}"#).unwrap(),
            Command::Twist(Twist {
                vx: 0.2,
                vy: 0.0,
                vz: 0.0,
                wz: 0.1
            })
        );
        assert_eq!(
            read(r#"{"steering-throttle": {"steering": 0.1, "throttle": 0.5}}"#).unwrap(),
            Command::SteeringThrottle(SteeringThrottle {
                steering: 0.1,
                throttle: 0.5
            })
        );
        assert!(matches!(
            read(r#"{"velocity-heading": {"speed": 0.3, "heading": 1.5}}"#).unwrap(),
            Command::VelocityHeading(_)
        ));
        assert!(matches!(
            read(r#"{"actuators": {"outputs": [0.2, -0.2]}}"#).unwrap(),
            Command::Actuators(_)
        ));
        assert_eq!(read(r#"{"stop": {}}"#).unwrap(), Command::Stop(Stop {}));
    }

    #[test]
    fn typos_unknown_kinds_and_out_of_range_values_are_refused() {
        for bad in [
            r#"{"twist": {"vX": 0.2}}"#,
            r#"{"warp": {}}"#,
            r#"{"steering-throttle": {"steering": 0.1}}"#,
            r#"{"steering-throttle": {"steering": 3.0, "throttle": 0.0}}"#,
            r#"{"actuators": {"outputs": [2.0]}}"#,
            r#"{"twist": {"vx": 1e999}}"#,
            r#"{"twist": {}, "stop": {}}"#,
            "not json",
            "",
        ] {
            assert!(CommandMsg::read(bad.as_bytes()).is_err(), "{bad}");
        }
    }

    #[test]
    fn commands_write_as_they_read() {
        let msg = CommandMsg::Twist {
            vx: 0.5,
            vy: 0.0,
            vz: 0.0,
            wz: -0.2,
        };
        let json = serde_json::to_string(&msg).unwrap();
        assert_eq!(json, r#"{"twist":{"vx":0.5,"vy":0.0,"vz":0.0,"wz":-0.2}}"#);
        assert_eq!(CommandMsg::read(json.as_bytes()).unwrap(), msg.command());
    }
}
