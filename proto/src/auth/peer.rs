//! Signing for a peer of the router (a robot, a controller, a bridge): what
//! it sends is stamped with station time and signed with its key
//! ([`Signer`]); what it receives is taken only when the router signed it
//! with that key, each stamp once on its stream ([`Verifier`]). The
//! router's own side, which holds every peer's key, is `mech-core`'s
//! keyring.

use std::collections::HashMap;
use std::hash::Hash;

use super::{AuthError, FROM_ROUTER, Freshness, Key, Stamper, Stream, TAG_LEN, Tag, split};

/// A peer's sending side: the stamps of what it sends, in station time
/// (its clock plus the offset the router's `Time` answer gave), and the
/// key that signs them.
#[derive(Debug, Clone)]
pub struct Signer {
    /// `None` at a station that does not authenticate: messages still
    /// carry stamps, and go unsigned.
    key: Option<Key>,
    stamper: Stamper,
}

impl Signer {
    pub fn new(key: Option<Key>) -> Signer {
        Signer {
            key,
            stamper: Stamper::default(),
        }
    }

    /// Whether what this peer sends is signed.
    pub fn signs(&self) -> bool {
        self.key.is_some()
    }

    /// Adopts station time: the router's clock read `station_us` when ours
    /// read `local_us`.
    pub fn sync(&mut self, station_us: u64, local_us: u64) {
        self.stamper.sync(station_us, local_us);
    }

    /// Station time when our clock reads `local_us`, without taking a
    /// stamp.
    pub fn station_us(&self, local_us: u64) -> u64 {
        local_us.saturating_add_signed(self.stamper.offset_us)
    }

    /// The next stamp, for a message made when our clock reads `local_us`:
    /// station time, and more than the last.
    pub fn stamp(&mut self, local_us: u64) -> u64 {
        self.stamper.next(local_us)
    }

    /// Signs `unsigned`, a whole message encoded with a nil `auth` element,
    /// as sent on the peer's link number `link` with a stamp already taken
    /// ([`Signer::stamp`]: the header carries it too). The direction bit is
    /// the router's and is cleared. Without a key the message is left
    /// unsigned.
    pub fn seal_at(
        &self,
        unsigned: &mut Vec<u8>,
        link: u8,
        stamp_us: u64,
    ) -> Result<(), AuthError> {
        match &self.key {
            Some(key) => key.seal(unsigned, link & !FROM_ROUTER, stamp_us),
            None => Ok(()),
        }
    }

    /// [`Signer::seal_at`] with the next stamp.
    pub fn seal(
        &mut self,
        unsigned: &mut Vec<u8>,
        link: u8,
        local_us: u64,
    ) -> Result<(), AuthError> {
        let stamp = self.stamp(local_us);
        self.seal_at(unsigned, link, stamp)
    }

    /// The tag over `region`, something signed that is not a message (a
    /// Zenoh route request), on `link` with the next stamp; `None` without
    /// a key (no stamp is taken).
    pub fn sign(&mut self, region: &[u8], link: u8, local_us: u64) -> Option<[u8; TAG_LEN]> {
        let key = self.key.as_ref()?;
        let stamp = self.stamper.next(local_us);
        Some(key.sign(region, link & !FROM_ROUTER, stamp))
    }
}

/// Why a peer refused a message from the router.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// Unsigned, malformed, signed with another key, changed, or a stamp
    /// that is not new on its stream.
    #[error("{0}")]
    Auth(#[from] AuthError),
    /// Signed with the peer's key, but not by the router: a message a peer
    /// holding the key sent, sent back (a reflection).
    #[error("not signed by the router for this key")]
    NotFromRouter,
}

/// A peer's receiving side: it takes a message only if the router signed
/// it with the peer's key, and each stamp once on the message's stream
/// ([`Stream`]). Streams are named by `K`, whatever the peer tells them
/// apart by (a sender and a link; `()` for one stream of everything the
/// router sends).
#[derive(Debug, Clone)]
pub struct Verifier<K> {
    key: Key,
    /// When a stream not seen before starts: its first stamp near our
    /// clock. `None`: only by [`Verifier::start`] (a robot without a clock
    /// starts the router's stream from the answer to its time request).
    admit: Option<Freshness>,
    streams: HashMap<K, Stream>,
}

impl<K: Eq + Hash> Verifier<K> {
    pub fn new(key: Key, admit: Option<Freshness>) -> Verifier<K> {
        Verifier {
            key,
            admit,
            streams: HashMap::new(),
        }
    }

    /// The tag of `bytes`, a whole message, if the router signed it with
    /// our key; its stamp is not looked at ([`Verifier::accept`]). The MAC
    /// is checked before the direction, so a reflection is only called one
    /// when the key signed it.
    pub fn verify(&self, bytes: &[u8]) -> Result<Tag, Refused> {
        let (region, tag) = split(bytes)?;
        let tag = tag.ok_or(AuthError::Unsigned)?;
        if tag.key_id != self.key.id() {
            return Err(AuthError::UnknownKey(tag.key_id).into());
        }
        if !self.key.verify(region, &tag) {
            return Err(AuthError::BadTag.into());
        }
        if !tag.from_router() {
            return Err(Refused::NotFromRouter);
        }
        Ok(tag)
    }

    /// Takes `stamp_us` on stream `id` if it is new there, or starts the
    /// stream with it if it is near our clock `now_us` (station time).
    pub fn accept(&mut self, id: K, stamp_us: u64, now_us: u64) -> Result<(), AuthError> {
        if let Some(stream) = self.streams.get_mut(&id) {
            return stream.accept(stamp_us);
        }
        if !self.admit.is_some_and(|f| f.admits(stamp_us, now_us)) {
            return Err(AuthError::Replay);
        }
        self.streams.insert(id, Stream::starting_at(stamp_us));
        Ok(())
    }

    /// [`Verifier::verify`], then [`Verifier::accept`] on the stream
    /// `stream` names for the tag.
    pub fn open(
        &mut self,
        bytes: &[u8],
        stream: impl FnOnce(&Tag) -> K,
        now_us: u64,
    ) -> Result<Tag, Refused> {
        let tag = self.verify(bytes)?;
        self.accept(stream(&tag), tag.stamp_us, now_us)?;
        Ok(tag)
    }

    /// Starts (or starts again) stream `id` at `stamp_us`, whose freshness
    /// something else proved (the nonce of a time request).
    pub fn start(&mut self, id: K, stamp_us: u64) {
        self.streams.insert(id, Stream::starting_at(stamp_us));
    }

    /// Forgets every stream (the router was lost: it may have restarted).
    pub fn forget(&mut self) {
        self.streams.clear();
    }

    /// Whether any stream has started.
    pub fn started(&self) -> bool {
        !self.streams.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NOW: u64 = 1_700_000_000_000_000;

    fn key(b: u8) -> Key {
        Key::new(&[b; 32])
    }

    /// A message as `key`'s holder seals it on `link`.
    fn sealed(key: &Key, link: u8, stamp: u64) -> Vec<u8> {
        let mut b = vec![0x93, 1, 2, 3, 0xc0];
        key.seal(&mut b, link, stamp).unwrap();
        b
    }

    fn tag_of(bytes: &[u8]) -> Tag {
        split(bytes).unwrap().1.unwrap()
    }

    #[test]
    fn a_signer_stamps_station_time_and_signs_as_a_peer() {
        let mut s = Signer::new(Some(key(1)));
        assert!(s.signs());
        let mut a = vec![0x93, 1, 2, 3, 0xc0];
        s.seal(&mut a, FROM_ROUTER | 2, 10).unwrap();
        let (region, tag) = split(&a).unwrap();
        let tag = tag.unwrap();
        assert!(key(1).verify(region, &tag));
        assert_eq!((tag.link, tag.stamp_us), (2, 10), "never the router's bit");
        assert_eq!(s.stamp(10), 11, "same clock reading: one more");
        s.sync(NOW, 20);
        assert_eq!(s.station_us(25), NOW + 5);
        assert_eq!(s.station_us(25), NOW + 5, "reading the time takes no stamp");
        let stamp = s.stamp(25);
        assert_eq!(stamp, NOW + 5);
        let mut b = vec![0x91, 0xc0];
        s.seal_at(&mut b, 0, stamp).unwrap();
        assert_eq!(tag_of(&b).stamp_us, NOW + 5);
        let t = s.sign(b"request", 0x40, 30).unwrap();
        let t = Tag::parse(&t).unwrap();
        assert_eq!((t.link, t.stamp_us), (0x40, NOW + 10));
        assert!(key(1).verify(b"request", &t) && !key(1).verify(b"other", &t));
    }

    #[test]
    fn a_signer_without_a_key_stamps_but_does_not_sign() {
        let mut s = Signer::new(None);
        assert!(!s.signs());
        let mut m = vec![0x91, 0xc0];
        s.seal(&mut m, 0, 10).unwrap();
        assert_eq!(m, [0x91, 0xc0], "nil auth");
        assert_eq!(s.stamp(10), 11);
        assert_eq!(s.sign(b"request", 0x40, 10), None);
        assert_eq!(s.stamp(10), 12, "no stamp taken for nothing signed");
    }

    #[test]
    fn only_what_the_router_signed_with_our_key_verifies() {
        let v: Verifier<()> = Verifier::new(key(1), None);
        let m = sealed(&key(1), FROM_ROUTER, NOW);
        assert_eq!(v.verify(&m), Ok(tag_of(&m)));
        let refused = |bytes: &[u8]| v.verify(bytes).unwrap_err();
        assert_eq!(refused(&[0x91, 0xc0]), AuthError::Unsigned.into());
        assert!(matches!(
            refused(&[0x91, 1]),
            Refused::Auth(AuthError::Shape(_))
        ));
        let other = sealed(&key(2), FROM_ROUTER, NOW);
        assert_eq!(refused(&other), AuthError::UnknownKey(key(2).id()).into());
        let mut changed = m.clone();
        changed[1] ^= 1;
        assert_eq!(refused(&changed), AuthError::BadTag.into());
        // Our own message sent back; one of another key is a forgery only.
        assert_eq!(refused(&sealed(&key(1), 0, NOW)), Refused::NotFromRouter);
        assert_eq!(
            refused(&sealed(&key(2), 0, NOW)),
            AuthError::UnknownKey(key(2).id()).into()
        );
        assert_eq!(
            Refused::NotFromRouter.to_string(),
            "not signed by the router for this key"
        );
        assert_eq!(
            Refused::from(AuthError::Replay).to_string(),
            "replay or stale stamp"
        );
    }

    #[test]
    fn each_stream_takes_a_stamp_once_and_starts_near_the_clock() {
        let fresh = Freshness {
            window_us: 10,
            not_before_us: NOW - 100,
        };
        let mut v: Verifier<u8> = Verifier::new(key(1), Some(fresh));
        let link = |t: &Tag| t.link;
        let m = sealed(&key(1), FROM_ROUTER, NOW + 5);
        assert!(!v.started());
        assert_eq!(v.open(&m, link, NOW), Ok(tag_of(&m)));
        assert!(v.started());
        assert_eq!(v.open(&m, link, NOW), Err(AuthError::Replay.into()));
        // A known stream goes on whatever the clock says.
        assert_eq!(v.accept(FROM_ROUTER, NOW + 1_000, NOW), Ok(()));
        // A new stream: near the clock, not from before the start.
        assert_eq!(v.accept(1, NOW + 11, NOW), Err(AuthError::Replay));
        assert_eq!(v.accept(1, NOW + 10, NOW), Ok(()));
        assert_eq!(v.accept(2, NOW - 101, NOW - 95), Err(AuthError::Replay));
        v.forget();
        assert!(!v.started());
        let forged = sealed(&key(2), FROM_ROUTER, NOW + 2_000);
        assert!(v.open(&forged, link, NOW).is_err());
        assert!(!v.started(), "a forgery starts no stream");
    }

    #[test]
    fn without_admission_only_a_started_stream_takes_stamps() {
        let mut v: Verifier<()> = Verifier::new(key(1), None);
        assert_eq!(v.accept((), NOW, NOW), Err(AuthError::Replay));
        v.start((), NOW);
        assert!(v.started());
        assert_eq!(
            v.accept((), NOW, NOW),
            Err(AuthError::Replay),
            "the start's"
        );
        assert_eq!(v.accept((), NOW + 1, 0), Ok(()));
        v.forget();
        assert_eq!(v.accept((), NOW + 2, NOW), Err(AuthError::Replay));
    }
}
