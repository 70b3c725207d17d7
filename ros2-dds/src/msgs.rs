//! ROS 2 messages in their field layout, for CDR on DDS: the structs are
//! serialized field by field in declaration order, which is the order of
//! the `.msg` files of ROS 2 Humble and Jazzy (the two lay out every type
//! here the same way). Only what the bridge publishes or takes is here.

pub mod builtin;
pub mod diagnostic;
pub mod geometry;
pub mod nav;
pub mod sensor;
pub mod std;
pub mod visualization;

/// A ROS 2 message type: its package and name make the DDS type name
/// (`geometry_msgs::msg::dds_::Twist_`) that other nodes match on.
pub trait RosMessage {
    /// The package, `geometry_msgs`.
    const PACKAGE: &'static str;
    /// The message, `Twist`.
    const NAME: &'static str;

    /// `geometry_msgs/msg/Twist`, as ROS 2 tools print it.
    fn ros_name() -> String {
        format!("{}/msg/{}", Self::PACKAGE, Self::NAME)
    }

    /// `geometry_msgs::msg::dds_::Twist_`, the type name on DDS.
    fn dds_name() -> String {
        format!("{}::msg::dds_::{}_", Self::PACKAGE, Self::NAME)
    }
}

/// Implements [`RosMessage`] for each `(type, package, name)`.
macro_rules! ros_message {
    ($($ty:ty => $package:literal / $name:literal),* $(,)?) => {
        $(impl $crate::msgs::RosMessage for $ty {
            const PACKAGE: &'static str = $package;
            const NAME: &'static str = $name;
        })*
    };
}
pub(crate) use ros_message;

#[cfg(test)]
mod tests {
    use super::RosMessage;
    use super::geometry::Twist;

    #[test]
    fn type_names_are_the_ones_ros_2_puts_on_dds() {
        assert_eq!(Twist::dds_name(), "geometry_msgs::msg::dds_::Twist_");
        assert_eq!(Twist::ros_name(), "geometry_msgs/msg/Twist");
    }
}
