//! `/<robot>/battery` (sensor_msgs/BatteryState): MECH telemetry carries
//! the charge fraction only; everything else is unknown (NaN, as the
//! message asks), and a robot that reports no battery is `present = false`.

use mech_proto::Telemetry;

use super::Frames;
use crate::msgs::builtin::Time;
use crate::msgs::sensor::{BatteryState, POWER_SUPPLY_UNKNOWN};
use crate::msgs::std::Header;

/// The battery message for a sample of `robot`.
pub fn battery(robot: &str, t: &Telemetry, stamp: Time, frames: &Frames) -> BatteryState {
    BatteryState {
        header: Header {
            stamp,
            frame_id: frames.base.clone(),
        },
        voltage: f32::NAN,
        temperature: f32::NAN,
        current: f32::NAN,
        charge: f32::NAN,
        capacity: f32::NAN,
        design_capacity: f32::NAN,
        percentage: t.battery.map_or(f32::NAN, |b| b as f32),
        power_supply_status: POWER_SUPPLY_UNKNOWN,
        power_supply_health: POWER_SUPPLY_UNKNOWN,
        power_supply_technology: POWER_SUPPLY_UNKNOWN,
        present: t.battery.is_some(),
        cell_voltage: Vec::new(),
        cell_temperature: Vec::new(),
        location: robot.to_string(),
        serial_number: String::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fleet::tests::telemetry;

    #[test]
    fn the_charge_is_the_percentage_and_the_rest_is_unknown() {
        let frames = Frames::new("map", "robot_1");
        let b = battery("robot_1", &telemetry(0.0, 0.0), Time::default(), &frames);
        assert_eq!((b.percentage, b.present), (0.8, true));
        assert!(b.voltage.is_nan() && b.current.is_nan());
        assert_eq!(b.header.frame_id, "robot_1/base_link");
        let mut none = telemetry(0.0, 0.0);
        none.battery = None;
        let b = battery("robot_1", &none, Time::default(), &frames);
        assert!(b.percentage.is_nan() && !b.present);
    }
}
