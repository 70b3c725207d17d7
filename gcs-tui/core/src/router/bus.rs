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

    /// Delivers `stamped` to the sink, then to every subscriber that
    /// wants it.
    pub(crate) fn deliver(&self, stamped: &Arc<Stamped>) {
        self.sink.apply(stamped);
        // Periodic reports, per robot many times a second or every second:
        // only for subscribers that asked for them.
        let periodic = matches!(
            stamped.event,
            Event::Telemetry { .. } | Event::LinkQuality { .. }
        );
        let mut subs = lock(&self.subscribers);
        subs.retain(|s| {
            if periodic && !s.telemetry {
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
    }

    /// Closes every subscription (after shutdown, `recv` returns `None`).
    pub(crate) fn close(&self) {
        lock(&self.subscribers).clear();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::counters::LinkQuality;

    #[derive(Debug)]
    struct Nowhere;

    impl EventSink for Nowhere {
        fn apply(&self, _: &Stamped) {}
    }

    #[tokio::test]
    async fn periodic_reports_reach_only_subscribers_that_asked_for_them() {
        let bus = EventBus::new(Instant::now(), Arc::new(Nowhere));
        let mut plain = bus.subscribe(8, false);
        let mut all = bus.subscribe(8, true);
        let stamped = |event| {
            Arc::new(Stamped {
                at: Duration::ZERO,
                event,
            })
        };
        bus.deliver(&stamped(Event::LinkQuality {
            robot: "robot_1".into(),
            quality: LinkQuality::default(),
        }));
        bus.deliver(&stamped(Event::Bye {
            robot: "robot_1".into(),
            reason: "done".into(),
        }));
        let bye = |e: Option<Arc<Stamped>>| e.is_some_and(|e| matches!(e.event, Event::Bye { .. }));
        assert!(bye(plain.try_recv()));
        assert!(matches!(
            all.try_recv().map(|e| e.event.clone()),
            Some(Event::LinkQuality { .. })
        ));
        assert!(bye(all.try_recv()));
    }
}
