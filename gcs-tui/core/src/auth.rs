//! Who may do what on the robot network: keys with roles, the `[auth]`
//! configuration section, and the gate every received message passes
//! before the router acts on it.
//!
//! | role | may send |
//! | --- | --- |
//! | robot | its own registration, telemetry, heartbeats, acknowledgements, notices, Bye |
//! | controller | commands, fleet and cluster commands and missions on its `channels`; position fixes for robot R if `fix/R` is among them; channel discovery, telemetry subscriptions |
//! | operator | what a controller may, on every channel; e-stop engage and release |
//! | estop | e-stop engage only |
//!
//! Every message must carry a valid tag from a listed key ([`mech_proto::auth`])
//! whose name is the message's sender, be fresh on its stream, and be
//! permitted to the key's role. In-process publishers (the TUI, scripts,
//! the station's controllers) act as the station's operator. Rejections
//! are counted by reason.

mod keyfile;

use std::collections::HashMap;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::time::Duration;

use mech_proto::Body;
use mech_proto::auth::{AuthError, Freshness, Key, Stream, Tag};
use serde::Deserialize;

pub use keyfile::{KeyFile, KeyFileError};

use crate::config::{ConfigError, is_channel_name, secs};
use crate::counters::RejectReason;

/// Whether messages must be signed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum AuthMode {
    /// Every message must be signed by a listed key.
    Required,
    /// Nothing is checked: anyone who can reach the router can drive the
    /// robots. Shown as UNAUTHENTICATED.
    Off,
}

/// How exposed a running station is, for the status bar and `status`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Security {
    /// Every message from the network must be signed by a listed key.
    #[default]
    Authenticated,
    /// Unsigned, but listening on loopback only (the demo).
    LoopbackOnly,
    /// Unsigned and reachable from the network (`auth.mode = "off"`):
    /// anyone who reaches the router can drive the robots.
    Unauthenticated,
}

impl Security {
    /// How `status` and the service's start-up line say it (not a name:
    /// the attach protocol writes it in snake case).
    pub fn label(self) -> &'static str {
        match self {
            Security::Authenticated => "authenticated",
            Security::LoopbackOnly => "unsigned (loopback only)",
            Security::Unauthenticated => "UNAUTHENTICATED",
        }
    }
}

mech_proto::named_enum! {
    /// What a key may do.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
    pub enum Role: "role" {
        Robot => "robot",
        Controller => "controller",
        Operator => "operator",
        Estop => "estop",
    }
}

mech_proto::serde_by_name!(Role);

/// One `[[auth.keys]]` entry.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyEntry {
    pub role: Role,
    /// The robot, controller, operator or e-stop name the key signs as (a
    /// message's sender).
    pub name: String,
    /// The key file (`mech-gcs keygen NAME`).
    pub file: PathBuf,
    /// Channels a controller may publish on: names, or prefixes ending in
    /// `*` (`ext/*`). Operators may publish everywhere.
    #[serde(default)]
    pub channels: Vec<String>,
}

/// The `[auth]` section.
#[derive(Debug, Clone, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AuthConfig {
    /// `required` or `off`. Unset: required when keys are listed; with no
    /// keys, off on loopback, and a station listening beyond loopback
    /// refuses to start.
    pub mode: Option<AuthMode>,
    /// A stream the receiver has no record of is accepted only if its stamp
    /// is within this many seconds of the station's clock (default 10).
    #[serde(with = "secs_opt")]
    pub window: Option<Duration>,
    pub keys: Vec<KeyEntry>,
}

mod secs_opt {
    use std::time::Duration;

    use serde::Deserializer;

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Option<Duration>, D::Error> {
        super::secs::deserialize(d).map(Some)
    }
}

/// Default freshness window for a new stream.
pub const DEFAULT_WINDOW: Duration = Duration::from_secs(10);

impl AuthConfig {
    /// The mode the router runs in, given the endpoints it listens on.
    pub fn resolve(&self, endpoints: &[SocketAddr]) -> Result<AuthMode, ConfigError> {
        if let Some(mode) = self.mode {
            return Ok(mode);
        }
        if !self.keys.is_empty() {
            return Ok(AuthMode::Required);
        }
        match endpoints.iter().find(|a| !a.ip().is_loopback()) {
            None => Ok(AuthMode::Off),
            Some(open) => Err(ConfigError(format!(
                "the router listens on {open}, beyond this machine, and no keys are configured: \
                 anyone on that network could drive the robots. List keys in [auth] \
                 (make them with `mech-gcs keygen NAME`), or set auth.mode = \"off\" to run \
                 unauthenticated on a network you trust"
            ))),
        }
    }

    /// Checks names, channels and duplicates (not the files).
    pub fn validate(&self) -> Result<(), ConfigError> {
        let mut seen = HashMap::new();
        for k in &self.keys {
            if k.name.is_empty() || k.name.len() > mech_proto::MAX_NAME_LEN {
                return Err(ConfigError(format!(
                    "auth.keys: {:?} is not a name",
                    k.name
                )));
            }
            if let Some(other) = seen.insert((k.name.clone(), k.file.clone()), k.role) {
                return Err(ConfigError(format!(
                    "auth.keys: {} {} with {} is listed twice (also as {})",
                    k.role.as_str(),
                    k.name,
                    k.file.display(),
                    other.as_str()
                )));
            }
            for c in &k.channels {
                let pattern = c.strip_suffix('*').unwrap_or(c);
                if !(c == "*" || is_channel_name(pattern)) {
                    return Err(ConfigError(format!(
                        "auth.keys: {} channel {c:?} is not a channel name or prefix*",
                        k.name
                    )));
                }
            }
            if !k.channels.is_empty() && k.role != Role::Controller {
                return Err(ConfigError(format!(
                    "auth.keys: channels are for controllers; {} is a {}",
                    k.name,
                    k.role.as_str()
                )));
            }
        }
        if self.window.is_some_and(|w| w.is_zero()) {
            return Err(ConfigError::new("auth.window must be positive"));
        }
        Ok(())
    }

    /// Reads every key file.
    pub fn load_keys(&self) -> Result<Vec<Identity>, ConfigError> {
        self.keys.iter().map(load_key).collect()
    }

    /// What is wrong with the key files (missing, readable by others, of
    /// another holder), every one of them rather than the first: for
    /// `mech-gcs --check`. Empty when every key file loads.
    pub fn key_problems(&self) -> Vec<ConfigError> {
        self.keys.iter().filter_map(|e| load_key(e).err()).collect()
    }
}

/// Reads one listed key file and checks it is the key of the holder the
/// list names.
fn load_key(e: &KeyEntry) -> Result<Identity, ConfigError> {
    let file = KeyFile::load(&e.file).map_err(|err| match err {
        KeyFileError::Read { source, .. } if source.kind() == std::io::ErrorKind::NotFound => {
            ConfigError(format!(
                "the key file {} of {} {:?} does not exist; make it with \
                 `mech-gcs keygen {} --out {}`",
                e.file.display(),
                e.role.as_str(),
                e.name,
                e.name,
                e.file.display()
            ))
        }
        other => ConfigError(other.to_string()),
    })?;
    if file.name != e.name {
        return Err(ConfigError(format!(
            "{} is the key of {:?}, but auth.keys lists it for {:?}",
            e.file.display(),
            file.name,
            e.name
        )));
    }
    Ok(Identity::new(e.role, &e.name, file.key, e.channels.clone()))
}

/// A key, whose it is, and what it may do.
#[derive(Debug, Clone)]
pub struct Identity {
    pub role: Role,
    pub name: String,
    pub key: Key,
    channels: Vec<String>,
}

impl Identity {
    pub fn new(role: Role, name: &str, key: Key, channels: Vec<String>) -> Identity {
        Identity {
            role,
            name: name.to_string(),
            key,
            channels,
        }
    }

    /// Whether this identity may publish on `channel`.
    pub fn may_publish(&self, channel: &str) -> bool {
        match self.role {
            Role::Operator => true,
            Role::Controller => self.channels.iter().any(|p| match p.strip_suffix('*') {
                Some(prefix) => channel.starts_with(prefix),
                None => p == channel,
            }),
            Role::Robot | Role::Estop => false,
        }
    }

    /// Whether this identity may send `body` on `channel`; `None` if so,
    /// else why not.
    pub fn permits(&self, body: &Body, channel: &str) -> Option<String> {
        let role = self.role;
        let ok = match body {
            Body::Hello(_)
            | Body::Telemetry(_)
            | Body::MissionAck(_)
            | Body::RouteAck(_)
            | Body::EStopAck(_)
            | Body::ArenaAck(_) => role == Role::Robot,
            Body::Heartbeat(_) | Body::Notice(_) | Body::Bye(_) | Body::TimeRequest(_) => true,
            Body::Command(_) | Body::FleetCommand(_) | Body::Cluster(_) | Body::Mission(_) => {
                self.may_publish(channel)
            }
            Body::PositionFix(fix) => self.may_publish(&format!("fix/{}", fix.robot)),
            Body::ChannelsRequest(_) | Body::Subscribe(_) => {
                matches!(role, Role::Controller | Role::Operator)
            }
            Body::EStop(e) => role == Role::Operator || (e.engage && role == Role::Estop),
            Body::Autopilot(_) => role == Role::Operator,
            // The station's own: only the router sends them (an arena with
            // the layer switched off, too, comes from an operator's command
            // at the station, never from a peer).
            Body::Welcome(_)
            | Body::Route(_)
            | Body::Channels(_)
            | Body::Time(_)
            | Body::Arena(_)
            | Body::Neighbours(_) => false,
        };
        if ok {
            return None;
        }
        Some(match body {
            Body::EStop(e) if !e.engage => format!(
                "{} {} may not release the e-stop (operators only)",
                role.as_str(),
                self.name
            ),
            Body::Command(_) | Body::FleetCommand(_) | Body::Cluster(_) | Body::Mission(_) => {
                format!(
                    "{} {} may not publish on {channel:?}",
                    role.as_str(),
                    self.name
                )
            }
            _ => format!(
                "{} {} may not send {}",
                role.as_str(),
                self.name,
                body.kind()
            ),
        })
    }
}

/// Why the gate refused a message: a reason to count by, and a detail for
/// the log.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rejection {
    pub reason: RejectReason,
    pub detail: String,
}

fn reason_of(e: AuthError) -> RejectReason {
    match e {
        AuthError::Unsigned => RejectReason::Unsigned,
        AuthError::UnknownKey(_) => RejectReason::UnknownKey,
        AuthError::BadTag | AuthError::Shape(_) => RejectReason::BadTag,
        AuthError::Replay => RejectReason::Replay,
    }
}

/// A sender's stream under one key (its id) on one of its links.
type StreamId = (u32, u8);

/// The keyring's maps hash with foldhash, seeded per process: every
/// message looks a key up three to five times, and only keys the station
/// lists (and streams of messages whose tag checked) are ever inserted, so
/// a peer cannot choose what fills them.
type Map<K, V> = HashMap<K, V, foldhash::fast::RandomState>;

/// The keys the router holds and the freshness of every stream: the gate
/// of the authenticated control plane.
#[derive(Debug)]
pub struct Keyring {
    by_id: Map<u32, Identity>,
    /// The key each name last signed with (or, before that, the one listed
    /// last): the router signs what it sends a peer with it, so a key
    /// rotation works whichever key the peer holds.
    by_name: Map<String, u32>,
    /// Every stream, by key and link. A key is one name's (a message
    /// signed with it from another name is refused before its stamp is
    /// read), so the key's id names the sender too.
    streams: Map<StreamId, Stream>,
    freshness: Freshness,
}

/// A message that passed the tag and freshness checks: who signed it.
#[derive(Debug, Clone, Copy)]
pub struct Verified<'a> {
    pub identity: &'a Identity,
    pub tag: Tag,
}

impl Keyring {
    /// A keyring; new streams are accepted within `window` of the clock and
    /// not from before `started_us` (the router's start).
    pub fn new(keys: Vec<Identity>, window: Duration, started_us: u64) -> Keyring {
        let mut ring = Keyring {
            by_id: Map::default(),
            by_name: Map::default(),
            streams: Map::default(),
            freshness: Freshness {
                window_us: window.as_micros() as u64,
                not_before_us: started_us,
            },
        };
        for k in keys {
            ring.add(k);
        }
        ring
    }

    /// Adds a key. Both of a name's keys verify; the router signs with the
    /// one its holder last used, or the one added last.
    pub fn add(&mut self, identity: Identity) {
        let id = identity.key.id();
        self.by_name.insert(identity.name.clone(), id);
        self.by_id.insert(id, identity);
    }

    /// Number of keys held.
    pub fn len(&self) -> usize {
        self.by_id.len()
    }

    pub fn is_empty(&self) -> bool {
        self.by_id.is_empty()
    }

    /// The key the router signs with when it sends to `name`.
    pub fn key_for(&self, name: &str) -> Option<&Key> {
        self.by_name
            .get(name)
            .and_then(|id| self.by_id.get(id))
            .map(|i| &i.key)
    }

    /// The identity of a key id.
    pub fn identity(&self, key_id: u32) -> Option<&Identity> {
        self.by_id.get(&key_id)
    }

    /// Whether `stamp_us` is within the freshness window of the station's
    /// clock `now_us`: a stamp from a peer whose clock agrees with the
    /// station's, so its freshness can be judged.
    pub fn near_clock(&self, stamp_us: u64, now_us: u64) -> bool {
        stamp_us.abs_diff(now_us) <= self.freshness.window_us
    }

    /// Checks a message's tag over `region` and that `sender` is the key's
    /// name; with `fresh`, also that its stamp is new on its stream (and
    /// records it). `now_us` is the station's clock.
    pub fn verify(
        &mut self,
        region: &[u8],
        tag: Option<Tag>,
        sender: &str,
        now_us: u64,
        fresh: bool,
    ) -> Result<Verified<'_>, Rejection> {
        let tag = self.check_tag(region, tag, sender)?;
        if fresh {
            self.check_fresh(&tag, sender, now_us)?;
        }
        if self.by_name.get(sender) != Some(&tag.key_id) {
            self.by_name.insert(sender.to_string(), tag.key_id);
        }
        let identity = &self.by_id[&tag.key_id];
        Ok(Verified { identity, tag })
    }

    /// A tag of a listed key, made by a peer (not the router), that checks
    /// over `region`, from the key's own name.
    fn check_tag(&self, region: &[u8], tag: Option<Tag>, sender: &str) -> Result<Tag, Rejection> {
        let (tag, identity) = self.screened(tag, sender)?;
        if !identity.key.verify(region, &tag) {
            return Err(Rejection {
                reason: RejectReason::BadTag,
                detail: format!(
                    "tag of {sender:?} does not check with key {:08x}",
                    tag.key_id
                ),
            });
        }
        Ok(tag)
    }

    /// The checks that cost no MAC, for a message from `sender` whose tag
    /// (if any) is `tag`: it is signed, with a listed key, by a peer (not
    /// the router), and the key is the sender's. A forgery that fails
    /// them is refused before its body is read.
    pub fn screen(&self, tag: Option<Tag>, sender: &str) -> Result<(), Rejection> {
        self.screened(tag, sender).map(|_| ())
    }

    fn screened(&self, tag: Option<Tag>, sender: &str) -> Result<(Tag, &Identity), Rejection> {
        let reject = |e: AuthError, detail: String| Rejection {
            reason: reason_of(e),
            detail,
        };
        let tag = tag.ok_or_else(|| {
            reject(
                AuthError::Unsigned,
                format!("unsigned message from {sender:?}"),
            )
        })?;
        let identity = self.by_id.get(&tag.key_id).ok_or_else(|| {
            reject(
                AuthError::UnknownKey(tag.key_id),
                format!("key {:08x} (sender {sender:?}) is not listed", tag.key_id),
            )
        })?;
        if tag.from_router() {
            return Err(reject(
                AuthError::BadTag,
                format!("{sender:?} sent a message the router signed (reflected)"),
            ));
        }
        if identity.name != sender {
            return Err(Rejection {
                reason: RejectReason::NotPermitted,
                detail: format!(
                    "{:?} sent a message tagged with the key of {} {:?}",
                    sender,
                    identity.role.as_str(),
                    identity.name
                ),
            });
        }
        Ok((tag, identity))
    }

    /// The tag's stamp is newer than its stream's last (recorded), or
    /// starts a stream within the window of the clock.
    fn check_fresh(&mut self, tag: &Tag, sender: &str, now_us: u64) -> Result<(), Rejection> {
        let replay = |detail: String| Rejection {
            reason: RejectReason::Replay,
            detail,
        };
        let id = (tag.key_id, tag.link);
        if let Some(stream) = self.streams.get_mut(&id) {
            let last = stream.last_us();
            return stream.accept(tag.stamp_us).map_err(|_| {
                replay(format!(
                    "{sender:?} stamp {} is not newer than {last} (replay?)",
                    tag.stamp_us
                ))
            });
        }
        if !self.freshness.admits(tag.stamp_us, now_us) {
            return Err(replay(format!(
                "{sender:?} stamp is {:.1} s from the station's clock (replay, or its clock \
                 is off: ask the router for the time)",
                (tag.stamp_us as f64 - now_us as f64) / 1e6
            )));
        }
        self.streams.insert(id, Stream::starting_at(tag.stamp_us));
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ring(keys: &[(&str, u8)]) -> Keyring {
        let ids = keys
            .iter()
            .map(|(n, b)| Identity::new(Role::Controller, n, Key::new(&[*b; 32]), vec!["*".into()]))
            .collect();
        Keyring::new(ids, Duration::from_secs(10), 1_000)
    }

    fn signed(key: &Key, stamp: u64) -> (Vec<u8>, Tag) {
        signed_on(key, 0, stamp)
    }

    fn signed_on(key: &Key, link: u8, stamp: u64) -> (Vec<u8>, Tag) {
        let mut b = vec![0x91, 0x01, 0xc0];
        key.seal(&mut b, link, stamp).unwrap();
        let (_, tag) = mech_proto::auth::split(&b).unwrap();
        (b[..2].to_vec(), tag.unwrap())
    }

    #[test]
    fn each_key_and_link_of_a_sender_is_a_stream_of_its_own() {
        let (old, new, other) = (Key::new(&[1; 32]), Key::new(&[2; 32]), Key::new(&[3; 32]));
        let mut r = ring(&[("matlab", 1), ("matlab", 2), ("octave", 3)]);
        let now = 5_000_000;
        let mut verify = |key: &Key, sender: &str, link: u8, stamp: u64| {
            let (region, tag) = signed_on(key, link, stamp);
            r.verify(&region, Some(tag), sender, now, true)
                .map(|_| ())
                .map_err(|e| e.reason)
        };
        assert_eq!(verify(&old, "matlab", 0, now + 10), Ok(()));
        // The same stamp on another link, under another key of the same
        // name, from another sender: each starts a stream of its own.
        assert_eq!(verify(&old, "matlab", 1, now + 10), Ok(()));
        assert_eq!(verify(&new, "matlab", 0, now + 10), Ok(()));
        assert_eq!(verify(&other, "octave", 0, now + 10), Ok(()));
        // Each stream remembers its own stamps.
        for (key, sender, link) in [
            (&old, "matlab", 0),
            (&old, "matlab", 1),
            (&new, "matlab", 0),
            (&other, "octave", 0),
        ] {
            let again = verify(key, sender, link, now + 10);
            assert_eq!(again, Err(RejectReason::Replay), "{sender} {link}");
            assert_eq!(
                verify(key, sender, link, now + 11),
                Ok(()),
                "{sender} {link}"
            );
        }
        assert_eq!(verify(&old, "matlab", 2, now + 11), Ok(()), "a new link");
    }

    #[test]
    fn during_a_rotation_the_router_signs_with_the_key_the_holder_uses() {
        let (old, new) = (Key::new(&[1; 32]), Key::new(&[2; 32]));
        let mut r = ring(&[("matlab", 1), ("matlab", 2)]);
        assert_eq!(r.key_for("matlab").unwrap().id(), new.id(), "listed last");
        let (region, tag) = signed(&old, 5_000_000);
        r.verify(&region, Some(tag), "matlab", 5_000_000, true)
            .unwrap();
        assert_eq!(
            r.key_for("matlab").unwrap().id(),
            old.id(),
            "the one in use"
        );
        let (region, tag) = signed(&new, 5_000_001);
        r.verify(&region, Some(tag), "matlab", 5_000_001, true)
            .unwrap();
        assert_eq!(r.key_for("matlab").unwrap().id(), new.id());
    }

    #[test]
    fn new_streams_must_be_near_the_clock_and_after_the_start() {
        let k = Key::new(&[1; 32]);
        let mut r = ring(&[("matlab", 1)]);
        let hour = 3_600_000_000;
        let (region, tag) = signed(&k, 2 * hour);
        let e = r
            .verify(&region, Some(tag), "matlab", 3 * hour, true)
            .unwrap_err();
        assert_eq!(e.reason, RejectReason::Replay, "an hour old");
        let (region, tag) = signed(&k, 500);
        let e = r
            .verify(&region, Some(tag), "matlab", 600, true)
            .unwrap_err();
        assert_eq!(e.reason, RejectReason::Replay, "before the router started");
        let (region, tag) = signed(&k, 3 * hour - 1);
        r.verify(&region, Some(tag), "matlab", 3 * hour, true)
            .unwrap();
        let e = r
            .verify(&region, Some(tag), "matlab", 3 * hour, true)
            .unwrap_err();
        assert_eq!(e.reason, RejectReason::Replay, "the same message again");
    }

    /// Arenas and neighbour lists come from the station alone: no peer,
    /// not even an operator, may send them (switching a robot's layer off
    /// is an operator's command at the station); only robots acknowledge.
    #[test]
    fn only_the_station_sends_arenas_and_neighbours_and_only_robots_ack_them() {
        let arena = Body::Arena(mech_proto::Arena {
            robot: "robot_1".into(),
            id: 1,
            enabled: false,
            boundary: vec![],
            keep_out: vec![],
            slow_zones: vec![],
            margin: 0.1,
        });
        let neighbours = Body::Neighbours(mech_proto::Neighbours {
            robot: "robot_1".into(),
            stamp_us: 1,
            robots: vec![],
            obstacles: vec![],
        });
        let ack = Body::ArenaAck(mech_proto::ArenaAck {
            robot: "robot_1".into(),
            id: 1,
        });
        for role in [Role::Robot, Role::Controller, Role::Operator, Role::Estop] {
            let who = Identity::new(role, "x", Key::new(&[1; 32]), vec![]);
            assert!(who.permits(&arena, "").is_some(), "{role:?} arena");
            assert!(
                who.permits(&neighbours, "").is_some(),
                "{role:?} neighbours"
            );
            assert_eq!(who.permits(&ack, "").is_none(), role == Role::Robot);
        }
    }
}
