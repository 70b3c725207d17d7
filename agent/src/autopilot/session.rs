//! The MAVLink conversation with one autopilot, without I/O: messages heard
//! go in ([`Session::receive`]), and out come the setpoints, heartbeats and
//! commands to send, and reports for the operator. The vehicle
//! ([`super::vehicle`]) moves the bytes; tests drive this directly.
//!
//! - Heartbeats: the first autopilot heard (or the configured system) is the
//!   target; its firmware (PX4, ArduPilot), vehicle type, armed state and
//!   mode are followed, and every change is reported. Silence for the
//!   heartbeat timeout is reported as the autopilot lost.
//! - Setpoints: SET_POSITION_TARGET_LOCAL_NED in `MAV_FRAME_LOCAL_NED`,
//!   velocity and yaw rate only (type mask 0x05c7), from a body twist.
//! - Telemetry: LOCAL_POSITION_NED (position, velocity), ATTITUDE (yaw,
//!   yaw rate), SYS_STATUS (battery), GLOBAL_POSITION_INT (home altitude,
//!   for a PX4 takeoff), STATUSTEXT warnings, COMMAND_ACK.
//! - Commands (COMMAND_LONG) only for an operator's [`AutopilotAction`]:
//!   nothing here arms, disarms or changes the mode by itself.

use std::time::Duration;

use mavlink::MavHeader;
use mavlink::dialects::common::{
    COMMAND_LONG_DATA, HEARTBEAT_DATA, MavAutopilot, MavCmd, MavFrame, MavMessage, MavModeFlag,
    MavResult, MavSeverity, MavState, MavType, PositionTargetTypemask,
    SET_POSITION_TARGET_LOCAL_NED_DATA,
};
use mech_proto::{AutopilotAction, AutopilotNews, Level, Pose, Telemetry, Twist, Velocity};

use super::config::{AutopilotConfig, Flavour};
use super::frames::{Ned, pose_from_ned, twist_to_ned, velocity_from_ned};
pub use crate::runtime::Report;

/// Unanswered commands remembered for their acknowledgements.
const PENDING: usize = 8;

/// Velocity and yaw rate only: position, acceleration and yaw ignored.
pub const VELOCITY_TYPE_MASK: u16 = 0x05c7;

/// The autopilot being flown: who it is and what it last said.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    pub system: u8,
    pub component: u8,
    pub flavour: Flavour,
    /// Ground rovers and boats have no land or take-off.
    pub rover: bool,
}

/// The newest of what the autopilot reports of the vehicle.
#[derive(Debug, Clone, Default)]
struct Reported {
    position: Option<Ned>,
    /// A LOCAL_POSITION_NED arrived since [`Session::take_pose`].
    fresh_position: bool,
    velocity: Option<Ned>,
    /// Yaw and yaw rate, rad and rad/s.
    yaw: Option<(f64, f64)>,
    battery: Option<f64>,
    /// AMSL altitude of home, m (GLOBAL_POSITION_INT alt - relative_alt).
    home_amsl: Option<f64>,
}

/// The state of the conversation; see the module docs.
#[derive(Debug, Clone)]
pub struct Session {
    system_id: u8,
    component_id: u8,
    /// Configured firmware (`Auto`: from the heartbeat).
    flavour: Flavour,
    target_system: u8,
    timeout: Duration,
    target: Option<Target>,
    last_heartbeat: Option<Duration>,
    lost: bool,
    armed: Option<bool>,
    mode: Option<String>,
    /// What the autopilot says of the vehicle's motion and battery.
    vehicle: Reported,
    /// Commands sent and not yet acknowledged, oldest first, so each
    /// COMMAND_ACK can name its action (at most [`PENDING`]).
    pending: Vec<(MavCmd, AutopilotAction)>,
}

impl Session {
    pub fn new(config: &AutopilotConfig) -> Session {
        Session {
            system_id: config.system_id,
            component_id: config.component_id,
            flavour: config.flavour,
            target_system: config.target_system,
            timeout: config.heartbeat_timeout(),
            target: None,
            last_heartbeat: None,
            lost: false,
            armed: None,
            mode: None,
            vehicle: Reported::default(),
            pending: Vec::new(),
        }
    }

    /// The header this agent sends with.
    pub fn header(&self) -> MavHeader {
        MavHeader {
            system_id: u32::from(self.system_id),
            component_id: self.component_id,
            sequence: 0,
        }
    }

    pub fn target(&self) -> Option<Target> {
        self.target
    }

    /// Whether the autopilot's heartbeat came within the timeout.
    pub fn connected(&self, now: Duration) -> bool {
        self.last_heartbeat
            .is_some_and(|t| now.saturating_sub(t) <= self.timeout)
    }

    pub fn armed(&self) -> Option<bool> {
        self.armed
    }

    /// The autopilot's mode, by name (`OFFBOARD`, `GUIDED`...).
    pub fn mode(&self) -> Option<&str> {
        self.mode.as_deref()
    }

    /// Takes in one message; returns what the operator should hear.
    pub fn receive(&mut self, header: &MavHeader, msg: &MavMessage, now: Duration) -> Vec<Report> {
        if let MavMessage::HEARTBEAT(hb) = msg {
            return self.heartbeat(header, hb, now);
        }
        let from_target = self.target.is_some_and(|t| {
            u32::from(t.system) == header.system_id && t.component == header.component_id
        });
        if !from_target {
            return Vec::new();
        }
        match msg {
            MavMessage::LOCAL_POSITION_NED(p) => {
                let f = |v: f32| f64::from(v);
                if [p.x, p.y, p.z, p.vx, p.vy, p.vz]
                    .iter()
                    .all(|v| v.is_finite())
                {
                    self.vehicle.position = Some(Ned {
                        north: f(p.x),
                        east: f(p.y),
                        down: f(p.z),
                    });
                    self.vehicle.velocity = Some(Ned {
                        north: f(p.vx),
                        east: f(p.vy),
                        down: f(p.vz),
                    });
                    self.vehicle.fresh_position = true;
                }
            }
            MavMessage::ATTITUDE(a) if a.yaw.is_finite() && a.yawspeed.is_finite() => {
                self.vehicle.yaw = Some((f64::from(a.yaw), f64::from(a.yawspeed)));
            }
            MavMessage::SYS_STATUS(s) => {
                // -1: the autopilot does not know.
                self.vehicle.battery = (0..=100)
                    .contains(&s.battery_remaining)
                    .then(|| f64::from(s.battery_remaining) / 100.0);
            }
            MavMessage::GLOBAL_POSITION_INT(g) => {
                self.vehicle.home_amsl = Some(f64::from(g.alt - g.relative_alt) / 1000.0);
            }
            MavMessage::COMMAND_ACK(ack) => return self.command_ack(ack.command, ack.result),
            MavMessage::STATUSTEXT(t)
                if (t.severity as u8) <= MavSeverity::MAV_SEVERITY_WARNING as u8 =>
            {
                let text = t.text.to_str().unwrap_or("(not UTF-8)").trim();
                return vec![Report::warn(format!("autopilot: {text}"))];
            }
            _ => {}
        }
        Vec::new()
    }

    fn heartbeat(&mut self, header: &MavHeader, hb: &HEARTBEAT_DATA, now: Duration) -> Vec<Report> {
        let mut out = Vec::new();
        let autopilot = !matches!(hb.autopilot, MavAutopilot::MAV_AUTOPILOT_INVALID)
            && !matches!(
                hb.mavtype,
                MavType::MAV_TYPE_GCS | MavType::MAV_TYPE_ONBOARD_CONTROLLER
            );
        // Targets of our commands are 8-bit system ids.
        let Ok(system) = u8::try_from(header.system_id) else {
            return out;
        };
        let wanted = self.target_system == 0 || self.target_system == system;
        if !autopilot || !wanted {
            return out;
        }
        let target = match self.target {
            Some(t) if t.system == system && t.component == header.component_id => t,
            Some(_) => return out, // another autopilot: ignored
            None => {
                let flavour = match (self.flavour, hb.autopilot) {
                    (Flavour::Auto, MavAutopilot::MAV_AUTOPILOT_PX4) => Flavour::Px4,
                    (Flavour::Auto, MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA) => {
                        Flavour::Ardupilot
                    }
                    (configured, _) => configured,
                };
                let t = Target {
                    system,
                    component: header.component_id,
                    flavour,
                    rover: matches!(
                        hb.mavtype,
                        MavType::MAV_TYPE_GROUND_ROVER | MavType::MAV_TYPE_SURFACE_BOAT
                    ),
                };
                self.target = Some(t);
                let which = format!(
                    "{} {:?}, system {} component {}",
                    flavour_name(flavour),
                    hb.mavtype,
                    t.system,
                    t.component
                );
                out.push(Report::info(AutopilotNews::Found(which).text()));
                t
            }
        };
        if self.lost {
            self.lost = false;
            out.push(Report::info(AutopilotNews::HeardAgain.text()));
        }
        self.last_heartbeat = Some(now);
        let armed = hb
            .base_mode
            .contains(MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED);
        if self.armed != Some(armed) {
            if self.armed.is_some() || armed {
                out.push(Report::info(AutopilotNews::Armed(armed).text()));
            }
            self.armed = Some(armed);
        }
        let mode = mode_name(target, hb.custom_mode);
        if self.mode.as_deref() != Some(mode.as_str()) {
            out.push(Report::info(AutopilotNews::Mode(mode.clone()).text()));
            self.mode = Some(mode);
        }
        out
    }

    /// Whether the vehicle is armed and its flight mode, as reports, once
    /// the autopilot has said: what a station that did not hear the
    /// changes (it started later, or the robot registered again) is told.
    pub fn state_reports(&self) -> Vec<Report> {
        let mut out = Vec::new();
        if let Some(armed) = self.armed {
            out.push(Report::info(AutopilotNews::Armed(armed).text()));
        }
        if let Some(mode) = &self.mode {
            out.push(Report::info(AutopilotNews::Mode(mode.clone()).text()));
        }
        out
    }

    /// Reports (once) an autopilot whose heartbeat stopped.
    pub fn check_link(&mut self, now: Duration) -> Option<Report> {
        if self.last_heartbeat.is_some() && !self.connected(now) && !self.lost {
            self.lost = true;
            let why = format!("no heartbeat for {:.1} s", self.timeout.as_secs_f64());
            return Some(Report {
                level: Level::Error,
                text: AutopilotNews::Lost(why).text(),
            });
        }
        None
    }

    fn command_ack(&mut self, command: MavCmd, result: MavResult) -> Vec<Report> {
        let Some(i) = self.pending.iter().position(|(sent, _)| *sent == command) else {
            return Vec::new();
        };
        let action = self.pending.remove(i).1.as_str();
        match result {
            MavResult::MAV_RESULT_ACCEPTED => {
                vec![Report::info(format!("autopilot accepted {action}"))]
            }
            MavResult::MAV_RESULT_IN_PROGRESS => Vec::new(),
            other => vec![Report::warn(format!(
                "autopilot refused {action}: {other:?}"
            ))],
        }
    }

    /// The pose, when a LOCAL_POSITION_NED arrived since the last call and
    /// the yaw is known.
    pub fn take_pose(&mut self) -> Option<Pose> {
        if !self.vehicle.fresh_position {
            return None;
        }
        let (position, (yaw, _)) = (self.vehicle.position?, self.vehicle.yaw?);
        self.vehicle.fresh_position = false;
        Some(pose_from_ned(position, yaw))
    }

    /// World-frame velocity (ENU) as the autopilot measures it.
    pub fn velocity(&self) -> Option<Velocity> {
        let (v, (_, rate)) = (self.vehicle.velocity?, self.vehicle.yaw?);
        Some(velocity_from_ned(v, rate))
    }

    /// The same velocity in the body frame (REP 103: x forward, y left),
    /// turned by the autopilot's heading.
    pub fn body_twist(&self) -> Option<Twist> {
        let v = self.velocity()?;
        let (yaw, _) = self.vehicle.yaw?;
        let (sin, cos) = super::frames::yaw_to_heading(yaw).sin_cos();
        Some(Twist {
            vx: cos * v.vx + sin * v.vy,
            vy: -sin * v.vx + cos * v.vy,
            vz: v.vz,
            wz: v.wz,
        })
    }

    /// Battery charge, a fraction.
    pub fn battery(&self) -> Option<f64> {
        self.vehicle.battery
    }

    /// Puts what the autopilot measures into the agent's telemetry: its
    /// velocity (measured, instead of the commanded one) and its battery.
    pub fn patch(&self, t: &mut Telemetry) {
        if let Some(v) = self.velocity() {
            t.velocity = v;
            t.velocity_source = mech_proto::VelocitySource::Measured;
        }
        if self.vehicle.battery.is_some() {
            t.battery = self.vehicle.battery;
        }
    }

    /// Our HEARTBEAT: an onboard controller, not an autopilot.
    pub fn heartbeat_message(&self) -> MavMessage {
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode: 0,
            mavtype: MavType::MAV_TYPE_ONBOARD_CONTROLLER,
            autopilot: MavAutopilot::MAV_AUTOPILOT_INVALID,
            base_mode: MavModeFlag::empty(),
            system_status: MavState::MAV_STATE_ACTIVE,
            mavlink_version: 3,
        })
    }

    /// The velocity setpoint for a body twist, or `None` before an autopilot
    /// is known. Without a yaw yet, only a zero setpoint (hold) is sent.
    pub fn setpoint(&self, twist: &Twist, now: Duration) -> Option<MavMessage> {
        let target = self.target?;
        let still = Twist::default();
        let (twist, heading) = match self.vehicle.yaw {
            Some((yaw, _)) => (twist, super::frames::yaw_to_heading(yaw)),
            None => (&still, 0.0),
        };
        let s = twist_to_ned(twist, heading);
        Some(MavMessage::SET_POSITION_TARGET_LOCAL_NED(
            SET_POSITION_TARGET_LOCAL_NED_DATA {
                time_boot_ms: now.as_millis() as u32,
                x: 0.0,
                y: 0.0,
                z: 0.0,
                vx: s.velocity.north as f32,
                vy: s.velocity.east as f32,
                vz: s.velocity.down as f32,
                afx: 0.0,
                afy: 0.0,
                afz: 0.0,
                yaw: 0.0,
                yaw_rate: s.yaw_rate as f32,
                type_mask: PositionTargetTypemask::from_bits_truncate(VELOCITY_TYPE_MASK),
                target_system: target.system,
                target_component: target.component,
                coordinate_frame: MavFrame::MAV_FRAME_LOCAL_NED,
            },
        ))
    }

    /// The COMMAND_LONG that carries out an operator's request, or why it
    /// cannot be.
    pub fn request(
        &mut self,
        action: AutopilotAction,
        altitude: f64,
    ) -> Result<MavMessage, String> {
        let target = self.target.ok_or("no autopilot heard yet")?;
        let nan = f32::NAN;
        let (command, params) = match action {
            AutopilotAction::Arm => (
                MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
                [1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ),
            AutopilotAction::Disarm => (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, [0.0; 7]),
            AutopilotAction::Offboard | AutopilotAction::Hold | AutopilotAction::Land => {
                let (main, sub) = mode_number(target, action)?;
                (
                    MavCmd::MAV_CMD_DO_SET_MODE,
                    [
                        f32::from(MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED.bits()),
                        main,
                        sub,
                        0.0,
                        0.0,
                        0.0,
                        0.0,
                    ],
                )
            }
            AutopilotAction::Takeoff => {
                if target.rover {
                    return Err("a ground vehicle does not take off".to_string());
                }
                // ArduPilot: metres above home; PX4: above mean sea level,
                // from home's altitude. Without it PX4 would be sent NaN
                // (its own MIS_TAKEOFF_ALT), ignoring the operator's
                // altitude unseen: refused instead, saying why.
                let alt = match (target.flavour, self.vehicle.home_amsl) {
                    (Flavour::Px4, Some(home)) => (home + altitude) as f32,
                    (Flavour::Px4, None) => {
                        return Err(format!(
                            "PX4 takes off to an altitude above sea level and its home \
                             altitude is not known yet (no GLOBAL_POSITION_INT heard: no \
                             global position fix?), so {altitude} m above home cannot be \
                             given; wait for a position fix, or take off from PX4's own \
                             controls"
                        ));
                    }
                    _ => altitude as f32,
                };
                let (lat, lon) = match target.flavour {
                    Flavour::Px4 => (nan, nan),
                    _ => (0.0, 0.0),
                };
                (
                    MavCmd::MAV_CMD_NAV_TAKEOFF,
                    [0.0, 0.0, 0.0, nan, lat, lon, alt],
                )
            }
        };
        if self.pending.len() >= PENDING {
            self.pending.remove(0); // never answered
        }
        self.pending.push((command, action));
        Ok(MavMessage::COMMAND_LONG(COMMAND_LONG_DATA {
            param1: params[0],
            param2: params[1],
            param3: params[2],
            param4: params[3],
            param5: params[4],
            param6: params[5],
            param7: params[6],
            command,
            target_system: target.system,
            target_component: target.component,
            confirmation: 0,
        }))
    }
}

fn flavour_name(f: Flavour) -> &'static str {
    match f {
        Flavour::Px4 => "PX4",
        Flavour::Ardupilot => "ArduPilot",
        Flavour::Auto => "MAVLink",
    }
}

/// PX4 main modes (custom_mode bits 16-23) and AUTO sub-modes (bits 24-31).
mod px4 {
    pub const POSCTL: u32 = 3;
    pub const AUTO: u32 = 4;
    pub const OFFBOARD: u32 = 6;
    pub const AUTO_TAKEOFF: u32 = 2;
    pub const AUTO_LOITER: u32 = 3;
    pub const AUTO_MISSION: u32 = 4;
    pub const AUTO_RTL: u32 = 5;
    pub const AUTO_LAND: u32 = 6;
}

/// ArduCopter and ArduRover custom modes.
mod ardupilot {
    pub const COPTER_GUIDED: u32 = 4;
    pub const COPTER_LOITER: u32 = 5;
    pub const COPTER_LAND: u32 = 9;
    pub const ROVER_HOLD: u32 = 4;
    pub const ROVER_GUIDED: u32 = 15;
}

/// DO_SET_MODE's custom mode (and PX4 sub-mode) for an action.
fn mode_number(target: Target, action: AutopilotAction) -> Result<(f32, f32), String> {
    let refuse = || Err(format!("a ground vehicle has no {} mode", action.as_str()));
    let (main, sub) = match (target.flavour, action, target.rover) {
        (Flavour::Px4, AutopilotAction::Offboard, _) => (px4::OFFBOARD, 0),
        (Flavour::Px4, AutopilotAction::Hold, _) => (px4::AUTO, px4::AUTO_LOITER),
        (Flavour::Px4, AutopilotAction::Land, false) => (px4::AUTO, px4::AUTO_LAND),
        (Flavour::Ardupilot, AutopilotAction::Offboard, false) => (ardupilot::COPTER_GUIDED, 0),
        (Flavour::Ardupilot, AutopilotAction::Offboard, true) => (ardupilot::ROVER_GUIDED, 0),
        (Flavour::Ardupilot, AutopilotAction::Hold, false) => (ardupilot::COPTER_LOITER, 0),
        (Flavour::Ardupilot, AutopilotAction::Hold, true) => (ardupilot::ROVER_HOLD, 0),
        (Flavour::Ardupilot, AutopilotAction::Land, false) => (ardupilot::COPTER_LAND, 0),
        (_, AutopilotAction::Land, true) => return refuse(),
        (Flavour::Auto, ..) => {
            return Err("unknown autopilot firmware: set [autopilot] flavour".to_string());
        }
        _ => return Err(format!("{} is not a mode change", action.as_str())),
    };
    Ok((main as f32, sub as f32))
}

/// The name of the mode a heartbeat's custom_mode says.
fn mode_name(target: Target, custom_mode: u32) -> String {
    match target.flavour {
        Flavour::Px4 => {
            let (main, sub) = ((custom_mode >> 16) & 0xff, (custom_mode >> 24) & 0xff);
            match (main, sub) {
                (px4::OFFBOARD, _) => "OFFBOARD".to_string(),
                (px4::POSCTL, _) => "POSCTL".to_string(),
                (px4::AUTO, px4::AUTO_TAKEOFF) => "AUTO.TAKEOFF".to_string(),
                (px4::AUTO, px4::AUTO_LOITER) => "AUTO.LOITER".to_string(),
                (px4::AUTO, px4::AUTO_MISSION) => "AUTO.MISSION".to_string(),
                (px4::AUTO, px4::AUTO_RTL) => "AUTO.RTL".to_string(),
                (px4::AUTO, px4::AUTO_LAND) => "AUTO.LAND".to_string(),
                (main, sub) => format!("PX4 {main}.{sub}"),
            }
        }
        Flavour::Ardupilot => {
            let name = match (target.rover, custom_mode) {
                (false, 0) => "STABILIZE",
                (false, 2) => "ALT_HOLD",
                (false, 3) => "AUTO",
                (false, ardupilot::COPTER_GUIDED) => "GUIDED",
                (false, ardupilot::COPTER_LOITER) => "LOITER",
                (false, 6) => "RTL",
                (false, ardupilot::COPTER_LAND) => "LAND",
                (true, 0) => "MANUAL",
                (true, ardupilot::ROVER_HOLD) => "HOLD",
                (true, 10) => "AUTO",
                (true, ardupilot::ROVER_GUIDED) => "GUIDED",
                _ => return format!("ArduPilot {custom_mode}"),
            };
            name.to_string()
        }
        Flavour::Auto => format!("custom {custom_mode}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mavlink::dialects::common::{
        ATTITUDE_DATA, COMMAND_ACK_DATA, GLOBAL_POSITION_INT_DATA, LOCAL_POSITION_NED_DATA,
        MavSysStatusSensor, SYS_STATUS_DATA,
    };

    fn config() -> AutopilotConfig {
        toml::from_str("link = \"udpin:127.0.0.1:14540\"").unwrap()
    }

    fn from(system: u8, component: u8) -> MavHeader {
        MavHeader {
            system_id: u32::from(system),
            component_id: component,
            sequence: 0,
        }
    }

    fn heartbeat(
        autopilot: MavAutopilot,
        mavtype: MavType,
        armed: bool,
        custom_mode: u32,
    ) -> MavMessage {
        let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
        if armed {
            base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        MavMessage::HEARTBEAT(HEARTBEAT_DATA {
            custom_mode,
            mavtype,
            autopilot,
            base_mode,
            system_status: MavState::MAV_STATE_STANDBY,
            mavlink_version: 3,
        })
    }

    fn px4(armed: bool, main: u32, sub: u32) -> MavMessage {
        heartbeat(
            MavAutopilot::MAV_AUTOPILOT_PX4,
            MavType::MAV_TYPE_QUADROTOR,
            armed,
            (main << 16) | (sub << 24),
        )
    }

    const S: Duration = Duration::from_secs(1);

    #[test]
    fn the_first_autopilot_heard_is_the_target_and_its_changes_are_reported() {
        let mut s = Session::new(&config());
        // A ground station's heartbeat is not an autopilot.
        let gcs = heartbeat(
            MavAutopilot::MAV_AUTOPILOT_INVALID,
            MavType::MAV_TYPE_GCS,
            false,
            0,
        );
        assert!(s.receive(&from(255, 190), &gcs, S).is_empty());
        assert_eq!(
            s.setpoint(&Twist::default(), S),
            None,
            "nowhere to send yet"
        );
        let found = s.receive(&from(1, 1), &px4(false, px4::POSCTL, 0), S);
        assert!(
            found[0].text.contains("PX4") && found[1].text.contains("POSCTL"),
            "{found:?}"
        );
        assert_eq!(s.armed(), Some(false));
        let other = px4(true, px4::OFFBOARD, 0);
        assert!(
            s.receive(&from(2, 1), &other, S).is_empty(),
            "a second autopilot is ignored"
        );
        let changed = s.receive(&from(1, 1), &px4(true, px4::OFFBOARD, 0), 2 * S);
        let texts: Vec<&str> = changed.iter().map(|r| r.text.as_str()).collect();
        assert_eq!(texts, ["autopilot armed", "autopilot mode OFFBOARD"]);
        assert!(s.connected(3 * S) && s.check_link(3 * S).is_none());
        assert!(!s.connected(5 * S));
        assert_eq!(s.check_link(5 * S).map(|r| r.level), Some(Level::Error));
        assert_eq!(s.check_link(6 * S), None, "reported once");
        let back = s.receive(&from(1, 1), &px4(true, px4::OFFBOARD, 0), 7 * S);
        assert_eq!(back[0].text, "autopilot heard again");
    }

    #[test]
    fn telemetry_is_converted_to_the_enu_frame() {
        let mut s = Session::new(&config());
        s.receive(&from(1, 1), &px4(false, px4::POSCTL, 0), S);
        let position = MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
            time_boot_ms: 1,
            x: 2.0,
            y: 1.0,
            z: -1.5,
            vx: 0.5,
            vy: -0.25,
            vz: -0.1,
        });
        s.receive(&from(1, 1), &position, S);
        assert_eq!(s.take_pose(), None, "no yaw yet");
        let attitude = MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms: 1,
            roll: 0.0,
            pitch: 0.0,
            yaw: std::f32::consts::FRAC_PI_2, // facing east
            rollspeed: 0.0,
            pitchspeed: 0.0,
            yawspeed: 0.2, // turning clockwise
        });
        s.receive(&from(1, 1), &attitude, S);
        s.receive(&from(1, 1), &position, S);
        let pose = s.take_pose().unwrap();
        assert_eq!((pose.x, pose.y, pose.z), (1.0, 2.0, 1.5));
        assert!(pose.heading.abs() < 1e-6, "east is heading 0: {pose:?}");
        assert_eq!(s.take_pose(), None, "one pose per LOCAL_POSITION_NED");
        let v = s.velocity().unwrap();
        assert!((v.vx + 0.25).abs() < 1e-6 && (v.vy - 0.5).abs() < 1e-6);
        assert!((v.vz - 0.1).abs() < 1e-6 && (v.wz + 0.2).abs() < 1e-6);
        let status = |remaining| {
            MavMessage::SYS_STATUS(SYS_STATUS_DATA {
                onboard_control_sensors_present: MavSysStatusSensor::empty(),
                onboard_control_sensors_enabled: MavSysStatusSensor::empty(),
                onboard_control_sensors_health: MavSysStatusSensor::empty(),
                load: 0,
                voltage_battery: 12_000,
                current_battery: -1,
                drop_rate_comm: 0,
                errors_comm: 0,
                errors_count1: 0,
                errors_count2: 0,
                errors_count3: 0,
                errors_count4: 0,
                battery_remaining: remaining,
            })
        };
        s.receive(&from(1, 1), &status(76), S);
        assert_eq!(s.battery(), Some(0.76));
        s.receive(&from(1, 1), &status(-1), S);
        assert_eq!(s.battery(), None, "-1 means unknown");
        // Another system's position is not ours.
        s.receive(&from(7, 1), &position, S);
        assert_eq!(s.take_pose(), None);
    }

    #[test]
    fn a_twist_becomes_a_local_ned_velocity_setpoint() {
        let mut s = Session::new(&config());
        s.receive(&from(1, 1), &px4(false, px4::POSCTL, 0), S);
        let forward_left = Twist {
            vx: 1.0,
            vy: 0.0,
            vz: 0.5,
            wz: 0.3,
        };
        // Before the attitude is known only a hold is sent.
        let Some(MavMessage::SET_POSITION_TARGET_LOCAL_NED(sp)) = s.setpoint(&forward_left, S)
        else {
            panic!("a setpoint")
        };
        assert_eq!((sp.vx, sp.vy, sp.vz, sp.yaw_rate), (0.0, 0.0, 0.0, 0.0));
        let attitude = MavMessage::ATTITUDE(ATTITUDE_DATA {
            time_boot_ms: 1,
            roll: 0.0,
            pitch: 0.0,
            yaw: 0.0, // facing north
            rollspeed: 0.0,
            pitchspeed: 0.0,
            yawspeed: 0.0,
        });
        s.receive(&from(1, 1), &attitude, S);
        let Some(MavMessage::SET_POSITION_TARGET_LOCAL_NED(sp)) = s.setpoint(&forward_left, S)
        else {
            panic!("a setpoint")
        };
        assert_eq!(sp.coordinate_frame, MavFrame::MAV_FRAME_LOCAL_NED);
        assert_eq!(sp.type_mask.bits(), 0x05c7);
        assert_eq!((sp.target_system, sp.target_component), (1, 1));
        // Facing north, forward is +north; climbing is -down; a left turn
        // is a negative (anticlockwise) NED yaw rate.
        assert!((sp.vx - 1.0).abs() < 1e-6 && sp.vy.abs() < 1e-6);
        assert!((sp.vz + 0.5).abs() < 1e-6 && (sp.yaw_rate + 0.3).abs() < 1e-6);
    }

    #[test]
    fn requests_become_the_firmwares_commands() {
        let mut s = Session::new(&config());
        assert!(
            s.request(AutopilotAction::Arm, 0.0).is_err(),
            "no autopilot yet"
        );
        s.receive(&from(1, 1), &px4(false, px4::POSCTL, 0), S);
        let command = |m: MavMessage| match m {
            MavMessage::COMMAND_LONG(c) => c,
            other => panic!("{other:?}"),
        };
        let arm = command(s.request(AutopilotAction::Arm, 0.0).unwrap());
        assert_eq!(
            (arm.command, arm.param1),
            (MavCmd::MAV_CMD_COMPONENT_ARM_DISARM, 1.0)
        );
        let ack = |s: &mut Session, command, result| {
            let msg = MavMessage::COMMAND_ACK(COMMAND_ACK_DATA { command, result });
            s.receive(&from(1, 1), &msg, S)
        };
        let refused = ack(
            &mut s,
            MavCmd::MAV_CMD_COMPONENT_ARM_DISARM,
            MavResult::MAV_RESULT_DENIED,
        );
        assert_eq!(refused[0].level, Level::Warn);
        assert!(refused[0].text.contains("refused arm"), "{refused:?}");
        let off = command(s.request(AutopilotAction::Offboard, 0.0).unwrap());
        assert_eq!(off.command, MavCmd::MAV_CMD_DO_SET_MODE);
        assert_eq!((off.param1, off.param2), (1.0, 6.0));
        let land = command(s.request(AutopilotAction::Land, 0.0).unwrap());
        assert_eq!((land.param2, land.param3), (4.0, 6.0));
        // Two mode changes in flight: their acknowledgements come in order.
        let accepted = ack(
            &mut s,
            MavCmd::MAV_CMD_DO_SET_MODE,
            MavResult::MAV_RESULT_ACCEPTED,
        );
        assert_eq!(accepted[0].text, "autopilot accepted offboard");
        let accepted = ack(
            &mut s,
            MavCmd::MAV_CMD_DO_SET_MODE,
            MavResult::MAV_RESULT_ACCEPTED,
        );
        assert_eq!(accepted[0].text, "autopilot accepted land");

        let mut rover = Session::new(&config());
        let hb = heartbeat(
            MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            MavType::MAV_TYPE_GROUND_ROVER,
            false,
            ardupilot::ROVER_HOLD,
        );
        let found = rover.receive(&from(1, 1), &hb, S);
        assert!(
            found.iter().any(|r| r.text == "autopilot mode HOLD"),
            "{found:?}"
        );
        let guided = command(rover.request(AutopilotAction::Offboard, 0.0).unwrap());
        assert_eq!(guided.param2, 15.0);
        assert!(rover.request(AutopilotAction::Land, 0.0).is_err());
        assert!(rover.request(AutopilotAction::Takeoff, 2.0).is_err());

        let mut copter = Session::new(&config());
        let hb = heartbeat(
            MavAutopilot::MAV_AUTOPILOT_ARDUPILOTMEGA,
            MavType::MAV_TYPE_QUADROTOR,
            false,
            ardupilot::COPTER_GUIDED,
        );
        copter.receive(&from(1, 1), &hb, S);
        let takeoff = command(copter.request(AutopilotAction::Takeoff, 2.5).unwrap());
        assert_eq!(
            (takeoff.command, takeoff.param7),
            (MavCmd::MAV_CMD_NAV_TAKEOFF, 2.5)
        );
    }

    #[test]
    fn a_px4_takeoff_without_home_altitude_is_refused_saying_why() {
        let mut s = Session::new(&config());
        s.receive(&from(1, 1), &px4(false, px4::POSCTL, 0), S);
        let why = s.request(AutopilotAction::Takeoff, 2.0).unwrap_err();
        assert!(why.contains("GLOBAL_POSITION_INT"), "{why}");
        assert!(why.contains("2 m above home"), "{why}");
        // Home at 488 m above sea level (and the vehicle 1.5 m above it).
        let global = MavMessage::GLOBAL_POSITION_INT(GLOBAL_POSITION_INT_DATA {
            time_boot_ms: 1,
            lat: 473_977_420,
            lon: 85_455_940,
            alt: 489_500,
            relative_alt: 1_500,
            vx: 0,
            vy: 0,
            vz: 0,
            hdg: 0,
        });
        s.receive(&from(1, 1), &global, S);
        let MavMessage::COMMAND_LONG(c) = s.request(AutopilotAction::Takeoff, 2.0).unwrap() else {
            panic!("a command");
        };
        assert_eq!(c.command, MavCmd::MAV_CMD_NAV_TAKEOFF);
        assert!((c.param7 - 490.0).abs() < 1e-3, "home + 2 m: {}", c.param7);
    }

    #[test]
    fn the_state_is_said_again_on_request_once_known() {
        let mut s = Session::new(&config());
        assert!(s.state_reports().is_empty(), "nothing heard yet");
        s.receive(&from(1, 1), &px4(true, px4::OFFBOARD, 0), S);
        let texts: Vec<String> = s.state_reports().into_iter().map(|r| r.text).collect();
        assert_eq!(texts, ["autopilot armed", "autopilot mode OFFBOARD"]);
    }
}
