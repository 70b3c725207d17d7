//! Plane geometry shared by the controllers: angle wrapping and rotations
//! between the world frame and body or cluster frames.

pub use mech_proto::wrap_angle;

/// Rotates the vector `(x, y)` counter-clockwise by `angle`.
pub(crate) fn rotate(x: f64, y: f64, angle: f64) -> (f64, f64) {
    let (s, c) = angle.sin_cos();
    (c * x - s * y, s * x + c * y)
}

/// Euclidean length of `(x, y)`.
pub(crate) fn norm(x: f64, y: f64) -> f64 {
    x.hypot(y)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn wrap_keeps_half_open_range() {
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-3.0 * PI / 2.0) - PI / 2.0).abs() < 1e-12);
        assert_eq!(wrap_angle(0.25), 0.25);
        assert!(
            wrap_angle(f64::NAN).is_nan(),
            "a bad angle stays visibly bad"
        );
    }

    #[test]
    fn rotate_quarter_turn() {
        let (x, y) = rotate(1.0, 0.0, PI / 2.0);
        assert!(x.abs() < 1e-12 && (y - 1.0).abs() < 1e-12);
    }
}
