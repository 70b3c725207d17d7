//! `builtin_interfaces`: time stamps and durations.

use serde::{Deserialize, Serialize};

/// `builtin_interfaces/Time`: seconds and nanoseconds since the Unix epoch
/// (the ROS clock when it is not simulated).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Time {
    pub sec: i32,
    pub nanosec: u32,
}

impl Time {
    /// A stamp from microseconds since the Unix epoch (MECH's stamps).
    pub fn from_micros(us: u64) -> Time {
        let sec = us / 1_000_000;
        Time {
            sec: i32::try_from(sec).unwrap_or(i32::MAX),
            nanosec: ((us % 1_000_000) * 1_000) as u32,
        }
    }

    /// Microseconds since the Unix epoch; `None` before it.
    pub fn to_micros(self) -> Option<u64> {
        let sec = u64::try_from(self.sec).ok()?;
        Some(sec * 1_000_000 + u64::from(self.nanosec) / 1_000)
    }

    /// Whether the stamp is unset (zero), as many publishers leave it.
    pub fn is_zero(self) -> bool {
        self.sec == 0 && self.nanosec == 0
    }
}

/// `builtin_interfaces/Duration`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Duration {
    pub sec: i32,
    pub nanosec: u32,
}

#[cfg(test)]
mod tests {
    use super::Time;

    #[test]
    fn stamps_convert_from_and_to_microseconds() {
        let t = Time::from_micros(1_700_000_000_123_456);
        assert_eq!((t.sec, t.nanosec), (1_700_000_000, 123_456_000));
        assert_eq!(t.to_micros(), Some(1_700_000_000_123_456));
        assert_eq!(
            Time {
                sec: -1,
                nanosec: 0
            }
            .to_micros(),
            None
        );
        assert!(Time::default().is_zero());
    }
}
