//! The live view's channels and clients. Each client has a bounded queue of
//! frames its connection task sends; publishing offers a frame to the
//! queue of each client subscribed to the channel without waiting, and a
//! full queue drops the frame and counts it. Channels are advertised to
//! every client as they appear (a robot's on its first telemetry); a client
//! whose queue is too full even for that is disconnected (it would miss
//! channels), as is one that keeps sending bad requests.

use std::collections::HashMap;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use mech_core::record::schema;
use mech_core::sync::lock;
use tokio::sync::{Semaphore, mpsc};

use super::protocol::{self, ChannelInfo, Level, Subscription};

/// A frame for a client's connection task.
#[derive(Debug)]
pub(super) enum Out {
    Text(String),
    Binary(Vec<u8>),
}

/// Why the hub let go of a client (its connection says so as it closes).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Cut {
    /// The live view is stopping.
    Stopping,
    /// Its queue had no room for a new channel's advertisement.
    NoRoomForChannel,
}

/// Connections closing at once that are given time to take their close
/// frame and close their side; beyond them a closing connection is dropped
/// at once, so strangers who get themselves cut and then hold the
/// connection cannot pile up sockets.
const CLOSING_PLACES: usize = 16;

/// Bad requests a client may send before it is disconnected.
const BAD_REQUESTS_ALLOWED: u64 = 32;

/// Totals since the live view started.
#[derive(Debug, Default)]
pub(super) struct Stats {
    /// Message-data frames queued for clients.
    pub(super) sent: AtomicU64,
    /// Frames dropped because a client's queue was full.
    pub(super) dropped: AtomicU64,
    /// Requests refused (unreadable, or not served).
    pub(super) bad_requests: AtomicU64,
    /// Connections refused (too many clients) or cut (too slow, too many
    /// bad requests).
    pub(super) refused: AtomicU64,
    /// Clients that connected.
    pub(super) clients: AtomicU64,
}

#[derive(Debug)]
struct Client {
    tx: mpsc::Sender<Out>,
    /// Channel id -> the client's subscription id.
    subs: HashMap<u32, u32>,
    dropped: u64,
    bad: u64,
}

#[derive(Debug, Default)]
struct Inner {
    channels: Vec<ChannelInfo>,
    by_topic: HashMap<String, u32>,
    clients: HashMap<u64, Client>,
    next_client: u64,
    /// Channel id -> how many clients subscribe to it.
    wanted: HashMap<u32, usize>,
    /// Clients let go of, until their connections ask why.
    cut: HashMap<u64, Cut>,
}

impl Inner {
    fn wants(&self, channel: u32) -> bool {
        self.wanted.get(&channel).is_some_and(|&n| n > 0)
    }
}

/// Channels and clients, shared by the source and the connections.
#[derive(Debug)]
pub(super) struct Hub {
    inner: Mutex<Inner>,
    pub(super) stats: Stats,
    client_queue: usize,
    max_clients: usize,
    session: String,
    /// Places for connections closing gracefully ([`CLOSING_PLACES`]).
    pub(super) closing: Semaphore,
}

/// Why a request was refused, for the client's status message.
pub(super) type Refusal = String;

impl Hub {
    pub(super) fn new(client_queue: usize, max_clients: usize) -> Hub {
        Hub {
            inner: Mutex::new(Inner::default()),
            stats: Stats::default(),
            client_queue,
            max_clients,
            session: mech_proto::unix_micros().to_string(),
            closing: Semaphore::new(CLOSING_PLACES),
        }
    }

    /// The channel on `topic` with the schema named `schema_name`, added
    /// (and advertised to every client) on first use.
    pub(super) fn channel(&self, topic: &str, schema_name: &'static str) -> u32 {
        let mut inner = lock(&self.inner);
        if let Some(&id) = inner.by_topic.get(topic) {
            return id;
        }
        let id = inner.channels.len() as u32 + 1;
        let info = ChannelInfo {
            id,
            topic: topic.to_string(),
            schema_name,
            schema: schema::schema(schema_name).to_string(),
        };
        let advert = protocol::advertise(std::slice::from_ref(&info));
        inner.channels.push(info);
        inner.by_topic.insert(topic.to_string(), id);
        let full: Vec<u64> = inner
            .clients
            .iter()
            .filter(|(_, c)| c.tx.try_send(Out::Text(advert.clone())).is_err())
            .map(|(id, _)| *id)
            .collect();
        for client in full {
            tracing::warn!(
                client,
                "Foxglove client too slow to take a new channel: cut"
            );
            self.stats.refused.fetch_add(1, Ordering::Relaxed);
            remove(&mut inner, client);
            inner.cut.insert(client, Cut::NoRoomForChannel);
        }
        id
    }

    /// A new client: its id and queue (server info and every channel
    /// already in it), or `None` when there are too many.
    pub(super) fn connect(&self) -> Option<(u64, mpsc::Receiver<Out>)> {
        let mut inner = lock(&self.inner);
        if inner.clients.len() >= self.max_clients {
            self.stats.refused.fetch_add(1, Ordering::Relaxed);
            return None;
        }
        let (tx, rx) = mpsc::channel(self.client_queue);
        // The queue is empty and holds at least 16 frames.
        let _ = tx.try_send(Out::Text(protocol::server_info(&self.session)));
        let _ = tx.try_send(Out::Text(protocol::advertise(&inner.channels)));
        inner.next_client += 1;
        let id = inner.next_client;
        let client = Client {
            tx,
            subs: HashMap::new(),
            dropped: 0,
            bad: 0,
        };
        inner.clients.insert(id, client);
        self.stats.clients.fetch_add(1, Ordering::Relaxed);
        Some((id, rx))
    }

    /// The client is gone: its subscriptions with it. Returns how many
    /// frames it lost to a full queue.
    pub(super) fn disconnect(&self, client: u64) -> u64 {
        let mut inner = lock(&self.inner);
        inner.cut.remove(&client);
        remove(&mut inner, client)
    }

    /// Why the hub let go of `client`, if it did.
    pub(super) fn cut(&self, client: u64) -> Option<Cut> {
        lock(&self.inner).cut.remove(&client)
    }

    /// Counts a bad message from `client` that ends its connection (one
    /// too big, or breaking the protocol): it is told why as it is closed.
    pub(super) fn count_bad(&self, client: u64) {
        self.stats.bad_requests.fetch_add(1, Ordering::Relaxed);
        self.stats.refused.fetch_add(1, Ordering::Relaxed);
        if let Some(c) = lock(&self.inner).clients.get_mut(&client) {
            c.bad += 1;
        }
    }

    /// Subscribes `client` to channels; what could not be done is refused.
    pub(super) fn subscribe(&self, client: u64, subs: &[Subscription]) -> Result<(), Refusal> {
        let mut inner = lock(&self.inner);
        let known = inner.channels.len() as u32;
        let Some(c) = inner.clients.get_mut(&client) else {
            return Ok(());
        };
        let mut added = Vec::new();
        let mut refused = Vec::new();
        for s in subs {
            if s.channel_id == 0 || s.channel_id > known {
                refused.push(format!("no channel {}", s.channel_id));
            } else if c.subs.values().any(|&id| id == s.id) {
                refused.push(format!("subscription {} is taken", s.id));
            } else if c.subs.insert(s.channel_id, s.id).is_none() {
                added.push(s.channel_id);
            }
        }
        for ch in added {
            *inner.wanted.entry(ch).or_insert(0) += 1;
        }
        if refused.is_empty() {
            Ok(())
        } else {
            Err(format!("subscribe: {}", refused.join(", ")))
        }
    }

    /// Ends `client`'s subscriptions with these ids (unknown ids ignored).
    pub(super) fn unsubscribe(&self, client: u64, ids: &[u32]) {
        let mut inner = lock(&self.inner);
        let Some(c) = inner.clients.get_mut(&client) else {
            return;
        };
        let gone: Vec<u32> = c
            .subs
            .iter()
            .filter(|(_, id)| ids.contains(id))
            .map(|(ch, _)| *ch)
            .collect();
        for ch in &gone {
            c.subs.remove(ch);
        }
        unwant(&mut inner, &gone);
    }

    /// Counts a bad request from `client` and tells it why (if its queue
    /// has room). `false`: it has sent too many and must be cut.
    pub(super) fn refuse(&self, client: u64, why: &str) -> bool {
        self.stats.bad_requests.fetch_add(1, Ordering::Relaxed);
        let mut inner = lock(&self.inner);
        let Some(c) = inner.clients.get_mut(&client) else {
            return false;
        };
        c.bad += 1;
        let _ =
            c.tx.try_send(Out::Text(protocol::status(Level::Warning, why)));
        if c.bad > BAD_REQUESTS_ALLOWED {
            self.stats.refused.fetch_add(1, Ordering::Relaxed);
            return false;
        }
        true
    }

    /// Whether any client subscribes to `channel`.
    pub(super) fn wants(&self, channel: u32) -> bool {
        lock(&self.inner)
            .wanted
            .get(&channel)
            .is_some_and(|&n| n > 0)
    }

    /// Sends a message on `channel` to every client subscribed to it,
    /// encoding it (`payload`) only if there is one.
    pub(super) fn publish(&self, channel: u32, unix_ns: u64, payload: impl FnOnce() -> Vec<u8>) {
        let mut inner = lock(&self.inner);
        if !inner.wants(channel) {
            return;
        }
        let payload = payload();
        for c in inner.clients.values_mut() {
            let Some(&sub) = c.subs.get(&channel) else {
                continue;
            };
            match c
                .tx
                .try_send(Out::Binary(protocol::data(sub, unix_ns, &payload)))
            {
                Ok(()) => self.stats.sent.fetch_add(1, Ordering::Relaxed),
                Err(_) => {
                    c.dropped += 1;
                    self.stats.dropped.fetch_add(1, Ordering::Relaxed)
                }
            };
        }
    }

    /// Clients connected now.
    pub(super) fn clients(&self) -> usize {
        lock(&self.inner).clients.len()
    }

    /// Lets go of every client: the live view is ending (their queues
    /// close, and their connections close saying so).
    pub(super) fn close_all(&self) {
        let mut inner = lock(&self.inner);
        let ids: Vec<u64> = inner.clients.keys().copied().collect();
        for id in ids {
            inner.cut.insert(id, Cut::Stopping);
        }
        inner.clients.clear();
        inner.wanted.clear();
    }
}

fn remove(inner: &mut Inner, client: u64) -> u64 {
    let Some(c) = inner.clients.remove(&client) else {
        return 0;
    };
    let channels: Vec<u32> = c.subs.keys().copied().collect();
    unwant(inner, &channels);
    c.dropped
}

fn unwant(inner: &mut Inner, channels: &[u32]) {
    for ch in channels {
        if let Some(n) = inner.wanted.get_mut(ch) {
            *n = n.saturating_sub(1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sub(id: u32, channel_id: u32) -> Subscription {
        Subscription { id, channel_id }
    }

    #[test]
    fn only_subscribers_get_a_channel_and_a_full_queue_drops_and_counts() {
        let hub = Hub::new(16, 2);
        let pose = hub.channel("/robots/a/pose", schema::POSE_IN_FRAME);
        let scene = hub.channel(schema::SCENE, schema::SCENE_UPDATE);
        let (a, mut rx) = hub.connect().unwrap();
        let (b, _rx_b) = hub.connect().unwrap();
        assert!(hub.connect().is_none(), "a third client is refused");
        // serverInfo, then both channels in one advertise.
        assert!(matches!(rx.try_recv(), Ok(Out::Text(t)) if t.contains("serverInfo")));
        assert!(matches!(rx.try_recv(), Ok(Out::Text(t)) if t.contains("/mech/scene")));
        assert!(!hub.wants(pose));
        hub.subscribe(a, &[sub(7, pose)]).unwrap();
        assert!(hub.subscribe(a, &[sub(7, scene), sub(8, 99)]).is_err());
        let mut encoded = 0;
        hub.publish(scene, 1, || {
            encoded += 1;
            vec![]
        });
        assert_eq!(encoded, 0, "nobody wants the scene: it is not even made");
        for _ in 0..20 {
            hub.publish(pose, 5, || b"{}".to_vec());
        }
        match rx.try_recv() {
            Ok(Out::Binary(f)) => assert_eq!(f, protocol::data(7, 5, b"{}")),
            other => panic!("{other:?}"),
        }
        assert_eq!(hub.stats.sent.load(Ordering::Relaxed), 16);
        assert_eq!(hub.stats.dropped.load(Ordering::Relaxed), 4);
        assert_eq!(hub.disconnect(a), 4);
        assert!(!hub.wants(pose));
        hub.unsubscribe(b, &[1, 2]);
        assert_eq!(hub.clients(), 1);
    }

    #[test]
    fn a_client_that_cannot_take_a_new_channel_or_keeps_erring_is_cut() {
        let hub = Hub::new(16, 4);
        let (slow, _rx) = hub.connect().unwrap();
        let first = hub.channel("/robots/a/pose", schema::POSE_IN_FRAME);
        hub.subscribe(slow, &[sub(1, first)]).unwrap();
        for _ in 0..20 {
            hub.publish(first, 1, || b"{}".to_vec());
        }
        hub.channel("/robots/b/pose", schema::POSE_IN_FRAME);
        assert_eq!(hub.clients(), 0);
        assert_eq!(hub.cut(slow), Some(Cut::NoRoomForChannel));
        assert_eq!(hub.cut(slow), None, "asked once");
        let (bad, _rx) = hub.connect().unwrap();
        let cut = (0..100).position(|_| !hub.refuse(bad, "no"));
        assert_eq!(cut, Some(BAD_REQUESTS_ALLOWED as usize));
    }
}
