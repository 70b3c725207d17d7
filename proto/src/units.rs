//! The protocol's conventions as code, shared by both ends: headings in
//! `(-π, π]` counter-clockwise from +x (REP 103), and message stamps in
//! microseconds since the Unix epoch.

use std::f64::consts::{PI, TAU};

/// Wraps an angle to `(-π, π]`, the range headings use on the wire. A
/// non-finite angle gives NaN, so a bad input cannot pass for a heading
/// (a command carrying it fails validation and is never sent).
pub fn wrap_angle(a: f64) -> f64 {
    let w = a.rem_euclid(TAU);
    if w > PI { w - TAU } else { w }
}

/// Microseconds since the Unix epoch: the `stamp_us` a sender writes in a
/// header. For display and logs only, never for safety timing (a robot
/// without network time may think it is 1970); a clock before 1970 gives 0.
pub fn unix_micros() -> u64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_micros() as u64)
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_wrap_into_the_half_open_range() {
        for (a, w) in [
            (0.0, 0.0),
            (PI, PI),
            (-PI, PI),
            (3.0 * PI, PI),
            (TAU + 0.5, 0.5),
            (-TAU - 0.5, -0.5),
            (1e6, 1e6_f64.rem_euclid(TAU) - TAU),
        ] {
            assert!((wrap_angle(a) - w).abs() < 1e-9, "{a} -> {}", wrap_angle(a));
        }
        assert!(wrap_angle(f64::NAN).is_nan());
        assert!(wrap_angle(f64::INFINITY).is_nan());
    }
}
