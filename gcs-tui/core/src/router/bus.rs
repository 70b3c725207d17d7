//! Fan-out of router events: the [`EventSink`] (the fleet model) is updated
//! synchronously (it must never miss a route or link change), then each
//! subscriber's bounded queue is offered the event without waiting; a full
//! queue drops (and counts) that subscriber's copy rather than block the
//! routing path.

use std::sync::Arc;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use tokio::sync::mpsc;
use tokio::time::Instant;

use crate::event::{Event, EventSink, Stamped};
use crate::sync::lock;

/// A subscriber's end: a bounded queue of events. When the subscriber falls
/// behind, new events for it are dropped and counted in [`Subscription::dropped`];
/// the router and other subscribers are not slowed.
#[derive(Debug)]
pub struct Subscription {
    rx: mpsc::Receiver<Arc<Stamped>>,
    dropped: Arc<AtomicU64>,
}

impl Subscription {
    /// The next event, or `None` once the router has shut down.
    pub async fn recv(&mut self) -> Option<Arc<Stamped>> {
        self.rx.recv().await
    }

    /// The next event if one is queued.
    pub fn try_recv(&mut self) -> Option<Arc<Stamped>> {
        self.rx.try_recv().ok()
    }

    /// Events dropped because this subscriber's queue was full.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }
}

#[derive(Debug)]
struct Subscriber {
    tx: mpsc::Sender<Arc<Stamped>>,
    dropped: Arc<AtomicU64>,
    telemetry: bool,
}

/// Fan-out of router events: the fleet model is updated synchronously (it
/// must never miss a route or link change), then each subscriber's queue is
/// offered the event without waiting.
#[derive(Debug)]
pub(crate) struct EventBus {
    start: Instant,
    sink: Arc<dyn EventSink>,
    subscribers: Mutex<Vec<Subscriber>>,
}

impl EventBus {
    pub(crate) fn new(start: Instant, sink: Arc<dyn EventSink>) -> EventBus {
        EventBus {
            start,
            sink,
            subscribers: Mutex::new(Vec::new()),
        }
    }

    pub(crate) fn subscribe(&self, capacity: usize, telemetry: bool) -> Subscription {
        let (tx, rx) = mpsc::channel(capacity.max(1));
        let dropped = Arc::new(AtomicU64::new(0));
        lock(&self.subscribers).push(Subscriber {
            tx,
            dropped: dropped.clone(),
            telemetry,
        });
        Subscription { rx, dropped }
    }

    /// When the router started.
    pub(crate) fn start(&self) -> Instant {
        self.start
    }

    /// Time since the router started.
    pub(crate) fn elapsed(&self) -> Duration {
        Instant::now().saturating_duration_since(self.start)
    }

    /// Delivers `event` and returns it stamped.
    pub(crate) fn emit(&self, event: Event) -> Arc<Stamped> {
        let stamped = Arc::new(Stamped {
            at: self.elapsed(),
            event,
        });
        self.sink.apply(&stamped);
        let is_telemetry = matches!(stamped.event, Event::Telemetry { .. });
        let mut subs = lock(&self.subscribers);
        subs.retain(|s| {
            if is_telemetry && !s.telemetry {
                return true;
            }
            match s.tx.try_send(stamped.clone()) {
                Ok(()) => true,
                Err(mpsc::error::TrySendError::Full(_)) => {
                    s.dropped.fetch_add(1, Ordering::Relaxed);
                    true
                }
                Err(mpsc::error::TrySendError::Closed(_)) => false,
            }
        });
        drop(subs);
        stamped
    }

    /// Closes every subscription (after shutdown, `recv` returns `None`).
    pub(crate) fn close(&self) {
        lock(&self.subscribers).clear();
    }
}
