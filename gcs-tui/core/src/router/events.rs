//! Events in the order the tables made them, delivered to the fleet model
//! and subscribers after the tables lock is released.
//!
//! A decision's events are stamped, offered to the recorder's tap and
//! appended to one queue while the deciding thread still holds the tables
//! lock: cheap (no sink, no subscriber), and in the tables' order whichever
//! thread decided. Once it has released the tables lock, the thread takes
//! the delivery lock and delivers what waits, in queue order, until its own
//! events are delivered: a thread that finds them delivered by another
//! returns at once. So the fleet model and every subscriber see events in
//! the tables' order (a mission is "sent" before its acknowledgement,
//! whichever UDP worker decided the acknowledgement), and when a call that
//! made events returns, the fleet model has applied them.
//!
//! Lock order: delivery, then tables, then queue. The sink runs holding the
//! delivery lock only: it may read the router (counters, channels) but must
//! not make it decide anything (that would wait for the delivery lock it
//! holds).

use std::sync::{Arc, Mutex};

use tokio::time::Instant;

use super::bus::EventBus;
use super::tables::tap::{Tap, Tapped};
use crate::event::{Event, Stamped};
use crate::sync::lock;

/// Where a thread's events stand in the queue: its last event's number. A
/// thread that made no event has none to wait for.
pub(super) type Ticket = Option<u64>;

/// The queue, between the tables and the delivery lock.
#[derive(Debug)]
pub(super) struct EventQueue {
    bus: EventBus,
    /// Appended to under the tables lock.
    queued: Mutex<Queued>,
    /// Held while delivering: how many events have been delivered, and a
    /// spare buffer the queue is swapped with (its allocation reused).
    delivering: Mutex<Delivered>,
}

#[derive(Debug, Default)]
struct Queued {
    events: Vec<Arc<Stamped>>,
    /// Events ever queued.
    count: u64,
}

#[derive(Debug, Default)]
struct Delivered {
    count: u64,
    spare: Vec<Arc<Stamped>>,
}

impl EventQueue {
    pub(super) fn new(bus: EventBus) -> EventQueue {
        EventQueue {
            bus,
            queued: Mutex::new(Queued::default()),
            delivering: Mutex::new(Delivered::default()),
        }
    }

    /// The subscribers' fan-out (and the router's start time).
    pub(super) fn bus(&self) -> &EventBus {
        &self.bus
    }

    /// Stamps `events` with the router time, offers each to `tap` (while
    /// recording) and queues them, leaving `events` empty. Called holding
    /// the tables lock, so the queue (and the recording) has events in the
    /// order the tables made them.
    pub(super) fn push(&self, tap: Option<&Tap>, events: &mut Vec<Event>) -> Ticket {
        if events.is_empty() {
            return None;
        }
        let at = self.bus.elapsed();
        let n = events.len() as u64;
        let mut q = lock(&self.queued);
        for event in events.drain(..) {
            let stamped = Arc::new(Stamped { at, event });
            if let Some(tap) = tap {
                tap.offer(Tapped::Event(stamped.clone()));
            }
            q.events.push(stamped);
        }
        q.count += n;
        Some(q.count)
    }

    /// Delivers every queued event up to `ticket` (and whatever else waits
    /// when it takes its turn), in queue order; returns once those are
    /// delivered, by this thread or another. Call without holding the
    /// tables lock.
    pub(super) fn deliver(&self, ticket: Ticket) {
        let Some(ticket) = ticket else { return };
        let mut d = lock(&self.delivering);
        while d.count < ticket {
            self.deliver_queued(&mut d);
        }
    }

    /// Delivers everything queued so far (at shutdown, and before a
    /// recording takes its first look at the fleet model). Returns the
    /// delivery lock, still held: nothing else is delivered until it is
    /// dropped.
    pub(super) fn deliver_all(&self) -> DeliveryTurn<'_> {
        let mut d = lock(&self.delivering);
        loop {
            let queued = lock(&self.queued).count;
            if d.count >= queued {
                return DeliveryTurn { _held: d };
            }
            self.deliver_queued(&mut d);
        }
    }

    /// Takes what is queued and delivers it, holding the delivery lock.
    fn deliver_queued(&self, d: &mut Delivered) {
        {
            let mut q = lock(&self.queued);
            std::mem::swap(&mut q.events, &mut d.spare);
        }
        for stamped in d.spare.drain(..) {
            self.bus.deliver(&stamped);
            d.count += 1;
        }
    }

    /// Queues `events` and delivers them at once: for a thread that holds
    /// no lock and taps nothing (the router starting).
    pub(super) fn emit(&self, mut events: Vec<Event>) {
        let ticket = self.push(None, &mut events);
        self.deliver(ticket);
    }

    /// The events queued and not yet delivered, in order (taken holding the
    /// tables lock and a [`DeliveryTurn`], so none is delivered or queued
    /// meanwhile).
    pub(super) fn waiting(&self, _turn: &DeliveryTurn<'_>) -> Vec<Arc<Stamped>> {
        lock(&self.queued).events.clone()
    }

    /// When the router started (router time 0).
    pub(super) fn start(&self) -> Instant {
        self.bus.start()
    }
}

/// The delivery lock, held: no event is delivered while it lives.
#[derive(Debug)]
pub(super) struct DeliveryTurn<'a> {
    _held: std::sync::MutexGuard<'a, Delivered>,
}
