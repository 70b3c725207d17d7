//! Messages to and from the station, sealed and opened as any controller
//! does it (`docs/protocol.md`, *Signing*): outgoing ones numbered,
//! stamped with station time and, with a key, signed; incoming ones
//! accepted only when the router signed them for this key, each stamp once.
//! Pure: the clock is passed in.

use mech_proto::auth::{self, Freshness, Key, Refused, Signer, Verifier};
use mech_proto::{Body, Envelope, Header};

/// How far a new stream's first stamp may be from our clock (the
/// station's own default window), µs.
const WINDOW_US: u64 = 10_000_000;

/// Why a message could not be sent or was not accepted.
#[derive(Debug, thiserror::Error)]
pub enum SealError {
    #[error("cannot encode: {0}")]
    Encode(#[from] mech_proto::Error),
    #[error("{0}")]
    Auth(#[from] auth::AuthError),
    #[error("not signed by the router for this key")]
    NotFromRouter,
}

impl From<Refused> for SealError {
    fn from(refused: Refused) -> SealError {
        match refused {
            Refused::Auth(e) => SealError::Auth(e),
            Refused::NotFromRouter => SealError::NotFromRouter,
        }
    }
}

/// The sending side of one identity at the station: its name, its message
/// numbers, and its stamps and key (none at an unauthenticated station).
#[derive(Debug)]
pub struct Sealer {
    name: String,
    seq: u32,
    signer: Signer,
}

impl Sealer {
    pub fn new(name: &str, key: Option<Key>) -> Sealer {
        Sealer {
            name: name.to_string(),
            seq: 0,
            signer: Signer::new(key),
        }
    }

    /// The sender name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Whether messages are signed.
    pub fn signs(&self) -> bool {
        self.signer.signs()
    }

    /// Adopts the router's clock: it read `station_us` when ours read
    /// `local_us`.
    pub fn sync(&mut self, station_us: u64, local_us: u64) {
        self.signer.sync(station_us, local_us);
    }

    /// Station time now, as our stamps give it.
    pub fn station_us(&self, local_us: u64) -> u64 {
        self.signer.station_us(local_us)
    }

    /// One message, encoded and (with a key) signed on link 0.
    pub fn seal(
        &mut self,
        destination: &str,
        channel: &str,
        body: Body,
        local_us: u64,
    ) -> Result<Vec<u8>, SealError> {
        self.seq = self.seq.wrapping_add(1);
        let stamp_us = self.signer.stamp(local_us);
        let env = Envelope::new(
            Header {
                seq: self.seq,
                stamp_us,
                sender: self.name.clone(),
                destination: destination.to_string(),
                channel: channel.to_string(),
            },
            body,
        );
        let mut bytes = mech_proto::encode(&env)?;
        self.signer.seal_at(&mut bytes, 0, stamp_us)?;
        Ok(bytes)
    }
}

/// The receiving side: decodes what the router sent, and with a key
/// accepts only messages the router signed with it, each stamp once per
/// stream (sender and link), a new stream only near our clock.
#[derive(Debug)]
pub struct Opener {
    /// `None` at an unauthenticated station: messages are decoded only.
    verifier: Option<Verifier<(String, u8)>>,
}

impl Opener {
    /// An opener that takes nothing signed before `started_us`.
    pub fn new(key: Option<Key>, started_us: u64) -> Opener {
        let admit = Freshness {
            window_us: WINDOW_US,
            not_before_us: started_us.saturating_sub(WINDOW_US),
        };
        Opener {
            verifier: key.map(|k| Verifier::new(k, Some(admit))),
        }
    }

    /// An opener for one answer whose freshness something else proves (the
    /// nonce of a time request): any stamp, as long as the router signed
    /// it for this key.
    pub fn any_time(key: Option<Key>) -> Opener {
        let admit = Freshness {
            window_us: u64::MAX,
            not_before_us: 0,
        };
        Opener {
            verifier: key.map(|k| Verifier::new(k, Some(admit))),
        }
    }

    /// The message in `bytes`, if it is one to accept; `now_us` is station
    /// time.
    pub fn open(&mut self, bytes: &[u8], now_us: u64) -> Result<Envelope, SealError> {
        let env = mech_proto::decode(bytes)?;
        let Some(verifier) = self.verifier.as_mut() else {
            return Ok(env);
        };
        let sender = &env.header.sender;
        verifier.open(bytes, |tag| (sender.clone(), tag.link), now_us)?;
        Ok(env)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_proto::auth::FROM_ROUTER;
    use mech_proto::{Command, Subscribe, Twist};

    const NOW: u64 = 1_700_000_000_000_000;

    fn key(b: u8) -> Key {
        Key::new(&[b; 32])
    }

    fn twist() -> Body {
        Body::Command(Command::Twist(Twist {
            vx: 0.1,
            vy: 0.0,
            vz: 0.0,
            wz: 0.0,
        }))
    }

    /// What the router sends us from `sender`: signed with `k`, router
    /// bit set.
    fn from_router(k: &Key, sender: &str, stamp: u64) -> Vec<u8> {
        let env = Envelope::new(
            Header {
                seq: 1,
                stamp_us: stamp,
                sender: sender.into(),
                destination: "ros2".into(),
                channel: String::new(),
            },
            twist(),
        );
        let mut b = mech_proto::encode(&env).unwrap();
        k.seal(&mut b, FROM_ROUTER, stamp).unwrap();
        b
    }

    #[test]
    fn sealed_messages_are_numbered_stamped_and_signed() {
        let mut s = Sealer::new("ros2", Some(key(1)));
        let a = s.seal("robot_1", "ros2/robot_1", twist(), NOW).unwrap();
        let b = s.seal("robot_1", "ros2/robot_1", twist(), NOW).unwrap();
        let (ea, eb) = (
            mech_proto::decode(&a).unwrap(),
            mech_proto::decode(&b).unwrap(),
        );
        assert_eq!((ea.header.seq, eb.header.seq), (1, 2));
        assert!(eb.header.stamp_us > ea.header.stamp_us, "stamps rise");
        assert_eq!(ea.header.sender, "ros2");
        let (region, tag) = auth::split(&a).unwrap();
        let tag = tag.unwrap();
        assert!(key(1).verify(region, &tag) && !tag.from_router());
        assert_eq!(tag.stamp_us, ea.header.stamp_us);

        let mut unsigned = Sealer::new("ros2", None);
        let u = unsigned.seal(
            "router",
            "",
            Body::Subscribe(Subscribe { telemetry: true }),
            NOW,
        );
        assert_eq!(u.unwrap().last(), Some(&0xc0), "nil auth");
    }

    /// Refusals are the bridge's errors; each sender is a stream of its
    /// own, and a new one starts only near our clock (at any stamp for the
    /// answer to a time request).
    #[test]
    fn only_router_signed_fresh_messages_for_our_key_are_opened() {
        let k = key(1);
        let mut o = Opener::new(Some(k.clone()), NOW);
        let m = from_router(&k, "robot_1", NOW + 10);
        assert!(o.open(&m, NOW).is_ok());
        assert!(
            matches!(
                o.open(&m, NOW),
                Err(SealError::Auth(auth::AuthError::Replay))
            ),
            "each stamp once"
        );
        assert!(
            o.open(&from_router(&k, "robot_1", NOW + 3_000_000), NOW)
                .is_ok()
        );
        assert!(
            o.open(&from_router(&k, "robot_2", NOW + 20), NOW).is_ok(),
            "another sender, a stream of its own"
        );
        let mut s = Sealer::new("ros2", Some(k.clone()));
        let ours = s.seal("robot_1", "", twist(), NOW + 40).unwrap();
        assert!(
            matches!(o.open(&ours, NOW), Err(SealError::NotFromRouter)),
            "reflected"
        );
        let old = from_router(&k, "robot_1", NOW - 60_000_000);
        let mut fresh = Opener::new(Some(k.clone()), NOW);
        assert!(
            fresh.open(&old, NOW).is_err(),
            "a new stream far from our clock"
        );
        let mut answer = Opener::any_time(Some(k.clone()));
        assert!(answer.open(&old, NOW).is_ok(), "a time answer: any stamp");
        let mut unsigned = Opener::new(None, NOW);
        assert!(unsigned.open(&m, NOW).is_ok(), "no key: decoded only");
        assert!(unsigned.open(&[0x93, 1, 2, 3], NOW).is_err());
    }
}
