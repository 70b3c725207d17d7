//! Plane geometry shared by the controllers: angle wrapping and rotations
//! between the world frame and body or cluster frames.

use std::f64::consts::PI;

/// Wraps an angle to `(-pi, pi]`, the range REP 103 headings use.
pub fn wrap_angle(a: f64) -> f64 {
    if !a.is_finite() {
        return 0.0;
    }
    let mut w = a % (2.0 * PI);
    if w <= -PI {
        w += 2.0 * PI;
    } else if w > PI {
        w -= 2.0 * PI;
    }
    w
}

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

    #[test]
    fn wrap_keeps_half_open_range() {
        assert!((wrap_angle(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-PI) - PI).abs() < 1e-12);
        assert!((wrap_angle(-3.0 * PI / 2.0) - PI / 2.0).abs() < 1e-12);
        assert_eq!(wrap_angle(0.25), 0.25);
        assert_eq!(wrap_angle(f64::NAN), 0.0);
    }

    #[test]
    fn rotate_quarter_turn() {
        let (x, y) = rotate(1.0, 0.0, PI / 2.0);
        assert!(x.abs() < 1e-12 && (y - 1.0).abs() < 1e-12);
    }
}
