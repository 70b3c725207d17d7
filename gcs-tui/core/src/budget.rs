//! A budget per second, for what a flood must not multiply (log lines,
//! whole records of refused messages): the first `LIMIT` of each second
//! pass, the rest are held back and counted until taken.

use std::time::Duration;

use tokio::time::Instant;

/// At most `LIMIT` a second. A second begins with the first one asked for
/// at least a second after the current one began.
#[derive(Debug, Clone, Copy, Default)]
pub struct PerSecond<const LIMIT: u32> {
    /// When the current second began, and how many passed in it.
    second: Option<(Instant, u32)>,
    /// Held back since [`PerSecond::take_held`] last took them.
    held: u32,
}

impl<const LIMIT: u32> PerSecond<LIMIT> {
    /// Whether one more at `now` passes; if not, it is held back (counted).
    pub fn admit(&mut self, now: Instant) -> bool {
        let (began, passed) = self.current(now);
        if passed >= LIMIT {
            self.second = Some((began, passed));
            self.held = self.held.saturating_add(1);
            return false;
        }
        self.second = Some((began, passed + 1));
        true
    }

    /// Whether the second `now` falls in has no more to give (nothing is
    /// counted).
    pub fn spent(&self, now: Instant) -> bool {
        self.current(now).1 >= LIMIT
    }

    /// How many were held back since the last call.
    pub fn take_held(&mut self) -> u32 {
        std::mem::take(&mut self.held)
    }

    fn current(&self, now: Instant) -> (Instant, u32) {
        self.second
            .filter(|(began, _)| now.saturating_duration_since(*began) < Duration::from_secs(1))
            .unwrap_or((now, 0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_of_each_second_pass_and_the_rest_are_counted() {
        let mut b = PerSecond::<5>::default();
        let t0 = Instant::now();
        assert!(!b.spent(t0));
        let passed = (0..100).filter(|_| b.admit(t0)).count();
        assert_eq!(passed, 5);
        assert!(b.spent(t0 + Duration::from_millis(999)));
        assert!(!b.admit(t0 + Duration::from_millis(999)));
        assert_eq!(b.take_held(), 96);
        assert_eq!(b.take_held(), 0);
        // A new second: a fresh budget, from the first asked for.
        let t1 = t0 + Duration::from_secs(1);
        assert!(!b.spent(t1));
        assert!(b.admit(t1));
        assert!((0..4).all(|_| b.admit(t1 + Duration::from_millis(500))));
        assert!(!b.admit(t1 + Duration::from_millis(999)));
        assert!(b.admit(t1 + Duration::from_secs(1)));
    }
}
