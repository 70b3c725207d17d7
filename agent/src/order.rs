//! Stale messages are never obeyed. UDP may reorder datagrams, a radio may
//! deliver a frame late, and a controller's "drive" sent before its "stop"
//! must not win because it arrived after it.
//!
//! A command is stale when it is older than the newest command already
//! obeyed from the same sender on the same channel: its sequence number is
//! behind (compared as wrapping 32-bit counters) *and* its header stamp is
//! not newer. A sender that restarts numbers from zero again, but its clock
//! has moved on, so its first command is newer by stamp and is obeyed (and
//! numbering starts afresh). A sender without a clock (stamp 0) is taken to
//! have restarted once it has been silent on the channel for the failsafe's
//! channel timeout. The memory is cleared when the route changes and when
//! the robot registers.
//!
//! Routes, missions and e-stops carry their own order (the route's epoch,
//! the mission's id, the e-stop's id); [`is_older`] compares them.

use std::collections::HashMap;
use std::time::Duration;

/// Most senders remembered on one channel; beyond it the one heard from
/// longest ago is forgotten (a flood of invented sender names cannot grow
/// the robot's memory).
const MAX_SENDERS: usize = 64;

/// Whether wrapping counter `a` is behind `b`.
pub fn is_older(a: u32, b: u32) -> bool {
    (a.wrapping_sub(b) as i32) < 0
}

#[derive(Debug, Clone, Copy)]
struct Newest {
    seq: u32,
    stamp_us: u64,
    at: Duration,
}

/// The newest command obeyed from each sender on each channel.
#[derive(Debug, Default)]
pub struct CommandOrder {
    newest: HashMap<(String, String), Newest>,
}

impl CommandOrder {
    /// Whether a command (`seq`, `stamp_us`) from `sender` on `channel`,
    /// received at `now`, may be obeyed; if so it becomes the newest.
    /// `restart_after` is how long a clockless sender must have been silent
    /// to count as restarted.
    pub fn admit(
        &mut self,
        sender: &str,
        channel: &str,
        seq: u32,
        stamp_us: u64,
        now: Duration,
        restart_after: Duration,
    ) -> bool {
        let key = (sender.to_string(), channel.to_string());
        let fresh = match self.newest.get(&key) {
            None => true,
            Some(last) => {
                let newer = (seq.wrapping_sub(last.seq) as i32) > 0;
                let restarted_clock = stamp_us > last.stamp_us;
                let restarted_silent = stamp_us == 0
                    && last.stamp_us == 0
                    && now.saturating_sub(last.at) >= restart_after;
                newer || restarted_clock || restarted_silent
            }
        };
        if fresh {
            if self.newest.len() >= MAX_SENDERS && !self.newest.contains_key(&key) {
                self.forget_oldest();
            }
            self.newest.insert(
                key,
                Newest {
                    seq,
                    stamp_us,
                    at: now,
                },
            );
        }
        fresh
    }

    /// Forgets every sender (the route changed, or the robot registered).
    pub fn clear(&mut self) {
        self.newest.clear();
    }

    fn forget_oldest(&mut self) {
        if let Some(key) = self
            .newest
            .iter()
            .min_by_key(|(_, n)| n.at)
            .map(|(k, _)| k.clone())
        {
            self.newest.remove(&key);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: Duration = Duration::from_millis(500);

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    #[test]
    fn an_older_command_from_the_same_sender_and_channel_is_stale() {
        let mut o = CommandOrder::default();
        assert!(o.admit("pad", "joy/0", 10, 1_000, ms(0), T));
        assert!(!o.admit("pad", "joy/0", 9, 990, ms(1), T), "overtaken");
        assert!(!o.admit("pad", "joy/0", 10, 1_000, ms(1), T), "duplicate");
        assert!(o.admit("pad", "joy/0", 11, 1_010, ms(2), T));
        // Other senders and channels have their own order.
        assert!(o.admit("matlab", "joy/0", 3, 5, ms(2), T));
        assert!(o.admit("pad", "joy/1", 1, 1, ms(2), T));
    }

    #[test]
    fn sequence_numbers_wrap() {
        let mut o = CommandOrder::default();
        assert!(o.admit("pad", "joy/0", u32::MAX - 1, 1, ms(0), T));
        assert!(o.admit("pad", "joy/0", 2, 2, ms(1), T), "past the wrap");
        assert!(!o.admit("pad", "joy/0", u32::MAX, 1, ms(2), T), "behind");
        assert!(is_older(u32::MAX, 2) && !is_older(2, u32::MAX));
    }

    #[test]
    fn a_restarted_sender_is_recognised_by_its_clock_or_its_silence() {
        let mut o = CommandOrder::default();
        assert!(o.admit("pad", "joy/0", 5_000, 10_000_000, ms(0), T));
        assert!(
            o.admit("pad", "joy/0", 1, 12_000_000, ms(10), T),
            "clock moved on"
        );
        assert!(o.admit("pad", "joy/0", 2, 12_000_100, ms(20), T));
        // Without a clock: only after the channel timeout of silence.
        assert!(o.admit("tiny", "joy/0", 900, 0, ms(0), T));
        assert!(!o.admit("tiny", "joy/0", 1, 0, ms(100), T));
        assert!(o.admit("tiny", "joy/0", 1, 0, ms(700), T));
    }

    #[test]
    fn memory_is_bounded_and_cleared() {
        let mut o = CommandOrder::default();
        for i in 0..1_000u64 {
            assert!(o.admit(&format!("s{i}"), "joy/0", 1, i, ms(i), T));
        }
        assert!(o.newest.len() <= MAX_SENDERS);
        o.admit("pad", "joy/0", 10, 10, ms(2_000), T);
        o.clear();
        assert!(
            o.admit("pad", "joy/0", 1, 1, ms(2_001), T),
            "a new route starts afresh"
        );
    }
}
