//! The robot's side of the authenticated control plane: it signs what it
//! sends with its key and obeys only messages the router signed for it.
//!
//! A robot often has no real-time clock (a Pi booted without network
//! time), yet signed messages carry station time. So after boot, and again
//! whenever the router is lost, the agent asks the router for the time
//! (`TimeRequest` with a fresh random nonce) before it registers. The
//! router's `Time` answer is signed with the robot's key and echoes the
//! nonce, so it cannot be a replay; it gives the offset from the robot's
//! clock to station time and starts the router's stream. From then on every
//! router message must be newer than the last one accepted.
//!
//! The agent asks again while no answer comes (every `hello_retry`), and an
//! answer may come after the next request has gone out (a slow link): an
//! answer to any of its last [`ASKED`] requests is taken. The stamps of its
//! requests rise for as long as the agent runs (and are station time once
//! it has synced before), which is what lets the router tell its newest
//! request from copies of earlier ones.

use std::collections::VecDeque;

use mech_proto::Body;
use mech_proto::auth::{AuthError, Key, Refused, Signer, Verifier};

/// Time requests whose answer is still taken: the last 16, four seconds of
/// requests at the agent's default `hello_retry` of 0.25 s.
pub const ASKED: usize = 16;

/// Signing and checking for one robot.
#[derive(Debug)]
pub struct RobotAuth {
    signer: Signer,
    /// The router's messages: one stream of them all, started only by a
    /// `Time` answer (the robot may have no clock to judge a first stamp
    /// by).
    from_router: Verifier<()>,
    /// The router's sender name (its messages must say so).
    router: String,
    /// Nonces of the time requests waiting for an answer, newest last.
    asked: VecDeque<u64>,
    /// Messages refused, by reason.
    pub rejected: RobotRejections,
}

/// Messages the robot refused, by reason (shown in its log and counters).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RobotRejections {
    /// Not signed, or signed with another key.
    pub bad_tag: u64,
    /// Not newer than the router's last message, or before the robot knew
    /// station time.
    pub replay: u64,
    /// Signed with this robot's key, but not by the router: one of the
    /// robot's own messages sent back to it (a reflection).
    pub not_router: u64,
}

impl RobotRejections {
    pub fn total(&self) -> u64 {
        self.bad_tag + self.replay + self.not_router
    }
}

/// What checking a received message decided.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Checked {
    /// Authentic and fresh: obey it.
    Accept,
    /// The router's answer to our time request: station time is known now
    /// (the caller should register at once).
    Synced,
    /// Refused (counted).
    Reject,
}

impl RobotAuth {
    pub fn new(key: Key, router: &str) -> RobotAuth {
        RobotAuth {
            signer: Signer::new(Some(key.clone())),
            from_router: Verifier::new(key, None),
            router: router.to_string(),
            asked: VecDeque::with_capacity(ASKED),
            rejected: RobotRejections::default(),
        }
    }

    /// Whether station time is known (a `Time` answer was accepted since
    /// the last [`RobotAuth::forget_router`]).
    pub fn synced(&self) -> bool {
        self.from_router.started()
    }

    /// A new time request: its nonce is random and remembered (with the
    /// last [`ASKED`] before it).
    pub fn time_request(&mut self) -> mech_proto::TimeRequest {
        let nonce = rand::random::<u64>();
        if self.asked.len() >= ASKED {
            self.asked.pop_front();
        }
        self.asked.push_back(nonce);
        mech_proto::TimeRequest { nonce }
    }

    /// The router was lost (it may have restarted, or someone is replaying
    /// its traffic): ask the time again before trusting it.
    pub fn forget_router(&mut self) {
        self.from_router.forget();
        self.asked.clear();
    }

    /// Signs an encoded message (nil `auth` element) with station time
    /// `local_us` + offset, as sent on the robot's link number `link`.
    pub fn seal(&mut self, bytes: &mut Vec<u8>, local_us: u64, link: u8) -> Result<(), AuthError> {
        self.signer.seal(bytes, link, local_us)
    }

    /// Checks a received message whose decoded form is `sender` + `body`,
    /// when the robot's clock reads `local_us`. The sender may be a
    /// controller whose command the router forwards; what matters is that
    /// the router signed it for this robot. The router's own messages (the
    /// time answer among them) name the router as sender.
    pub fn check(&mut self, bytes: &[u8], sender: &str, body: &Body, local_us: u64) -> Checked {
        let tag = match self.from_router.verify(bytes) {
            Ok(tag) => tag,
            Err(Refused::NotFromRouter) => {
                self.rejected.not_router += 1;
                return Checked::Reject;
            }
            Err(Refused::Auth(_)) => {
                self.rejected.bad_tag += 1;
                return Checked::Reject;
            }
        };
        if let Body::Time(t) = body {
            if sender == self.router && !self.synced() && self.asked.contains(&t.nonce) {
                self.asked.clear();
                self.signer.sync(t.station_us, local_us);
                self.from_router.start((), tag.stamp_us);
                return Checked::Synced;
            }
            self.rejected.replay += 1;
            return Checked::Reject;
        }
        match self.from_router.accept((), tag.stamp_us, local_us) {
            Ok(()) => Checked::Accept,
            Err(_) => {
                self.rejected.replay += 1;
                Checked::Reject
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_proto::auth::{FROM_ROUTER, split};
    use mech_proto::{Envelope, Header, Time};

    fn router_msg(key: &Key, body: Body, stamp: u64) -> (Vec<u8>, Body) {
        let env = Envelope::new(
            Header {
                sender: "router".into(),
                destination: "robot_1".into(),
                ..Header::default()
            },
            body.clone(),
        );
        let mut b = mech_proto::encode(&env).unwrap();
        key.seal(&mut b, FROM_ROUTER, stamp).unwrap();
        (b, body)
    }

    #[test]
    fn a_robot_booted_in_1970_syncs_then_takes_only_newer_router_messages() {
        let key = Key::new(&[4; 32]);
        let mut auth = RobotAuth::new(key.clone(), "router");
        let hb = Body::Heartbeat(mech_proto::Heartbeat::new(1));
        let (b, body) = router_msg(&key, hb.clone(), 10);
        assert_eq!(
            auth.check(&b, "router", &body, 5),
            Checked::Reject,
            "not synced"
        );
        let req = auth.time_request();
        // A replayed old answer (another nonce) is refused.
        let old = Body::Time(Time {
            nonce: req.nonce ^ 1,
            station_us: 7,
        });
        let (b, body) = router_msg(&key, old, 50);
        assert_eq!(auth.check(&b, "router", &body, 5), Checked::Reject);
        let answer = Body::Time(Time {
            nonce: req.nonce,
            station_us: 1_700_000_000_000_000,
        });
        let (b, body) = router_msg(&key, answer, 1_700_000_000_000_000);
        assert_eq!(auth.check(&b, "router", &body, 100), Checked::Synced);
        // Our stamps are station time now.
        let mut mine = mech_proto::encode(&Envelope::new(Header::default(), hb.clone())).unwrap();
        auth.seal(&mut mine, 150, 0).unwrap();
        let (_, tag) = split(&mine).unwrap();
        assert_eq!(tag.unwrap().stamp_us, 1_700_000_000_000_050);
        let (b, body) = router_msg(&key, hb.clone(), 1_700_000_000_000_001);
        assert_eq!(auth.check(&b, "router", &body, 200), Checked::Accept);
        assert_eq!(
            auth.check(&b, "router", &body, 200),
            Checked::Reject,
            "replay"
        );
        let (b, body) = router_msg(&Key::new(&[5; 32]), hb.clone(), 1_700_000_000_000_009);
        assert_eq!(
            auth.check(&b, "router", &body, 200),
            Checked::Reject,
            "wrong key"
        );
        let (b, body) = router_msg(&key, hb.clone(), 1_700_000_000_000_010);
        assert_eq!(
            auth.check(&b, "matlab", &body, 200),
            Checked::Accept,
            "a controller's command the router forwarded"
        );
        // The robot's own message, sent back to it.
        let mut mine = mech_proto::encode(&Envelope::new(Header::default(), hb.clone())).unwrap();
        auth.seal(&mut mine, 300, 0).unwrap();
        assert_eq!(
            auth.check(&mine, "router", &hb, 300),
            Checked::Reject,
            "reflected"
        );
        assert_eq!(
            auth.rejected,
            RobotRejections {
                bad_tag: 1,
                replay: 3,
                not_router: 1
            }
        );
    }

    /// On a link slower than the agent's retry period, the answer to a
    /// request comes after the next request went out: it is taken. One to
    /// a request older than the last [`ASKED`] is not.
    #[test]
    fn an_answer_to_an_earlier_request_syncs_a_robot_on_a_slow_link() {
        let key = Key::new(&[4; 32]);
        let mut auth = RobotAuth::new(key.clone(), "router");
        let first = auth.time_request();
        for _ in 1..ASKED {
            auth.time_request();
        }
        let answer = |nonce, stamp| {
            let t = Body::Time(Time {
                nonce,
                station_us: 1_700_000_000_000_000,
            });
            router_msg(&key, t, stamp)
        };
        let (b, body) = answer(first.nonce, 1_700_000_000_000_000);
        assert_eq!(auth.check(&b, "router", &body, 100), Checked::Synced);
        let mut auth = RobotAuth::new(key.clone(), "router");
        let first = auth.time_request();
        for _ in 0..ASKED {
            auth.time_request();
        }
        let (b, body) = answer(first.nonce, 1_700_000_000_000_000);
        assert_eq!(auth.check(&b, "router", &body, 100), Checked::Reject);
        assert!(!auth.synced());
    }
}
