//! `nav_msgs/Odometry` and `tf2_msgs/TFMessage`.

use serde::{Deserialize, Serialize};

use super::geometry::{PoseWithCovariance, TransformStamped, TwistWithCovariance};
use super::ros_message;
use super::std::Header;

/// `nav_msgs/Odometry`: the pose in `header.frame_id`, the twist in
/// `child_frame_id` (the robot's body frame, REP 105).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Odometry {
    pub header: Header,
    pub child_frame_id: String,
    pub pose: PoseWithCovariance,
    pub twist: TwistWithCovariance,
}

/// `tf2_msgs/TFMessage`, what `/tf` carries.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TfMessage {
    pub transforms: Vec<TransformStamped>,
}

ros_message!(
    Odometry => "nav_msgs" / "Odometry",
    TfMessage => "tf2_msgs" / "TFMessage",
);
