//! `sensor_msgs/BatteryState`.

use serde::{Deserialize, Serialize};

use super::ros_message;
use super::std::Header;

/// `sensor_msgs/BatteryState`. Unknown real values are NaN, as the message
/// asks.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct BatteryState {
    pub header: Header,
    pub voltage: f32,
    pub temperature: f32,
    pub current: f32,
    pub charge: f32,
    pub capacity: f32,
    pub design_capacity: f32,
    /// Charge fraction in [0, 1].
    pub percentage: f32,
    pub power_supply_status: u8,
    pub power_supply_health: u8,
    pub power_supply_technology: u8,
    pub present: bool,
    pub cell_voltage: Vec<f32>,
    pub cell_temperature: Vec<f32>,
    pub location: String,
    pub serial_number: String,
}

/// `POWER_SUPPLY_STATUS_UNKNOWN`, `_HEALTH_UNKNOWN`, `_TECHNOLOGY_UNKNOWN`.
pub const POWER_SUPPLY_UNKNOWN: u8 = 0;

ros_message!(BatteryState => "sensor_msgs" / "BatteryState");
