//! Which signed time requests the router answers. A robot without a clock
//! asks for station time with a random nonce before it registers; its
//! request cannot be judged by its stamp (the robot does not know the time
//! yet), so a copy captured earlier verifies like the real one. These
//! rules keep copies from taking a robot's turn:
//!
//! - a nonce is answered once: a request whose nonce was answered before
//!   (the last [`NONCES_PER_KEY`] of its key are remembered) is refused
//!   before it uses any budget;
//! - a request stamped later than every request answered on its stream
//!   (key and link) has never been answered: it is answered at once. A
//!   robot's stamps rise for as long as its agent runs, so its newest
//!   request always is such a one, and copies of its earlier requests
//!   never stand in its way;
//! - any other request (a copy, or the first request of a robot that
//!   restarted with its clock set back) is answered at most once per
//!   [`ANSWER_GAP`] per key and source address: copies from elsewhere
//!   cannot use the budget of the robot's own address.
//!
//! Requests whose stamp is near the station's clock are also checked for
//! freshness like every other message, before they get here (see
//! `super::super::Tables::admit`). All memory here is bounded; a station
//! that restarts starts it empty (`docs/security.md` says what then holds).

use std::collections::{HashMap, VecDeque};
use std::time::Duration;

use tokio::time::Instant;

use crate::router::tables::Peer;

/// The shortest time between two answers to one key's requests from one
/// source that are not newer than every answered one.
pub(super) const ANSWER_GAP: Duration = Duration::from_millis(100);

/// Nonces remembered per key (a robot asks four times a second, and only
/// while it does not know station time).
pub(super) const NONCES_PER_KEY: usize = 256;

/// Sources remembered for [`ANSWER_GAP`]; beyond it, those answered longer
/// ago are forgotten first.
const SOURCES: usize = 4096;

/// What to do with a verified time request.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Verdict {
    Answer,
    /// Its nonce was answered before: a copy.
    Repeated,
    /// Not newer than an answered request, and its source was answered
    /// within [`ANSWER_GAP`].
    TooSoon,
}

/// The memory behind the verdicts.
#[derive(Debug, Default)]
pub(super) struct TimeAnswers {
    /// Nonces answered, per key, oldest first.
    nonces: HashMap<u32, VecDeque<u64>>,
    /// The newest stamp answered per key and link.
    newest: HashMap<(u32, u8), u64>,
    /// When each key last answered each source a request that was not the
    /// newest.
    answered_at: HashMap<(u32, Peer), Instant>,
}

/// A verified time request, as judged here.
#[derive(Debug, Clone, Copy)]
pub(super) struct Request {
    pub(super) key_id: u32,
    pub(super) link: u8,
    pub(super) stamp_us: u64,
    pub(super) nonce: u64,
    pub(super) from: Peer,
}

impl TimeAnswers {
    /// Judges `r` at `now`; an answer is remembered as given.
    pub(super) fn judge(&mut self, r: Request, now: Instant) -> Verdict {
        let nonces = self.nonces.entry(r.key_id).or_default();
        if nonces.contains(&r.nonce) {
            return Verdict::Repeated;
        }
        let newest = self.newest.entry((r.key_id, r.link)).or_insert(0);
        let newer = r.stamp_us > *newest;
        if !newer {
            let source = (r.key_id, r.from);
            let recent = self
                .answered_at
                .get(&source)
                .is_some_and(|t| now.saturating_duration_since(*t) < ANSWER_GAP);
            if recent {
                return Verdict::TooSoon;
            }
            if self.answered_at.len() >= SOURCES {
                self.answered_at
                    .retain(|_, t| now.saturating_duration_since(*t) < ANSWER_GAP);
                if self.answered_at.len() >= SOURCES {
                    // All recent: a flood of copies from as many addresses.
                    // Forgetting them only lets each source one more answer.
                    self.answered_at.clear();
                }
            }
            self.answered_at.insert(source, now);
        }
        *newest = (*newest).max(r.stamp_us);
        if nonces.len() >= NONCES_PER_KEY {
            nonces.pop_front();
        }
        nonces.push_back(r.nonce);
        Verdict::Answer
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn peer(port: u16) -> Peer {
        Peer::Udp(([127, 0, 0, 1], port).into())
    }

    fn request(stamp_us: u64, nonce: u64, port: u16) -> Request {
        Request {
            key_id: 7,
            link: 0,
            stamp_us,
            nonce,
            from: peer(port),
        }
    }

    #[test]
    fn a_nonce_is_answered_once() {
        let (mut t, now) = (TimeAnswers::default(), Instant::now());
        assert_eq!(t.judge(request(10, 1, 9000), now), Verdict::Answer);
        let later = now + Duration::from_secs(60);
        assert_eq!(t.judge(request(10, 1, 9000), later), Verdict::Repeated);
        assert_eq!(t.judge(request(10, 1, 9001), later), Verdict::Repeated);
    }

    /// Copies of earlier requests, sent every 10 ms from another address or
    /// from the robot's own: the robot's new requests (rising stamps, new
    /// nonces, every 250 ms) are each answered at once.
    #[test]
    fn copies_never_take_the_turn_of_a_newer_request() {
        let (mut t, t0) = (TimeAnswers::default(), Instant::now());
        let ms = |v: u64| t0 + Duration::from_millis(v);
        // Captured earlier in this run (so answered) or before it (not).
        let old: Vec<Request> = (0..40).map(|i| request(100 + i, 1000 + i, 9000)).collect();
        let mut robot_stamp = 1_000_000;
        for step in 0..300u64 {
            let mut copy = old[step as usize % old.len()];
            copy.from = if step % 2 == 0 {
                peer(9000)
            } else {
                peer(6666)
            };
            let _ = t.judge(copy, ms(step * 10));
            if step % 25 == 0 {
                robot_stamp += 250_000;
                let mine = request(robot_stamp, step, 9000);
                assert_eq!(t.judge(mine, ms(step * 10 + 1)), Verdict::Answer, "{step}");
            }
        }
    }

    /// A robot whose clock went back (it restarted without one) competes
    /// with copies only from its own address: copies from another address
    /// use that address's budget.
    #[test]
    fn a_request_that_is_not_the_newest_is_limited_per_key_and_source() {
        let (mut t, t0) = (TimeAnswers::default(), Instant::now());
        let ms = |v: u64| t0 + Duration::from_millis(v);
        assert_eq!(t.judge(request(5_000, 1, 9000), t0), Verdict::Answer);
        // A copy from elsewhere, then the restarted robot (stamp 50).
        assert_eq!(t.judge(request(40, 2, 6666), ms(1)), Verdict::Answer);
        assert_eq!(t.judge(request(50, 3, 9000), ms(2)), Verdict::Answer);
        assert_eq!(t.judge(request(60, 4, 9000), ms(50)), Verdict::TooSoon);
        assert_eq!(t.judge(request(60, 4, 9000), ms(102)), Verdict::Answer);
    }

    #[test]
    fn memory_is_bounded() {
        let (mut t, now) = (TimeAnswers::default(), Instant::now());
        for i in 0..10_000u64 {
            let mut r = request(10_000 - i, i, (i % 60_000) as u16);
            r.from = peer((i % 60_000) as u16);
            let _ = t.judge(r, now + Duration::from_millis(i * 200));
        }
        assert!(t.nonces[&7].len() <= NONCES_PER_KEY);
        assert!(t.answered_at.len() <= SOURCES);
    }
}
