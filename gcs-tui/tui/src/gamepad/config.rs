//! The gamepad section of the configuration (`[gamepad]`): shaping,
//! dead-man and other buttons, rate and limits, checked and turned into the
//! station's [`TeleopConfig`]. The station's configuration file carries
//! the section for the TUI, which reads it ([`teleop_config`]).

use mech_core::ConfigError;
use mech_proto::Named;
use mech_station::ConfigFile;
use serde::Deserialize;

use super::{Limits, PadButton, Shaping, TeleopConfig, TeleopMode};

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
            deadman: t.deadman.map_or("none", PadButton::as_str).to_string(),
            mode_button: t.mode_button.as_str().to_string(),
            estop_button: t.estop_button.as_str().to_string(),
            initial_mode: t.initial_mode.as_str().to_string(),
            rate_hz: t.rate_hz,
            max_speed: t.limits.max_speed,
            max_yaw_rate: t.limits.max_yaw_rate,
            max_scale_rate: t.limits.max_scale_rate,
        }
    }
}

fn button(key: &str, name: &str) -> Result<PadButton, ConfigError> {
    PadButton::parse(name).ok_or_else(|| {
        ConfigError(format!(
            "gamepad.{key}: unknown button {name:?}; buttons are {}",
            PadButton::names()
        ))
    })
}

/// The mode named `name`, or an error naming `gamepad.<key>` and the modes.
fn mode(key: &str, name: &str) -> Result<TeleopMode, ConfigError> {
    TeleopMode::parse(name).ok_or_else(|| {
        ConfigError(format!(
            "gamepad.{key}: unknown mode {name:?}; modes are {}",
            TeleopMode::names()
        ))
    })
}

/// The teleop settings of a configuration file's `[gamepad]` section (the
/// defaults without one), or what is wrong in it.
pub fn teleop_config(
    config: &ConfigFile,
) -> Result<TeleopConfig, mech_station::config::ConfigError> {
    let section: GamepadConfig = config.gamepad.read("gamepad")?;
    Ok(section.teleop()?)
}

impl GamepadConfig {
    /// The teleop settings these values describe, or the first value at
    /// fault.
    pub fn teleop(&self) -> Result<TeleopConfig, ConfigError> {
        self.check_numbers()?;
        let (deadman, mode_button, estop_button) = self.buttons()?;
        let initial_mode = mode("initial_mode", &self.initial_mode)?;
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

    /// Shaping, rate and limits in range.
    fn check_numbers(&self) -> Result<(), ConfigError> {
        let bad = |m: String| Err(ConfigError(m));
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
        Ok(())
    }

    /// The dead-man (if any), mode and e-stop buttons, each a different
    /// button.
    fn buttons(&self) -> Result<(Option<PadButton>, PadButton, PadButton), ConfigError> {
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
                return Err(ConfigError(format!(
                    "gamepad.{a} and gamepad.{b} must be different buttons"
                )));
            }
        }
        Ok((deadman, mode_button, estop_button))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The teleop settings of a whole configuration file's text.
    fn teleop_of(text: &str) -> Result<TeleopConfig, mech_station::config::ConfigError> {
        teleop_config(&ConfigFile::parse(text)?)
    }

    #[test]
    fn gamepad_section_reaches_the_teleop_settings() {
        let t = teleop_of(
            "[gamepad]\ndeadzone = 0.2\nexpo = 0\ndeadman = \"right-bumper\"\n\
             mode_button = \"north\"\nestop_button = \"mode\"\nrate_hz = 50\n\
             initial_mode = \"cluster\"\nmax_speed = 0.8\n",
        )
        .unwrap();
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
        let none = teleop_of("[gamepad]\ndeadman = \"none\"\n").unwrap();
        assert_eq!(none.deadman, None);
        assert_eq!(teleop_of("").unwrap(), TeleopConfig::default());
        assert_eq!(
            GamepadConfig::default().teleop().unwrap(),
            TeleopConfig::default()
        );
    }

    #[test]
    fn bad_gamepad_values_say_what_is_wrong() {
        let err = |text: &str| teleop_of(text).unwrap_err().to_string();
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
}
