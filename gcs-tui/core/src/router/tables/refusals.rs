//! What operators are told about traffic the router refused (datagrams it
//! could not read, messages the gate rejected, datagrams shed unread):
//! every one is counted (`crate::counters`), but reported as counted
//! summaries, never one event per datagram. After a second without a
//! report, the next refusal is reported at once, with its source and
//! detail ([`Event::BadPacket`], [`Event::Rejected`]); the ones after it
//! are counted by reason and reported together once a second
//! ([`Event::Refused`]), with the number of distinct sources and one
//! example. So a flood, from however many sources (spoofed ones
//! included), reaches the event log, the log file and attached operators
//! as at most two lines a second.
//!
//! [`Refusals`] owns the counts since the last report; the router's timer
//! calls [`Refusals::due`].

use std::collections::{BTreeMap, HashSet};
use std::time::Duration;

use tokio::time::Instant;
use tracing::warn;

use super::Peer;
use crate::counters::{DropReason, RejectReason};
use crate::event::{Event, REFUSED_SOURCES_COUNTED as SOURCES_COUNTED};

/// The shortest time between two reports.
pub(super) const REPORT_EVERY: Duration = Duration::from_secs(1);

/// Why a message was refused, as reported.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Why {
    /// It could not be read (or was not a message the router takes).
    BadPacket,
    /// The gate refused it.
    Rejected(RejectReason),
    /// Shed unread: the router was behind and its source kept failing.
    Shed,
}

impl Why {
    /// The reason's name: the drop reason's, or the gate's rejection's.
    fn as_str(self) -> &'static str {
        match self {
            Why::BadPacket => DropReason::BadPacket.as_str(),
            Why::Rejected(r) => r.as_str(),
            Why::Shed => DropReason::Shed.as_str(),
        }
    }
}

/// Where a refused message came from: a peer, or a name given by a part
/// of the station that carries messages from beyond it (a bridge).
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub(super) enum Source {
    Peer(Peer),
    Named(String),
}

impl std::fmt::Display for Source {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Source::Peer(p) => p.fmt(f),
            Source::Named(n) => f.write_str(n),
        }
    }
}

/// Refusals since the last report.
#[derive(Debug, Default)]
pub(super) struct Refusals {
    reported_at: Option<Instant>,
    by_reason: BTreeMap<&'static str, u64>,
    count: u64,
    sources: HashSet<Source>,
    /// The first refusal counted since the last report: its source and
    /// why.
    example: Option<(String, String)>,
}

impl Refusals {
    /// Notes a refusal of a message from `from` at `now`; `detail` says
    /// why (made only when it is reported). Returns the event to report
    /// now: the first refusal after a second without a report.
    pub(super) fn note(
        &mut self,
        why: Why,
        from: Source,
        detail: impl FnOnce() -> String,
        now: Instant,
    ) -> Option<Event> {
        let quiet = self.count == 0
            && self
                .reported_at
                .is_none_or(|t| now.saturating_duration_since(t) >= REPORT_EVERY);
        if quiet {
            self.reported_at = Some(now);
            let (from, detail) = (from.to_string(), detail());
            warn!(%from, reason = why.as_str(), "refused: {detail}");
            return Some(match why {
                Why::Rejected(reason) => Event::Rejected {
                    from,
                    reason,
                    detail,
                },
                Why::BadPacket | Why::Shed => Event::BadPacket {
                    from,
                    error: detail,
                },
            });
        }
        self.count += 1;
        *self.by_reason.entry(why.as_str()).or_default() += 1;
        if self.example.is_none() {
            self.example = Some((from.to_string(), detail()));
        }
        if self.sources.len() < SOURCES_COUNTED {
            self.sources.insert(from);
        }
        None
    }

    /// The summary of what was refused since the last report, once a
    /// second while there is any.
    pub(super) fn due(&mut self, now: Instant) -> Option<Event> {
        if self.count == 0 {
            return None;
        }
        if self
            .reported_at
            .is_some_and(|t| now.saturating_duration_since(t) < REPORT_EVERY)
        {
            return None;
        }
        self.reported_at = Some(now);
        let (from, detail) = self.example.take().unwrap_or_default();
        let by_reason = std::mem::take(&mut self.by_reason);
        let count = std::mem::take(&mut self.count);
        let sources = self.sources.len() as u64;
        self.sources.clear();
        let reasons: Vec<String> = by_reason.iter().map(|(r, n)| format!("{n} {r}")).collect();
        warn!(
            count,
            sources,
            reasons = %reasons.join(", "),
            "refused in the last second; e.g. from {from}: {detail}"
        );
        Some(Event::Refused {
            count,
            sources,
            by_reason: by_reason
                .into_iter()
                .map(|(r, n)| (r.to_string(), n))
                .collect(),
            from,
            detail,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn udp(port: u16) -> Source {
        Source::Peer(Peer::Udp(([127, 0, 0, 1], port).into()))
    }

    /// 200,000 refusals from 3,000 source ports over ten seconds, noted on
    /// a 20 ms timer: the first is reported at once, the rest as one
    /// summary a second, every refusal counted in exactly one report.
    #[test]
    fn a_flood_from_thousands_of_sources_is_one_report_a_second() {
        let t0 = Instant::now();
        let mut r = Refusals::default();
        let mut events = Vec::new();
        let mut details = 0;
        for i in 0..200_000u64 {
            let now = t0 + Duration::from_micros(i * 50);
            let why = if i % 2 == 0 {
                Why::BadPacket
            } else {
                Why::Rejected(RejectReason::BadTag)
            };
            let detail = || {
                details += 1;
                "x".to_string()
            };
            events.extend(r.note(why, udp((i % 3000) as u16), detail, now));
            if i % 400 == 0 {
                events.extend(r.due(now));
            }
        }
        events.extend(r.due(t0 + Duration::from_secs(11)));
        assert!(
            matches!(events[0], Event::BadPacket { .. }),
            "{:?}",
            events[0]
        );
        assert!(events.len() <= 12, "{} reports", events.len());
        let summed: u64 = events
            .iter()
            .map(|e| match e {
                Event::Refused {
                    count, by_reason, ..
                } => {
                    assert_eq!(*count, by_reason.values().sum::<u64>());
                    *count
                }
                _ => 1,
            })
            .sum();
        assert_eq!(summed, 200_000);
        let Event::Refused {
            sources, by_reason, ..
        } = &events[1]
        else {
            panic!("{:?}", events[1]);
        };
        assert_eq!(*sources, 3000);
        assert_eq!(by_reason.len(), 2);
        // Details are made only for what is reported.
        assert!(details <= 2 * events.len(), "{details} details made");
    }

    #[test]
    fn after_a_quiet_second_the_next_refusal_is_reported_at_once() {
        let t0 = Instant::now();
        let mut r = Refusals::default();
        let why = Why::Rejected(RejectReason::Replay);
        assert!(r.note(why, udp(1), String::new, t0).is_some());
        assert!(r.note(why, udp(1), String::new, t0).is_none());
        assert!(r.due(t0 + Duration::from_millis(999)).is_none());
        assert!(r.due(t0 + REPORT_EVERY).is_some());
        assert!(r.due(t0 + Duration::from_secs(3)).is_none(), "nothing left");
        let later = t0 + Duration::from_millis(2_500);
        assert!(r.note(why, udp(1), String::new, later).is_some());
    }
}
