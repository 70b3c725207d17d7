//! The recorder's tap on the router: every message the tables decide (its
//! bytes as received, where it came from, what was done with it and why),
//! every event they make and every operator command, in the order the
//! tables saw them, offered to a bounded queue without ever waiting. A full
//! queue drops the record and counts it: recording never slows routing.
//!
//! The tap only copies and queues; the writer (`crate::record`) encodes and
//! writes on a thread of its own.
//!
//! Refused messages (unreadable, rejected, shed) are copied whole up to
//! [`REFUSED_RECORDED_PER_SECOND`] a second; past that they are counted
//! ([`crate::RecordingStatus::refused_unrecorded`]) and the recording holds
//! them only in the `refused` events' counts. So a stranger's flood can
//! neither fill the station's disk nor push the fleet's own traffic out of
//! a rotating recording.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{SyncSender, TrySendError};
use std::time::Duration;

use tokio::time::Instant;

use super::{Delivery, Peer};
use crate::budget::PerSecond;
use crate::counters::DropReason;
use crate::event::Stamped;

/// Refused messages recorded whole in a second.
pub(crate) const REFUSED_RECORDED_PER_SECOND: u32 = 100;

/// One message as the router decided it.
#[derive(Debug, Clone)]
pub(crate) struct TappedMessage {
    /// Router time it was decided at.
    pub at: Duration,
    /// The router's count of received messages, this one included: the
    /// recording's messages are numbered as the router counts them.
    pub number: u64,
    /// Where it came from (`udp:ADDR`, `tcp#N`, `gcs`).
    pub from: Peer,
    pub bytes: Vec<u8>,
    pub delivery: Delivery,
    /// Why it was refused or could not be read, when it was.
    pub detail: Option<String>,
}

/// A command the operator gave (command line, script, key), and how it went.
#[derive(Debug, Clone, PartialEq)]
pub struct OperatorRecord {
    pub at: Duration,
    /// Where it was given: `script`, `tui`, `serve`...
    pub source: String,
    /// Script line number, when it came from a script (0 otherwise).
    pub line: usize,
    pub text: String,
    pub ok: bool,
    /// The command's one-line outcome, or its error.
    pub summary: String,
}

/// What the tap queues, in the order the router made it.
#[derive(Debug)]
pub(crate) enum Tapped {
    Message(TappedMessage),
    Event(Arc<Stamped>),
    Operator(OperatorRecord),
    /// Recording starts: the fleet model with every event made so far
    /// applied (taken while the router delivers no event; the events made
    /// meanwhile follow it, so no message or event falls between it and
    /// what follows) and the router time.
    Begin {
        at: Duration,
        fleet: Box<crate::fleet::Fleet>,
        /// The router's count of received messages then.
        received: u64,
    },
    /// Recording ends; the router's count of received messages then.
    End {
        received: u64,
    },
}

/// The tap as the tables hold it: on while recording, with why the message
/// being decided was refused (noted only while recording, for its record).
#[derive(Debug, Default)]
pub(crate) struct TapSlot {
    tap: Option<Tap>,
    refusal: Option<String>,
    /// Refused messages recorded whole this second.
    refused: PerSecond<REFUSED_RECORDED_PER_SECOND>,
}

impl TapSlot {
    pub(crate) fn get(&self) -> Option<&Tap> {
        self.tap.as_ref()
    }

    /// Puts `tap` on (or takes it off), returning the one that was on. A
    /// new recording starts with a whole second's budget.
    pub(crate) fn set(&mut self, tap: Option<Tap>) -> Option<Tap> {
        self.refused = PerSecond::default();
        std::mem::replace(&mut self.tap, tap)
    }

    /// Keeps why the message being decided at `now` was refused, while
    /// recording and while refused messages are still recorded whole this
    /// second (a flood costs no text past that).
    pub(crate) fn note_refusal(&mut self, now: Instant, why: impl FnOnce() -> String) {
        if self.tap.is_some() && !self.refused.spent(now) {
            self.refusal = Some(why());
        }
    }

    /// Why the message just decided was refused, if it was.
    pub(crate) fn take_refusal(&mut self) -> Option<String> {
        self.refusal.take()
    }

    /// The tap, if a message decided `delivery` at `now` is recorded: a
    /// refused one only within the second's [`REFUSED_RECORDED_PER_SECOND`]
    /// (the rest are counted).
    pub(crate) fn for_message(&mut self, delivery: Delivery, now: Instant) -> Option<&Tap> {
        let tap = self.tap.as_ref()?;
        let refused = matches!(
            delivery,
            Delivery::Dropped(DropReason::BadPacket | DropReason::Rejected | DropReason::Shed)
        );
        if refused && !self.refused.admit(now) {
            tap.counts.unrecorded.fetch_add(1, Ordering::Relaxed);
            return None;
        }
        Some(tap)
    }
}

/// What a recording's taps count, shared with the recorder.
#[derive(Debug, Clone, Default)]
pub(crate) struct TapCounts {
    /// Records the queue could not take.
    pub(crate) dropped: Arc<AtomicU64>,
    /// Records queued.
    pub(crate) queued: Arc<AtomicU64>,
    /// Refused messages not recorded (see the module docs).
    pub(crate) unrecorded: Arc<AtomicU64>,
}

/// The sending end, held by the router's tables while recording.
#[derive(Debug, Clone)]
pub(crate) struct Tap {
    tx: SyncSender<Tapped>,
    /// Router start, for message times.
    start: Instant,
    counts: TapCounts,
}

impl Tap {
    /// A tap onto `tx`, counting into `counts`: records dropped, queued,
    /// and refused messages not recorded.
    pub(crate) fn new(tx: SyncSender<Tapped>, start: Instant, counts: &TapCounts) -> Tap {
        Tap {
            tx,
            start,
            counts: counts.clone(),
        }
    }

    /// Offers `t` to the queue; a full (or closed) queue drops and counts it.
    pub(crate) fn offer(&self, t: Tapped) {
        match self.tx.try_send(t) {
            Ok(()) => {
                self.counts.queued.fetch_add(1, Ordering::Relaxed);
            }
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                self.counts.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }

    /// Router time of `now`.
    pub(crate) fn at(&self, now: Instant) -> Duration {
        now.saturating_duration_since(self.start)
    }

    /// Queues a copy of a decided message.
    pub(crate) fn message(&self, m: MessageTap<'_>) {
        self.offer(Tapped::Message(TappedMessage {
            at: self.at(m.now),
            number: m.number,
            from: m.from,
            bytes: m.bytes.to_vec(),
            delivery: m.delivery,
            detail: m.detail,
        }));
    }
}

/// A decided message, as [`Tap::message`] takes it.
#[derive(Debug)]
pub(crate) struct MessageTap<'a> {
    pub(crate) now: Instant,
    pub(crate) number: u64,
    pub(crate) from: Peer,
    pub(crate) bytes: &'a [u8],
    pub(crate) delivery: Delivery,
    pub(crate) detail: Option<String>,
}
