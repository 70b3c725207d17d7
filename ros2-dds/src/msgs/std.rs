//! `std_msgs` (header, colour, empty) and `std_srvs` (trigger).

use serde::{Deserialize, Serialize};

use super::builtin::Time;
use super::ros_message;

/// `std_msgs/Header`: when, and in which frame.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Header {
    pub stamp: Time,
    pub frame_id: String,
}

/// `std_msgs/ColorRGBA`, each component in [0, 1].
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct ColorRgba {
    pub r: f32,
    pub g: f32,
    pub b: f32,
    pub a: f32,
}

/// `std_msgs/Empty`. DDS has no empty structs: ROS 2 gives it one octet,
/// `structure_needs_at_least_one_member`, which receivers ignore.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Empty {
    pub structure_needs_at_least_one_member: u8,
}

/// `std_srvs/Trigger` request: empty, as [`Empty`].
pub type TriggerRequest = Empty;

/// `std_srvs/Trigger` response.
#[derive(Debug, Clone, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TriggerResponse {
    pub success: bool,
    pub message: String,
}

ros_message!(Empty => "std_msgs" / "Empty");

impl ros2_client::Message for Empty {}
impl ros2_client::Message for TriggerResponse {}
