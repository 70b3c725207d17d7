//! [`Step`]: what every part of the core is handed while it handles one
//! message or runs one control period.

use std::time::Duration;

use mech_proto::{Body, Envelope, Level, NoticeCode};

use super::counters::Counters;
use super::wire::Wire;

/// One message being handled, or one period being run: the time, the
/// agent's counters, and the replies so far (numbered and stamped by the
/// wire).
#[derive(Debug)]
pub(crate) struct Step<'a> {
    pub(crate) now: Duration,
    pub(crate) wire: &'a mut Wire,
    pub(crate) counters: &'a mut Counters,
    pub(crate) out: &'a mut Vec<Envelope>,
}

impl<'a> Step<'a> {
    pub(crate) fn new(
        now: Duration,
        wire: &'a mut Wire,
        counters: &'a mut Counters,
        out: &'a mut Vec<Envelope>,
    ) -> Step<'a> {
        Step {
            now,
            wire,
            counters,
            out,
        }
    }

    /// This robot's name.
    pub(crate) fn robot(&self) -> &str {
        self.wire.name()
    }

    /// The robot's clock now, µs since the Unix epoch.
    pub(crate) fn stamp_us(&self) -> u64 {
        self.wire.stamp_us(self.now)
    }

    /// Sends `body` to `destination`.
    pub(crate) fn send(&mut self, destination: &str, body: Body) {
        let env = self.wire.envelope(destination, body, self.now);
        self.out.push(env);
    }

    /// Sends a notice (free text cut to the protocol's limit).
    pub(crate) fn notice(&mut self, destination: &str, level: Level, code: NoticeCode, text: &str) {
        let env = self.wire.notice(destination, level, code, text, self.now);
        self.out.push(env);
    }
}
