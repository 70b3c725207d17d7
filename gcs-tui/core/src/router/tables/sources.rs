//! Where UDP datagrams come from, so that under a flood the router serves
//! real robots and controllers first and bounds the work it spends on
//! strangers:
//!
//! - **known peers**: addresses that sent a message the router took (one
//!   signed by a listed key, when the station authenticates) within
//!   [`KNOWN_FOR`]. In every batch a worker received, their datagrams are
//!   decided first, then the others, each sender's in the order they
//!   arrived ([`Sources::order`]);
//! - **failure budgets**: the messages from each IP address refused in the
//!   current second. While a worker is behind (its receive call came back
//!   full, so more wait in the socket), datagrams from an address over
//!   [`FAILURE_BUDGET`] that is not a known peer are shed: counted and
//!   reported, never decoded or checked. A flood from one address then
//!   costs the router next to nothing while it lasts, and what was waiting
//!   behind it is reached sooner. A robot that has not registered yet and
//!   shares its address with the flood (or whose address the flood spoofs)
//!   is shed with it only while the router is behind.
//!
//! Both memories are bounded: beyond their size, what is out of date is
//! forgotten first, then everything.

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};
use std::time::Duration;

use tokio::time::Instant;

/// How long an address stays a known peer after the last message the
/// router took from it.
pub(super) const KNOWN_FOR: Duration = Duration::from_secs(10);

/// Refused messages an IP address may send in a second before its
/// datagrams may be shed.
pub(super) const FAILURE_BUDGET: u32 = 64;

/// Addresses remembered in each memory.
const REMEMBERED: usize = 65_536;

/// How often a known peer's time is renewed (not on every message: the
/// hot path pays one lookup).
const RENEW_EVERY: Duration = Duration::from_secs(1);

/// What a batch's datagram gets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Treatment {
    Decide,
    Shed,
}

/// Known peers and failure budgets.
#[derive(Debug, Default)]
pub(super) struct Sources {
    /// When the router last took a message from each known address.
    known: HashMap<SocketAddr, Instant>,
    /// Refusals per IP address in its current second.
    failures: HashMap<IpAddr, Window>,
    /// The order the current batch is decided in, and which of its
    /// datagrams come from known peers: kept between batches.
    order: Vec<(usize, Treatment)>,
    known_in_batch: Vec<bool>,
}

#[derive(Debug, Clone, Copy)]
struct Window {
    started: Instant,
    refused: u32,
}

impl Sources {
    /// The router took a message from `addr` at `now`.
    pub(super) fn vouch(&mut self, addr: SocketAddr, now: Instant) {
        if let Some(t) = self.known.get_mut(&addr) {
            if now.saturating_duration_since(*t) >= RENEW_EVERY {
                *t = now;
            }
            return;
        }
        if self.known.len() >= REMEMBERED {
            self.known
                .retain(|_, t| now.saturating_duration_since(*t) < KNOWN_FOR);
            if self.known.len() >= REMEMBERED {
                self.known.clear();
            }
        }
        self.known.insert(addr, now);
    }

    /// Whether `addr` is a known peer at `now`.
    pub(super) fn known(&self, addr: SocketAddr, now: Instant) -> bool {
        self.known
            .get(&addr)
            .is_some_and(|t| now.saturating_duration_since(*t) < KNOWN_FOR + RENEW_EVERY)
    }

    /// A message from `ip` was refused at `now`.
    pub(super) fn refused(&mut self, ip: IpAddr, now: Instant) {
        let fresh = Window {
            started: now,
            refused: 0,
        };
        if !self.failures.contains_key(&ip) && self.failures.len() >= REMEMBERED {
            let second = Duration::from_secs(1);
            self.failures
                .retain(|_, w| now.saturating_duration_since(w.started) < second);
            if self.failures.len() >= REMEMBERED {
                self.failures.clear();
            }
        }
        let w = self.failures.entry(ip).or_insert(fresh);
        if now.saturating_duration_since(w.started) >= Duration::from_secs(1) {
            *w = fresh;
        }
        w.refused = w.refused.saturating_add(1);
    }

    /// Whether `ip` has spent its failure budget in its current second.
    pub(super) fn failing(&self, ip: IpAddr, now: Instant) -> Option<u32> {
        let w = self.failures.get(&ip)?;
        let current = now.saturating_duration_since(w.started) < Duration::from_secs(1);
        (current && w.refused >= FAILURE_BUDGET).then_some(w.refused)
    }

    /// Orders a batch of `n` datagrams whose sources `from(i)` gives:
    /// known peers' first, then the others, each group in arrival order;
    /// with `behind`, the others from failing addresses are shed. Read
    /// the order with [`Sources::ordered`].
    pub(super) fn order(
        &mut self,
        n: usize,
        from: impl Fn(usize) -> Option<SocketAddr>,
        behind: bool,
        now: Instant,
    ) {
        let mut order = std::mem::take(&mut self.order);
        let mut known = std::mem::take(&mut self.known_in_batch);
        order.clear();
        known.clear();
        if n == 1 {
            order.push((0, Treatment::Decide));
        } else {
            known.extend((0..n).map(|i| from(i).is_some_and(|a| self.known(a, now))));
            order.extend((0..n).filter(|&i| known[i]).map(|i| (i, Treatment::Decide)));
            order.extend((0..n).filter(|&i| !known[i]).map(|i| {
                let shed = behind && from(i).is_some_and(|a| self.failing(a.ip(), now).is_some());
                (
                    i,
                    if shed {
                        Treatment::Shed
                    } else {
                        Treatment::Decide
                    },
                )
            }));
        }
        self.order = order;
        self.known_in_batch = known;
    }

    /// The `k`-th datagram to decide in the batch last ordered, and what
    /// it gets.
    pub(super) fn ordered(&self, k: usize) -> (usize, Treatment) {
        self.order[k]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn addr(ip: u8, port: u16) -> SocketAddr {
        ([10, 0, 0, ip], port).into()
    }

    #[test]
    fn known_peers_come_first_and_each_sender_keeps_its_order() {
        let now = Instant::now();
        let mut s = Sources::default();
        s.vouch(addr(1, 7000), now);
        let from = [
            addr(9, 1),
            addr(1, 7000),
            addr(9, 2),
            addr(9, 1),
            addr(1, 7000),
        ];
        s.order(from.len(), |i| Some(from[i]), false, now);
        let order: Vec<usize> = (0..from.len()).map(|k| s.ordered(k).0).collect();
        assert_eq!(order, [1, 4, 0, 2, 3]);
        // Out of date after KNOWN_FOR (and its renewal period).
        let later = now + KNOWN_FOR + RENEW_EVERY;
        s.order(from.len(), |i| Some(from[i]), false, later);
        let order: Vec<usize> = (0..from.len()).map(|k| s.ordered(k).0).collect();
        assert_eq!(order, [0, 1, 2, 3, 4]);
    }

    #[test]
    fn a_failing_address_is_shed_only_while_behind_and_never_a_known_peer() {
        let now = Instant::now();
        let mut s = Sources::default();
        let flooder = addr(9, 1);
        s.vouch(addr(9, 5000), now);
        for _ in 0..FAILURE_BUDGET {
            s.refused(flooder.ip(), now);
        }
        let from = [flooder, addr(9, 2), addr(9, 5000), addr(8, 1)];
        let shed = |s: &Sources| -> Vec<usize> {
            (0..from.len())
                .map(|k| s.ordered(k))
                .filter(|(_, t)| *t == Treatment::Shed)
                .map(|(i, _)| i)
                .collect()
        };
        s.order(from.len(), |i| Some(from[i]), false, now);
        assert!(shed(&s).is_empty(), "not behind: everything is decided");
        s.order(from.len(), |i| Some(from[i]), true, now);
        assert_eq!(shed(&s), [0, 1], "the failing address, not its known peer");
        // A new second: a fresh budget.
        let next = now + Duration::from_secs(1);
        s.order(from.len(), |i| Some(from[i]), true, next);
        assert!(shed(&s).is_empty());
    }

    #[test]
    fn memory_is_bounded() {
        let now = Instant::now();
        let mut s = Sources::default();
        for i in 0..(REMEMBERED as u32 + 10) {
            let a = SocketAddr::from((std::net::Ipv4Addr::from(i), 1));
            s.vouch(a, now);
            s.refused(a.ip(), now);
        }
        assert!(s.known.len() <= REMEMBERED && s.failures.len() <= REMEMBERED);
    }
}
