//! `/<robot>/odom` (nav_msgs/Odometry) and the robot's transform on `/tf`,
//! from one telemetry sample. The pose is the robot's estimate in the
//! world frame; the twist is turned into the body frame, where
//! nav_msgs/Odometry puts it (REP 105), from MECH's world-frame velocity.

use mech_proto::Telemetry;

use super::Frames;
use crate::msgs::builtin::Time;
use crate::msgs::geometry::{
    Covariance, Point, Pose, PoseWithCovariance, Quaternion, Transform, TransformStamped, Twist,
    TwistWithCovariance, Vector3,
};
use crate::msgs::nav::Odometry;
use crate::msgs::std::Header;

/// The odometry message for a sample. MECH telemetry carries no
/// covariance (only a fix quality, on `/diagnostics`), so the covariances
/// are zero: unknown, as most ROS 2 drivers without one publish.
pub fn odometry(t: &Telemetry, stamp: Time, frames: &Frames) -> Odometry {
    let p = &t.pose;
    let v = &t.velocity;
    let (s, c) = p.heading.sin_cos();
    Odometry {
        header: Header {
            stamp,
            frame_id: frames.map.clone(),
        },
        child_frame_id: frames.base.clone(),
        pose: PoseWithCovariance {
            pose: Pose {
                position: Point {
                    x: p.x,
                    y: p.y,
                    z: p.z,
                },
                orientation: Quaternion::from_yaw(p.heading),
            },
            covariance: Covariance::default(),
        },
        twist: TwistWithCovariance {
            twist: Twist {
                linear: Vector3 {
                    x: c * v.vx + s * v.vy,
                    y: -s * v.vx + c * v.vy,
                    z: v.vz,
                },
                angular: Vector3 {
                    x: 0.0,
                    y: 0.0,
                    z: v.wz,
                },
            },
            covariance: Covariance::default(),
        },
    }
}

/// `map` -> `<robot>/base_link` for a sample.
pub fn transform(t: &Telemetry, stamp: Time, frames: &Frames) -> TransformStamped {
    let p = &t.pose;
    TransformStamped {
        header: Header {
            stamp,
            frame_id: frames.map.clone(),
        },
        child_frame_id: frames.base.clone(),
        transform: Transform {
            translation: Vector3 {
                x: p.x,
                y: p.y,
                z: p.z,
            },
            rotation: Quaternion::from_yaw(p.heading),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fleet::tests::telemetry;
    use std::f64::consts::FRAC_PI_2;

    #[test]
    fn odometry_holds_the_pose_in_the_map_and_the_twist_in_the_body_frame() {
        let mut t = telemetry(1.0, FRAC_PI_2);
        t.pose.y = 2.0;
        t.pose.z = 0.5;
        t.velocity.vy = 0.3; // heading north at 0.3 m/s: forward in the body frame
        t.velocity.wz = 0.2;
        let frames = Frames::new("map", "robot_1");
        let stamp = Time::from_micros(1_700_000_000_500_000);
        let o = odometry(&t, stamp, &frames);
        assert_eq!(o.header.frame_id, "map");
        assert_eq!(o.header.stamp, stamp);
        assert_eq!(o.child_frame_id, "robot_1/base_link");
        let pos = o.pose.pose.position;
        assert_eq!((pos.x, pos.y, pos.z), (1.0, 2.0, 0.5));
        assert!((o.pose.pose.orientation.yaw() - FRAC_PI_2).abs() < 1e-12);
        let lin = o.twist.twist.linear;
        assert!(
            (lin.x - 0.3).abs() < 1e-12 && lin.y.abs() < 1e-12,
            "{lin:?}"
        );
        assert_eq!(o.twist.twist.angular.z, 0.2);
        let tf = transform(&t, stamp, &frames);
        assert_eq!(
            (tf.header.frame_id.as_str(), tf.child_frame_id.as_str()),
            ("map", "robot_1/base_link")
        );
        assert_eq!(tf.transform.translation.y, 2.0);
        assert_eq!(tf.transform.rotation, o.pose.pose.orientation);
    }
}
