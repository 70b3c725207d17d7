//! Who gets a place at the station, so that strangers who connect and say
//! nothing (or keep reconnecting) never keep operators out:
//!
//! - A client is *attaching* from the moment it connects until it is
//!   welcomed, within [`HANDSHAKE`]. Attaching clients have places of their
//!   own, apart from attached ones: [`TCP_ATTACHING`] over TCP (at most
//!   [`TCP_ATTACHING_PER_ADDRESS`] from one IP address) and
//!   [`UNIX_ATTACHING`] on the control socket. When they are taken, the new
//!   client takes the place of the one that has been attaching longest (of
//!   its own address, when that address holds its share), which is told so
//!   and closed. So idle connections cost a stranger a place each only
//!   until the next client comes, and an operator's handshake, which takes
//!   a round trip, gets through.
//! - A welcomed client holds a session place: [`TCP_SESSIONS`] over TCP (at
//!   most [`TCP_SESSIONS_PER_ADDRESS`] from one address) and
//!   [`UNIX_SESSIONS`] on the control socket, counted apart, so clients
//!   over TCP never take the places of the local socket's operators.
//!   Beyond them a client is told so and closed. The embedded TUI (in
//!   process) always gets in.
//! - Refused attaches reach the event log at most [`LOGGED_PER_SECOND`] a
//!   second; the rest are counted into one line a second.
//!
//! The Foxglove live view keeps an [`Admission`] of its own for its
//! connections' WebSocket handshakes: the same attaching places (within
//! its own 5 s for a handshake, not [`HANDSHAKE`]), and the same few log
//! lines a second; its clients' places are the live view's own
//! (`[foxglove] max_clients`), not the session places here.
//!
//! [`Admission`] owns the places; [`Attaching`] and [`Seat`] hold one each
//! and give it back when dropped.

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use mech_core::budget::PerSecond;
use mech_core::sync::lock;
use tokio::sync::Notify;
use tokio::time::Instant;

/// Time a client has to say Hello (and answer the challenge).
pub(crate) const HANDSHAKE: Duration = Duration::from_secs(10);

/// Clients attaching at once over TCP.
pub(crate) const TCP_ATTACHING: usize = 16;
/// Clients attaching at once over TCP from one IP address.
pub(crate) const TCP_ATTACHING_PER_ADDRESS: usize = 4;
/// Clients attaching at once on the control socket.
pub(crate) const UNIX_ATTACHING: usize = 16;
/// Clients attached at once over TCP.
pub(crate) const TCP_SESSIONS: usize = 64;
/// Clients attached at once over TCP from one IP address.
pub(crate) const TCP_SESSIONS_PER_ADDRESS: usize = 16;
/// Clients attached at once on the control socket.
pub(crate) const UNIX_SESSIONS: usize = 64;
/// Refused attaches logged one by one in a second.
pub(crate) const LOGGED_PER_SECOND: u32 = 5;

/// How a client came in, as far as places go.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Door {
    /// The embedded TUI: always let in.
    Local,
    /// The control socket.
    Unix,
    /// TCP, from this address.
    Tcp(IpAddr),
}

/// The station's places.
#[derive(Debug, Default)]
pub(crate) struct Admission {
    state: Mutex<State>,
}

#[derive(Debug, Default)]
struct State {
    next: u64,
    /// Clients attaching, oldest first.
    attaching: Vec<Pending>,
    unix_sessions: usize,
    tcp_sessions: usize,
    tcp_sessions_by_address: HashMap<IpAddr, usize>,
    refusals: PerSecond<LOGGED_PER_SECOND>,
}

#[derive(Debug)]
struct Pending {
    id: u64,
    door: Door,
    /// Tells the attaching client it lost its place.
    evicted: Arc<Notify>,
}

/// A place among the clients attaching; given back when dropped.
#[derive(Debug)]
pub(crate) struct Attaching {
    admission: Arc<Admission>,
    id: u64,
    door: Door,
    evicted: Arc<Notify>,
}

/// A place among the attached clients; given back when dropped.
#[derive(Debug)]
pub(crate) struct Seat {
    admission: Arc<Admission>,
    door: Door,
}

impl Admission {
    /// A place for a client attaching through `door`, made by closing the
    /// one attaching longest when they are taken.
    pub(crate) fn attaching(self: &Arc<Self>, door: Door) -> Attaching {
        let evicted = Arc::new(Notify::new());
        let mut s = lock(&self.state);
        s.next += 1;
        let id = s.next;
        if door != Door::Local {
            s.make_room(door);
            s.attaching.push(Pending {
                id,
                door,
                evicted: evicted.clone(),
            });
        }
        drop(s);
        Attaching {
            admission: self.clone(),
            id,
            door,
            evicted,
        }
    }

    /// Whether a refused attach at `now` goes to the event log on a line of
    /// its own (at most [`LOGGED_PER_SECOND`] a second; the others are
    /// counted for [`Admission::held_refusals`]).
    pub(crate) fn log_refusal(&self, now: Instant) -> bool {
        lock(&self.state).refusals.admit(now)
    }

    /// How many refused attaches were not logged one by one since the last
    /// call (the station logs them as one line every second).
    pub(crate) fn held_refusals(&self) -> u32 {
        lock(&self.state).refusals.take_held()
    }
}

impl State {
    fn attaching_through(&self, door: impl Fn(Door) -> bool) -> impl Iterator<Item = &Pending> {
        self.attaching.iter().filter(move |p| door(p.door))
    }

    /// Closes the client attaching longest through the same door (the same
    /// address, when that address holds its share) if the places are taken.
    fn make_room(&mut self, door: Door) {
        let (same_kind, share): (fn(Door) -> bool, usize) = match door {
            Door::Local => return,
            Door::Unix => (|d| d == Door::Unix, UNIX_ATTACHING),
            Door::Tcp(_) => (|d| matches!(d, Door::Tcp(_)), TCP_ATTACHING),
        };
        let victim = match door {
            Door::Tcp(ip)
                if self.attaching_through(|d| d == Door::Tcp(ip)).count()
                    >= TCP_ATTACHING_PER_ADDRESS =>
            {
                self.attaching_through(|d| d == Door::Tcp(ip)).next()
            }
            _ if self.attaching_through(same_kind).count() >= share => {
                self.attaching_through(same_kind).next()
            }
            _ => None,
        };
        let Some(id) = victim.map(|p| p.id) else {
            return;
        };
        if let Some(at) = self.attaching.iter().position(|p| p.id == id) {
            self.attaching.remove(at).evicted.notify_one();
        }
    }

    fn forget(&mut self, id: u64) {
        self.attaching.retain(|p| p.id != id);
    }
}

impl Attaching {
    /// Resolves when another client took this one's place.
    pub(crate) async fn evicted(&self) {
        self.evicted.notified().await;
    }

    /// Trades this place for a session place, or says why there is none.
    pub(crate) fn seat(self) -> Result<Seat, String> {
        let mut s = lock(&self.admission.state);
        s.forget(self.id);
        match self.door {
            Door::Local => {}
            Door::Unix => {
                if s.unix_sessions >= UNIX_SESSIONS {
                    return Err(format!(
                        "the station serves {UNIX_SESSIONS} clients on its control socket already"
                    ));
                }
                s.unix_sessions += 1;
            }
            Door::Tcp(ip) => {
                let from_ip = s.tcp_sessions_by_address.get(&ip).copied().unwrap_or(0);
                if s.tcp_sessions >= TCP_SESSIONS {
                    return Err(format!(
                        "the station serves {TCP_SESSIONS} clients over TCP already"
                    ));
                }
                if from_ip >= TCP_SESSIONS_PER_ADDRESS {
                    return Err(format!(
                        "the station serves {TCP_SESSIONS_PER_ADDRESS} clients from {ip} already"
                    ));
                }
                s.tcp_sessions += 1;
                *s.tcp_sessions_by_address.entry(ip).or_default() += 1;
            }
        }
        drop(s);
        Ok(Seat {
            admission: self.admission.clone(),
            door: self.door,
        })
    }
}

impl Drop for Attaching {
    fn drop(&mut self) {
        lock(&self.admission.state).forget(self.id);
    }
}

impl Drop for Seat {
    fn drop(&mut self) {
        let mut s = lock(&self.admission.state);
        match self.door {
            Door::Local => {}
            Door::Unix => s.unix_sessions = s.unix_sessions.saturating_sub(1),
            Door::Tcp(ip) => {
                s.tcp_sessions = s.tcp_sessions.saturating_sub(1);
                if let Some(n) = s.tcp_sessions_by_address.get_mut(&ip) {
                    *n = n.saturating_sub(1);
                    if *n == 0 {
                        s.tcp_sessions_by_address.remove(&ip);
                    }
                }
            }
        }
    }
}

/// Once a second, `say` how many lines about clients `admission` held
/// back ([`Admission::log_refusal`]), when it held any.
pub(crate) async fn say_held(admission: Arc<Admission>, say: impl Fn(u32)) {
    let mut every = tokio::time::interval(Duration::from_secs(1));
    every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
    loop {
        every.tick().await;
        let n = admission.held_refusals();
        if n > 0 {
            say(n);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tcp(ip: [u8; 4]) -> Door {
        Door::Tcp(ip.into())
    }

    fn unix() -> Door {
        Door::Unix
    }

    #[tokio::test]
    async fn a_new_client_takes_the_place_of_the_one_attaching_longest() {
        let a = Arc::new(Admission::default());
        // An address's share: its fifth closes its first.
        let first = a.attaching(tcp([10, 0, 0, 1]));
        let _more: Vec<_> = (2..=4).map(|_| a.attaching(tcp([10, 0, 0, 1]))).collect();
        let _fifth = a.attaching(tcp([10, 0, 0, 1]));
        tokio::time::timeout(Duration::from_secs(1), first.evicted())
            .await
            .expect("evicted");
        // TCP's places: 16 from four addresses; the 17th closes the oldest.
        let a = Arc::new(Admission::default());
        let held: Vec<_> = (0..16u8)
            .map(|i| a.attaching(tcp([10, 0, 0, i / 4])))
            .collect();
        let _newcomer = a.attaching(tcp([10, 0, 0, 9]));
        tokio::time::timeout(Duration::from_secs(1), held[0].evicted())
            .await
            .expect("evicted");
        // The control socket's places are its own.
        let local = a.attaching(unix());
        let _many: Vec<_> = (0..20u8).map(|i| a.attaching(tcp([10, 0, 1, i]))).collect();
        assert!(
            tokio::time::timeout(Duration::from_millis(50), local.evicted())
                .await
                .is_err()
        );
        local.seat().expect("seated");
    }

    #[test]
    fn sessions_over_tcp_never_take_the_control_sockets_places() {
        let a = Arc::new(Admission::default());
        let mut seats = Vec::new();
        for i in 0..TCP_SESSIONS {
            let ip = [10, 0, (i / TCP_SESSIONS_PER_ADDRESS) as u8, 1];
            if i == TCP_SESSIONS_PER_ADDRESS {
                let e = a.attaching(tcp([10, 0, 0, 1])).seat().unwrap_err();
                assert!(e.contains("from 10.0.0.1"), "{e}");
            }
            seats.push(a.attaching(tcp(ip)).seat().expect("seated"));
        }
        let e = a.attaching(tcp([10, 9, 9, 9])).seat().unwrap_err();
        assert!(e.contains("over TCP"), "{e}");
        let local: Vec<_> = (0..UNIX_SESSIONS)
            .map(|_| a.attaching(unix()).seat().expect("seated"))
            .collect();
        assert!(a.attaching(unix()).seat().is_err());
        drop(local);
        drop(seats.pop());
        a.attaching(tcp([10, 9, 9, 9]))
            .seat()
            .expect("a place freed");
        a.attaching(Door::Local).seat().expect("in process: always");
    }

    #[test]
    fn refused_attaches_are_logged_five_a_second_and_the_rest_counted() {
        let a = Admission::default();
        let t0 = Instant::now();
        let logged = (0..100).filter(|_| a.log_refusal(t0)).count();
        assert_eq!(logged, LOGGED_PER_SECOND as usize);
        assert!(!a.log_refusal(t0 + Duration::from_millis(999)));
        assert_eq!(a.held_refusals(), 101 - LOGGED_PER_SECOND);
        assert_eq!(a.held_refusals(), 0);
        assert!(a.log_refusal(t0 + Duration::from_secs(1)), "a new second");
    }
}
