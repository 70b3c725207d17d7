//! `mech-agent --check`, past the config and the key: opens every device
//! the robot's config names (the GPIO pins of an L298 or of wheel
//! encoders, the serial ports of a radio, a Pozyx tag, a GPS or an
//! autopilot) without driving any of them, and says exactly which could
//! not be opened and why. A robot's config is checked on the robot before
//! its first drive; a Pi's config checked off a Pi names the GPIO and the
//! serial ports this machine lacks, and nothing else.
//!
//! The devices are behind [`Devices`], so what is checked, and how each
//! failure is told, is tested with fakes; [`HostDevices`] opens the real
//! ones (rppal under the `rpi` feature, serialport under `serial`).

use std::collections::BTreeMap;

use crate::config::{ActuatorConfig, LinkConfig, PositionConfig, RobotConfig};

/// Opening a device, and letting it go again at once.
pub trait Devices {
    /// Opens the GPIO controller and takes each of `pins` (BCM numbers)
    /// without changing its mode or level.
    fn gpio(&mut self, pins: &[u8]) -> Result<(), String>;
    /// Opens a serial port at `baud`.
    fn serial(&mut self, port: &str, baud: u32) -> Result<(), String>;
    /// Joins DDS domain `domain` (a ROS 2 base's), and leaves it.
    fn dds(&mut self, domain: u16) -> Result<(), String>;
}

/// A device the config names that this machine could not open.
#[derive(Debug, Clone, PartialEq)]
pub struct Unopened {
    /// `GPIO 6, 12, 20` or `serial port /dev/ttyACM0 at 115200 baud`.
    pub device: String,
    /// What in the config needs it: `actuators: L298`, `position: Pozyx`.
    pub users: Vec<String>,
    /// The error opening it gave.
    pub why: String,
}

impl std::fmt::Display for Unopened {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{} ({}): {}",
            self.device,
            self.users.join("; "),
            self.why
        )
    }
}

/// Every device `config` names, each opened once however many parts of the
/// config use it; returns those that could not be opened, GPIO first, then
/// serial ports by name.
pub fn check(config: &RobotConfig, devices: &mut impl Devices) -> Vec<Unopened> {
    let mut unopened = Vec::new();
    let (pins, users) = gpio_needs(config);
    if !pins.is_empty()
        && let Err(why) = devices.gpio(&pins)
    {
        let list: Vec<String> = pins.iter().map(u8::to_string).collect();
        unopened.push(Unopened {
            device: format!("GPIO {}", list.join(", ")),
            users,
            why,
        });
    }
    for (port, (baud, users)) in serial_needs(config) {
        if let Err(why) = devices.serial(&port, baud) {
            unopened.push(Unopened {
                device: format!("serial port {port} at {baud} baud"),
                users,
                why,
            });
        }
    }
    if let Some(ros2) = config.ros2() {
        let env = std::env::var("ROS_DOMAIN_ID").ok();
        let joined = ros2
            .domain(env.as_deref())
            .and_then(|domain| devices.dds(domain).map(|()| domain));
        if let Err(why) = joined {
            unopened.push(Unopened {
                device: "DDS domain".to_string(),
                users: vec!["ros2".to_string()],
                why,
            });
        }
    }
    unopened
}

/// The GPIO pins the config drives or reads, in the config's order without
/// repeats, and what uses them.
fn gpio_needs(config: &RobotConfig) -> (Vec<u8>, Vec<String>) {
    let mut pins = Vec::new();
    let mut users = Vec::new();
    let mut take = |p: u8| {
        if !pins.contains(&p) {
            pins.push(p);
        }
    };
    if let ActuatorConfig::L298 { channels, .. } = config.actuators() {
        for c in channels {
            take(c.in1);
            take(c.in2);
            take(c.enable);
        }
        users.push("actuators: L298".to_string());
    }
    if let Some(e) = config.encoders() {
        for w in &e.channels {
            take(w.a);
            if let Some(b) = w.b {
                take(b);
            }
        }
        users.push("encoders".to_string());
    }
    (pins, users)
}

/// The serial ports the config opens, each with its baud rate and users.
fn serial_needs(config: &RobotConfig) -> BTreeMap<String, (u32, Vec<String>)> {
    let mut ports: BTreeMap<String, (u32, Vec<String>)> = BTreeMap::new();
    let mut add = |port: &str, baud: u32, user: String| {
        ports
            .entry(port.to_string())
            .or_insert_with(|| (baud, Vec::new()))
            .1
            .push(user);
    };
    for link in config.links() {
        if let LinkConfig::Serial { port, baud, .. } = link {
            add(port, *baud, "link: serial radio".to_string());
        }
    }
    match config.position() {
        PositionConfig::Pozyx { port, baud, .. } => add(port, *baud, "position: Pozyx".into()),
        PositionConfig::Nmea { port, baud, .. } => add(port, *baud, "position: NMEA GPS".into()),
        PositionConfig::None | PositionConfig::Sim | PositionConfig::External => {}
    }
    if let Some(a) = config.autopilot() {
        // `serial:DEVICE:BAUD`; the other links are sockets, opened by the
        // agent when it starts.
        if let Some((port, baud)) = a
            .link
            .strip_prefix("serial:")
            .and_then(|rest| rest.rsplit_once(':'))
            .and_then(|(port, baud)| Some((port, baud.parse::<u32>().ok()?)))
        {
            add(port, baud, "autopilot".to_string());
        }
    }
    ports
}

/// The devices of the machine the agent runs on.
#[derive(Debug, Default)]
pub struct HostDevices;

impl Devices for HostDevices {
    #[cfg(feature = "rpi")]
    fn gpio(&mut self, pins: &[u8]) -> Result<(), String> {
        let gpio = rppal::gpio::Gpio::new().map_err(|e| e.to_string())?;
        for &pin in pins {
            gpio.get(pin).map_err(|e| e.to_string())?;
        }
        Ok(())
    }

    #[cfg(not(feature = "rpi"))]
    fn gpio(&mut self, _pins: &[u8]) -> Result<(), String> {
        Err("this build has no GPIO support; rebuild with `--features rpi`".to_string())
    }

    #[cfg(feature = "serial")]
    fn serial(&mut self, port: &str, baud: u32) -> Result<(), String> {
        serialport::new(port, baud)
            .timeout(std::time::Duration::from_millis(100))
            .open()
            .map(drop)
            .map_err(|e| e.to_string())
    }

    #[cfg(not(feature = "serial"))]
    fn serial(&mut self, _port: &str, _baud: u32) -> Result<(), String> {
        Err("this build has no serial support; rebuild with `--features serial`".to_string())
    }

    #[cfg(feature = "ros2")]
    fn dds(&mut self, domain: u16) -> Result<(), String> {
        let options = ros2_client::ContextOptions::new().domain_id(domain);
        ros2_client::Context::with_options(options)
            .map(drop)
            .map_err(|e| format!("cannot join DDS domain {domain}: {e:?}"))
    }

    #[cfg(not(feature = "ros2"))]
    fn dds(&mut self, _domain: u16) -> Result<(), String> {
        Err("this build has no ROS 2 support; rebuild with `--features ros2`".to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Devices that open what they are told to and refuse the rest,
    /// remembering every attempt.
    #[derive(Debug, Default)]
    struct Fake {
        gpio: bool,
        ports: Vec<&'static str>,
        asked: Vec<String>,
    }

    impl Devices for Fake {
        fn gpio(&mut self, pins: &[u8]) -> Result<(), String> {
            self.asked.push(format!("gpio {pins:?}"));
            if self.gpio {
                Ok(())
            } else {
                Err("Unknown SoC".into())
            }
        }

        fn dds(&mut self, domain: u16) -> Result<(), String> {
            self.asked.push(format!("dds {domain}"));
            if domain == 0 {
                Ok(())
            } else {
                Err("no multicast interface".into())
            }
        }

        fn serial(&mut self, port: &str, baud: u32) -> Result<(), String> {
            self.asked.push(format!("serial {port} {baud}"));
            if self.ports.contains(&port) {
                Ok(())
            } else {
                Err("No such file or directory".into())
            }
        }
    }

    fn pi_config() -> RobotConfig {
        let text = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../config/agents/pi-l298-encoders-diff-drive.toml"
        ))
        .unwrap();
        RobotConfig::parse(&text, "pi").unwrap()
    }

    #[test]
    fn a_pi_config_off_a_pi_names_its_gpio_and_its_serial_port_and_nothing_else() {
        let mut off_pi = Fake::default();
        let unopened = check(&pi_config(), &mut off_pi);
        let lines: Vec<String> = unopened.iter().map(ToString::to_string).collect();
        assert_eq!(
            lines,
            [
                "GPIO 6, 12, 20, 13, 19, 26, 17, 27, 22, 23 (actuators: L298; encoders): Unknown SoC",
                "serial port /dev/ttyACM0 at 115200 baud (position: Pozyx): No such file or directory",
            ]
        );
        // Each device opened once.
        assert_eq!(off_pi.asked.len(), 2, "{:?}", off_pi.asked);
    }

    #[test]
    fn on_a_pi_with_its_tag_plugged_in_nothing_is_unopened() {
        let mut on_pi = Fake {
            gpio: true,
            ports: vec!["/dev/ttyACM0"],
            ..Fake::default()
        };
        assert!(check(&pi_config(), &mut on_pi).is_empty());
    }

    #[test]
    fn a_port_shared_by_two_users_is_opened_once_and_names_both() {
        let text = "name = \"r\"\n[platform]\nkind = \"diff-drive\"\ntrack_width = 0.15\n\
                    max_wheel_speed = 0.5\n[link]\nkind = \"serial\"\nport = \"/dev/ttyUSB0\"\n\
                    baud = 57600\n[position]\nkind = \"nmea\"\nport = \"/dev/ttyUSB0\"\n\
                    baud = 57600\n[position.origin]\nlatitude = 47.0\nlongitude = 8.0\n";
        let config = RobotConfig::parse(text, "shared").unwrap();
        let mut fake = Fake::default();
        let unopened = check(&config, &mut fake);
        assert_eq!(unopened.len(), 1);
        assert_eq!(
            unopened[0].users,
            ["link: serial radio", "position: NMEA GPS"]
        );
        assert_eq!(fake.asked, ["serial /dev/ttyUSB0 57600"]);
    }

    #[test]
    fn an_autopilot_on_a_uart_is_checked_and_one_on_udp_is_not() {
        let drone = |link: &str| {
            let text = format!(
                "name = \"d\"\n[platform]\nkind = \"quadcopter\"\nmax_speed = 1.0\n\
                 max_climb = 0.5\nmax_yaw_rate = 1.0\n\
                 [autopilot]\nlink = \"{link}\"\n"
            );
            RobotConfig::parse(&text, "drone").unwrap()
        };
        let mut fake = Fake::default();
        let unopened = check(&drone("serial:/dev/ttyAMA0:921600"), &mut fake);
        assert_eq!(
            unopened[0].to_string(),
            "serial port /dev/ttyAMA0 at 921600 baud (autopilot): No such file or directory"
        );
        assert!(check(&drone("udpin:0.0.0.0:14540"), &mut Fake::default()).is_empty());
    }

    #[test]
    fn a_ros2_base_joins_its_dds_domain() {
        let base = |domain: u16| {
            let text = format!(
                "name = \"tb3_1\"\n[platform]\nkind = \"diff-drive\"\ntrack_width = 0.16\nmax_wheel_speed = 0.22\n[ros2]\ndomain_id = {domain}\n"
            );
            RobotConfig::parse(&text, "tb3.toml").unwrap()
        };
        let mut devices = Fake::default();
        assert!(check(&base(0), &mut devices).is_empty());
        assert_eq!(devices.asked, ["dds 0"]);
        let unopened = check(&base(7), &mut Fake::default());
        assert_eq!(
            unopened[0].to_string(),
            "DDS domain (ros2): no multicast interface"
        );
    }

    #[test]
    fn a_simulated_robot_names_no_device() {
        let text = "name = \"s\"\n[platform]\nkind = \"kiwi\"\nradius = 0.1\n\
                    max_wheel_speed = 0.5\n[position]\nkind = \"sim\"\n";
        let mut fake = Fake::default();
        assert!(check(&RobotConfig::parse(text, "sim").unwrap(), &mut fake).is_empty());
        assert!(fake.asked.is_empty());
    }
}
