//! Message authentication: an HMAC-SHA-256 tag in the envelope's `auth`
//! element, and the freshness rule that refuses replays.
//!
//! A signed message ends with a 29-byte tag (bin 8):
//!
//! ```text
//! key_id u32 BE | link u8 | stamp_us u64 BE | mac [16]
//! mac = first 16 bytes of HMAC-SHA-256(key, signed_region || key_id || link || stamp_us)
//! ```
//!
//! - `signed_region` is every byte of the message before the `auth`
//!   element (header and body), so nothing in the message can change
//!   without the tag failing;
//! - `key_id` names the key, so a receiver holding several (old and new,
//!   during a rotation) knows which one to check with. It is derived from
//!   the key itself ([`Key::id`]): the first four bytes of SHA-256(key);
//! - `link`: bit 7 is the direction, set ([`FROM_ROUTER`]) on what the
//!   router signs and clear on what robots, controllers and operators sign,
//!   so a message cannot be reflected back to the one who signed it (a
//!   robot shares its key with the router only); bits 0-6 number the
//!   sender's links (UDP, a radio...) so each link is its own stream;
//! - `stamp_us` is the sender's station time in microseconds since the Unix
//!   epoch, strictly increasing on each stream (key, sender, link). A
//!   receiver accepts each stamp once, and only if it is not far behind the
//!   newest it accepted on that stream ([`Stream`]); a stream it has no
//!   record of is accepted only if the stamp is within a window of its own
//!   clock and not from before it started ([`Freshness`]). A robot without a real-time
//!   clock asks the router for station time first (`TimeRequest` with a
//!   random nonce; the router's signed `Time` answer echoes it).
//!
//! Verification compares MACs in constant time. Payloads are not encrypted:
//! anyone on the network can read them, nobody without the key can make or
//! change one.
//!
//! A peer of the router (a robot, a controller, a bridge) signs and checks
//! with [`Signer`] and [`Verifier`].

mod peer;

use hmac::{Hmac, Mac};
use sha2::{Digest, Sha256};

pub use peer::{Refused, Signer, Verifier};

/// Bytes of a tag (the `auth` element's payload).
pub const TAG_LEN: usize = 4 + 1 + 8 + MAC_LEN;

/// Bytes of the MAC at the end of a tag (128 bits).
pub const MAC_LEN: usize = 16;

/// Bytes of a key (256 bits).
pub const KEY_LEN: usize = 32;

/// The direction bit of a tag's `link`: set on everything the router signs.
pub const FROM_ROUTER: u8 = 0x80;

/// A shared secret and its id, ready to sign and verify. Keying HMAC is done
/// once here; each message then costs one clone of the keyed state.
#[derive(Clone)]
pub struct Key {
    id: u32,
    mac: Hmac<Sha256>,
}

impl std::fmt::Debug for Key {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        // Never print the secret.
        f.debug_struct("Key")
            .field("id", &format_args!("{:08x}", self.id))
            .finish_non_exhaustive()
    }
}

impl Key {
    /// A key from its 32 secret bytes.
    pub fn new(secret: &[u8; KEY_LEN]) -> Key {
        let digest = Sha256::digest(secret);
        let id = u32::from_be_bytes([digest[0], digest[1], digest[2], digest[3]]);
        let mac = <Hmac<Sha256> as Mac>::new_from_slice(secret)
            .unwrap_or_else(|_| unreachable!("HMAC accepts keys of any length"));
        Key { id, mac }
    }

    /// The key's id: the first four bytes of SHA-256(secret), big-endian.
    pub fn id(&self) -> u32 {
        self.id
    }

    /// The tag for a message whose signed region is `region`.
    pub fn sign(&self, region: &[u8], link: u8, stamp_us: u64) -> [u8; TAG_LEN] {
        let mut tag = [0u8; TAG_LEN];
        tag[..4].copy_from_slice(&self.id.to_be_bytes());
        tag[4] = link;
        tag[5..13].copy_from_slice(&stamp_us.to_be_bytes());
        let mut mac = self.mac.clone();
        mac.update(region);
        mac.update(&tag[..13]);
        let full = mac.finalize().into_bytes();
        tag[13..].copy_from_slice(&full[..MAC_LEN]);
        tag
    }

    /// Whether `tag` is this key's tag over `region` (constant time).
    pub fn verify(&self, region: &[u8], tag: &Tag) -> bool {
        if tag.key_id != self.id {
            return false;
        }
        let mut mac = self.mac.clone();
        mac.update(region);
        mac.update(&tag.bytes[..13]);
        mac.verify_truncated_left(&tag.bytes[13..]).is_ok()
    }

    /// Appends a tag to `unsigned`, a whole message encoded with a nil
    /// `auth` element (as [`crate::encode`] writes it): the nil is replaced
    /// by the tag.
    pub fn seal(&self, unsigned: &mut Vec<u8>, link: u8, stamp_us: u64) -> Result<(), AuthError> {
        if unsigned.last() != Some(&NIL) {
            return Err(AuthError::Shape(
                "message does not end with a nil auth element",
            ));
        }
        unsigned.pop();
        let tag = self.sign(unsigned, link, stamp_us);
        unsigned.reserve(TAG_LEN + 2);
        unsigned.push(BIN8);
        unsigned.push(TAG_LEN as u8);
        unsigned.extend_from_slice(&tag);
        Ok(())
    }
}

/// A parsed tag. The bytes are kept as received, since they are what the
/// MAC covers.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tag {
    pub key_id: u32,
    pub link: u8,
    pub stamp_us: u64,
    bytes: [u8; TAG_LEN],
}

impl Tag {
    /// Whether the router signed it (the direction bit of `link`).
    pub fn from_router(&self) -> bool {
        self.link & FROM_ROUTER != 0
    }

    /// Reads a tag from the `auth` element's payload.
    pub fn parse(payload: &[u8]) -> Result<Tag, AuthError> {
        let bytes: [u8; TAG_LEN] = payload
            .try_into()
            .map_err(|_| AuthError::Shape("tag is not 29 bytes"))?;
        Ok(Tag {
            key_id: u32::from_be_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]),
            link: bytes[4],
            stamp_us: u64::from_be_bytes([
                bytes[5], bytes[6], bytes[7], bytes[8], bytes[9], bytes[10], bytes[11], bytes[12],
            ]),
            bytes,
        })
    }
}

const NIL: u8 = 0xc0;
const BIN8: u8 = 0xc4;

/// Splits a message into its signed region and its tag, without decoding
/// it: the last element is the `auth` element, nil (unsigned) or a bin 8 of
/// [`TAG_LEN`] bytes. A message this calls signed is accepted only if the
/// MAC over the region checks, so reading an unsigned message's last bytes
/// as a tag by coincidence can only make it rejected, never accepted.
pub fn split(bytes: &[u8]) -> Result<(&[u8], Option<Tag>), AuthError> {
    let n = bytes.len();
    if n > TAG_LEN + 2 && bytes[n - TAG_LEN - 2] == BIN8 && bytes[n - TAG_LEN - 1] == TAG_LEN as u8
    {
        let tag = Tag::parse(&bytes[n - TAG_LEN..])?;
        return Ok((&bytes[..n - TAG_LEN - 2], Some(tag)));
    }
    match bytes.last() {
        Some(&NIL) => Ok((&bytes[..n - 1], None)),
        _ => Err(AuthError::Shape("last element is neither nil nor a tag")),
    }
}

/// Why a message failed authentication. Receivers count these by reason
/// (the station's `RejectReason`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
pub enum AuthError {
    /// No tag where one is required.
    #[error("unsigned")]
    Unsigned,
    /// The tag names a key the receiver does not hold.
    #[error("unknown key {0:08x}")]
    UnknownKey(u32),
    /// The MAC does not match: wrong key, or the message was changed.
    #[error("bad tag")]
    BadTag,
    /// The stamp is not newer than the stream's last, or a new stream's
    /// stamp is outside the receiver's window.
    #[error("replay or stale stamp")]
    Replay,
    /// The tag or the auth element is malformed.
    #[error("malformed tag: {0}")]
    Shape(&'static str),
}

/// Messages a stream may deliver out of order: a stamp older than the
/// newest is still accepted if it is among the last this many and not a
/// repeat (the anti-replay window of IPsec and DTLS, over stamps).
pub const REORDER_WINDOW: usize = 64;

/// How much older than the newest stamp a late message may be, µs.
pub const REORDER_SPAN_US: u64 = 1_000_000;

/// What a receiver remembers of one stream: where it started, the newest
/// stamp, and the stamps accepted most recently. A stamp is accepted once:
/// never a repeat, never from before the stream started, never more than
/// [`REORDER_WINDOW`] messages or [`REORDER_SPAN_US`] behind the newest. So
/// a captured message replayed later is refused, while a datagram the
/// network (or the router's own parallel paths) delivered a little late is
/// not lost.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stream {
    start_us: u64,
    newest_us: u64,
    /// The stamps remembered, oldest first from `head` round the ring: a
    /// stamp newer than all takes the oldest's place in one step.
    recent: [u64; REORDER_WINDOW],
    head: usize,
    len: usize,
}

impl Stream {
    /// A stream whose first accepted stamp was `stamp_us`.
    pub fn starting_at(stamp_us: u64) -> Stream {
        let mut recent = [0; REORDER_WINDOW];
        recent[0] = stamp_us;
        Stream {
            start_us: stamp_us,
            newest_us: stamp_us,
            recent,
            head: 0,
            len: 1,
        }
    }

    /// Accepts `stamp_us` if it is new to this stream and recent enough.
    pub fn accept(&mut self, stamp_us: u64) -> Result<(), AuthError> {
        if stamp_us > self.newest_us {
            // The usual case, a stamp newer than all: neither a repeat nor
            // too old, so it is remembered last, in place of the oldest
            // once the window is full.
            if self.len < REORDER_WINDOW {
                self.recent[self.slot(self.len)] = stamp_us;
                self.len += 1;
            } else {
                self.recent[self.head] = stamp_us;
                self.head = self.slot(1);
            }
            self.newest_us = stamp_us;
            return Ok(());
        }
        self.accept_late(stamp_us)
    }

    /// Where the `k`-th oldest stamp remembered is kept.
    fn slot(&self, k: usize) -> usize {
        (self.head + k) % REORDER_WINDOW
    }

    /// The `k`-th oldest stamp remembered.
    fn nth(&self, k: usize) -> u64 {
        self.recent[self.slot(k)]
    }

    /// [`Stream::accept`] for a stamp no newer than the newest accepted:
    /// found among the stamps remembered by bisection, and put in its
    /// place (the oldest forgotten when the window is full).
    fn accept_late(&mut self, stamp_us: u64) -> Result<(), AuthError> {
        let oldest = self.nth(0);
        let too_old = stamp_us < self.start_us
            || stamp_us.saturating_add(REORDER_SPAN_US) < self.newest_us
            || (self.len == REORDER_WINDOW && stamp_us <= oldest);
        let (mut lo, mut hi) = (0, self.len);
        while lo < hi {
            let mid = (lo + hi) / 2;
            if self.nth(mid) < stamp_us {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        if too_old || (lo < self.len && self.nth(lo) == stamp_us) {
            return Err(AuthError::Replay);
        }
        let mut at = lo;
        if self.len == REORDER_WINDOW {
            // Older than `stamp_us` (not too old), so `at >= 1`.
            self.head = self.slot(1);
            self.len -= 1;
            at -= 1;
        }
        for k in (at..self.len).rev() {
            self.recent[self.slot(k + 1)] = self.nth(k);
        }
        self.recent[self.slot(at)] = stamp_us;
        self.len += 1;
        Ok(())
    }

    /// The newest stamp accepted.
    pub fn last_us(&self) -> u64 {
        self.newest_us
    }
}

/// When a receiver accepts a stream it has no record of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Freshness {
    /// Largest distance between a new stream's stamp and the receiver's
    /// clock, µs.
    pub window_us: u64,
    /// Stamps from before this (the receiver's start) are refused: nothing
    /// signed before a restart is accepted after it.
    pub not_before_us: u64,
}

impl Freshness {
    /// Whether a new stream may start at `stamp_us` when the receiver's
    /// clock reads `now_us`.
    pub fn admits(&self, stamp_us: u64, now_us: u64) -> bool {
        stamp_us >= self.not_before_us && stamp_us.abs_diff(now_us) <= self.window_us
    }
}

/// A sender's stamps: station time (its clock plus an offset learned from
/// the router, for robots without a real-time clock), strictly increasing.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Stamper {
    /// Added to the local clock to get station time, µs.
    pub offset_us: i64,
    last_us: u64,
}

impl Stamper {
    /// The next stamp for a message made when the local clock reads
    /// `local_us`: station time, and at least one more than the last.
    pub fn next(&mut self, local_us: u64) -> u64 {
        let station = local_us.saturating_add_signed(self.offset_us);
        self.last_us = station.max(self.last_us.saturating_add(1));
        self.last_us
    }

    /// Adopts station time: `station_us` was the router's clock when the
    /// local clock read `local_us`.
    pub fn sync(&mut self, station_us: u64, local_us: u64) {
        self.offset_us = (station_us as i128 - local_us as i128)
            .clamp(i64::MIN as i128, i64::MAX as i128) as i64;
    }
}

/// A key file's contents: whose key it is, and the key. The file is two
/// TOML lines, `name = "..."` and `secret = "<64 hex digits>"`, with
/// comments; [`KeyText::render`] writes it, [`KeyText::parse`] reads it
/// (the key files themselves are read and written by the station and the
/// agent, which also check that only their owner can read them:
/// [`private_mode`]).
#[derive(Debug, Clone)]
pub struct KeyText {
    pub name: String,
    pub key: Key,
}

impl KeyText {
    /// Reads a key file's text.
    pub fn parse(text: &str) -> Result<KeyText, String> {
        let mut name = None;
        let mut secret = None;
        for (n, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            let (k, v) = line
                .split_once('=')
                .ok_or_else(|| format!("line {}: expected key = \"value\"", n + 1))?;
            let v = v.trim();
            let v = v
                .strip_prefix('"')
                .and_then(|v| v.strip_suffix('"'))
                .ok_or_else(|| format!("line {}: the value must be quoted", n + 1))?;
            match k.trim() {
                "name" => name = Some(v.to_string()),
                "secret" => secret = Some(parse_secret(v).map_err(|e| format!("secret: {e}"))?),
                other => return Err(format!("line {}: unknown field {other:?}", n + 1)),
            }
        }
        let name = name.ok_or("missing field `name`")?;
        let secret = secret.ok_or("missing field `secret`")?;
        if name.is_empty()
            || name.len() > crate::MAX_NAME_LEN
            || name
                .chars()
                .any(|c| c == '"' || c == '\\' || c.is_control())
        {
            return Err(format!("name {name:?} is not a MECH name"));
        }
        Ok(KeyText {
            name,
            key: Key::new(&secret),
        })
    }

    /// The text of a key file for `name` holding `secret`.
    pub fn render(name: &str, secret: &[u8; KEY_LEN]) -> String {
        let hex: String = secret.iter().map(|b| format!("{b:02x}")).collect();
        format!(
            "# MECH key for {name:?} (id {:08x}). Keep it secret: whoever holds it\n\
             # can sign as {name}.\nname = {name:?}\nsecret = \"{hex}\"\n",
            Key::new(secret).id()
        )
    }
}

/// Whether a key file with these Unix permission bits is private enough:
/// no access for group or others.
pub fn private_mode(mode: u32) -> Result<(), String> {
    if mode & 0o077 != 0 {
        return Err(format!(
            "it can be read by other users (mode {:o}); a key file must be private (chmod 600)",
            mode & 0o777
        ));
    }
    Ok(())
}

/// Reads a key's 32 secret bytes from 64 hex digits (surrounding
/// whitespace ignored).
pub fn parse_secret(hex: &str) -> Result<[u8; KEY_LEN], String> {
    let hex = hex.trim();
    if let Some((at, c)) = hex.char_indices().find(|(_, c)| !c.is_ascii_hexdigit()) {
        return Err(format!("{c:?} at byte {} is not hex", at + 1));
    }
    if hex.len() != 2 * KEY_LEN {
        return Err(format!(
            "a key is {} hex digits, found {}",
            2 * KEY_LEN,
            hex.len()
        ));
    }
    let mut out = [0u8; KEY_LEN];
    for (i, byte) in out.iter_mut().enumerate() {
        let pair = &hex[2 * i..2 * i + 2];
        *byte = u8::from_str_radix(pair, 16)
            .map_err(|_| format!("{pair:?} at digit {} is not hex", 2 * i + 1))?;
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(b: u8) -> Key {
        Key::new(&[b; KEY_LEN])
    }

    /// A secret of 64 bytes that are not all hex digits (a multi-byte
    /// character among them) is refused with the place of the first.
    #[test]
    fn a_secret_that_is_not_hex_is_refused_not_cut() {
        let good = "ab".repeat(KEY_LEN);
        assert_eq!(parse_secret(&good), Ok([0xab; KEY_LEN]));
        let accented = format!("a\u{e9}{}", &good[..61]);
        assert_eq!(accented.len(), 2 * KEY_LEN);
        let e = parse_secret(&accented).unwrap_err();
        assert!(e.contains("at byte 2"), "{e}");
        assert!(parse_secret(&format!("g{}", &good[1..])).is_err());
    }

    #[test]
    fn a_sealed_message_verifies_and_any_change_fails() {
        let k = key(7);
        let mut msg = vec![0x99, 1, 2, 3, NIL];
        k.seal(&mut msg, 2, 1_700_000_000_000_000).unwrap();
        assert_eq!(msg.len(), 4 + 2 + TAG_LEN);
        let (region, tag) = split(&msg).unwrap();
        let tag = tag.unwrap();
        assert_eq!((tag.key_id, tag.link), (k.id(), 2));
        assert_eq!(tag.stamp_us, 1_700_000_000_000_000);
        assert!(k.verify(region, &tag));
        assert!(!key(8).verify(region, &tag), "another key");
        for i in 0..msg.len() {
            let mut bad = msg.clone();
            bad[i] ^= 0x01;
            let ok = match split(&bad) {
                Ok((region, Some(tag))) => k.verify(region, &tag),
                _ => false,
            };
            assert!(!ok, "flipping byte {i} must break the tag");
        }
    }

    #[test]
    fn unsigned_messages_split_without_a_tag() {
        let (region, tag) = split(&[0x99, 1, NIL]).unwrap();
        assert_eq!((region, tag), (&[0x99, 1][..], None));
        assert!(split(&[0x99, 1]).is_err());
        assert!(split(&[]).is_err());
    }

    #[test]
    fn streams_take_each_stamp_once_and_tolerate_a_little_reordering() {
        let mut s = Stream::starting_at(100);
        assert_eq!(s.accept(100), Err(AuthError::Replay), "repeat");
        assert_eq!(s.accept(99), Err(AuthError::Replay), "before the start");
        assert_eq!(s.accept(105), Ok(()));
        assert_eq!(s.accept(103), Ok(()), "late, but new");
        assert_eq!(s.accept(103), Err(AuthError::Replay), "repeat");
        assert_eq!(s.last_us(), 105);
        // More than a second behind the newest: refused.
        assert_eq!(s.accept(2_000_105), Ok(()));
        assert_eq!(s.accept(1_000_104), Err(AuthError::Replay));
        // More than the window of messages behind: refused.
        for i in 1..=REORDER_WINDOW as u64 {
            assert_eq!(s.accept(3_000_000 + i), Ok(()));
        }
        assert_eq!(s.accept(3_000_000), Err(AuthError::Replay));
        let f = Freshness {
            window_us: 10,
            not_before_us: 50,
        };
        assert!(f.admits(95, 100) && f.admits(105, 100));
        assert!(!f.admits(89, 100) && !f.admits(111, 100));
        assert!(!f.admits(49, 55), "from before the receiver started");
    }

    proptest::proptest! {
        /// A stamp newer than all takes the short way; whatever way it
        /// takes, the stream accepts exactly what its rule says (a stamp
        /// once, from the start on, within the window and the span behind
        /// the newest).
        #[test]
        fn streams_accept_what_the_rule_says(
            steps in proptest::collection::vec((0u64..4, 0u64..200), 1..400)
        ) {
            let mut s = Stream::starting_at(1_000);
            let mut accepted: Vec<u64> = vec![1_000];
            let mut newest = 1_000u64;
            for (kind, d) in steps {
                // Mostly forward, sometimes back, sometimes far back.
                let stamp = match kind {
                    0 | 1 => newest + d,
                    2 => newest.saturating_sub(d),
                    _ => newest.saturating_sub(d * 10_000),
                };
                let window = &accepted[accepted.len().saturating_sub(REORDER_WINDOW)..];
                let mut recent = window.to_vec();
                recent.sort_unstable();
                let oldest = recent[0];
                let new = stamp >= 1_000
                    && stamp.saturating_add(REORDER_SPAN_US) >= newest
                    && !(window.len() == REORDER_WINDOW && stamp <= oldest)
                    && !recent.contains(&stamp);
                proptest::prop_assert_eq!(s.accept(stamp).is_ok(), new, "{}", stamp);
                if new {
                    // What the stream remembers: the newest WINDOW stamps
                    // by value once full (the oldest makes room).
                    accepted.push(stamp);
                    if accepted.len() > REORDER_WINDOW {
                        let (i, _) = accepted
                            .iter()
                            .enumerate()
                            .min_by_key(|(_, v)| **v)
                            .unwrap();
                        accepted.remove(i);
                    }
                    newest = newest.max(stamp);
                }
                proptest::prop_assert_eq!(s.last_us(), newest);
            }
        }
    }

    #[test]
    fn stamps_are_station_time_and_strictly_increasing() {
        let mut s = Stamper::default();
        assert_eq!(s.next(10), 10);
        assert_eq!(s.next(10), 11, "same clock reading: one more");
        s.sync(1_000_000, 20);
        assert_eq!(s.next(20), 1_000_000);
        assert_eq!(s.next(25), 1_000_005);
        s.sync(10, 30); // the router's clock went back: stamps still rise
        assert_eq!(s.next(31), 1_000_006);
    }

    #[test]
    fn key_files_render_and_parse_back() {
        let text = KeyText::render("robot_1", &[7; KEY_LEN]);
        let k = KeyText::parse(&text).unwrap();
        assert_eq!((k.name.as_str(), k.key.id()), ("robot_1", key(7).id()));
        assert!(text.starts_with("# MECH key for \"robot_1\""));
        let e = |t: &str| KeyText::parse(t).unwrap_err();
        assert!(e("name = \"a\"\n").contains("secret"));
        assert!(e("name = \"a\"\nsecret = \"00\"\n").contains("64 hex digits"));
        assert!(e("name = a\n").contains("quoted"));
        assert!(e("colour = \"red\"\n").contains("unknown field"));
        assert!(private_mode(0o600).is_ok() && private_mode(0o400).is_ok());
        assert!(private_mode(0o640).unwrap_err().contains("chmod 600"));
    }

    #[test]
    fn key_ids_come_from_the_key_and_secrets_parse_from_hex() {
        let secret = parse_secret(&"00".repeat(32)).unwrap();
        assert_eq!(Key::new(&secret).id(), Key::new(&[0; 32]).id());
        assert_ne!(key(1).id(), key(2).id());
        assert!(parse_secret("abc").unwrap_err().contains("64 hex digits"));
        assert!(
            parse_secret(&"zz".repeat(32))
                .unwrap_err()
                .contains("not hex")
        );
        assert!(
            !format!("{:?}", key(3)).contains("3, 3"),
            "no secret in Debug"
        );
    }
}
