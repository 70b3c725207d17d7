//! Link quality per robot, measured from traffic the router handles anyway:
//! messages per second each way, the robot's loss from the gaps in its
//! envelope sequence numbers, and the round-trip time from the echo of the
//! router's heartbeat in the robot's own. Counting is a few integer
//! operations per message under the tables' lock, in fixed-size state: no
//! allocation per datagram. Every second each robot's figures over the
//! last [`STEPS`] seconds go out as an [`Event::LinkQuality`].

use std::time::Duration;

use mech_proto::{Echo, Heartbeat};
use tokio::time::Instant;

use super::{Ctx, Delivery, Incoming, Tables};
use crate::counters::LinkQuality;
use crate::event::Event;

/// How often a robot's figures are closed and reported.
const STEP: Duration = Duration::from_secs(1);
/// Steps the reported figures cover: long enough that a loss of a fifth at
/// 20 Hz reads within a few points, short enough to follow a change.
const STEPS: usize = 5;
/// Router heartbeats remembered per robot, for matching echoes (two
/// seconds of them at the default period).
const BEATS: usize = 8;
/// A sequence number this far ahead of (or behind) the newest is taken as
/// the robot numbering afresh (a restart the router missed), not as
/// thousands of lost messages.
const MAX_GAP: u32 = 4096;

/// Counts of one step.
#[derive(Debug, Clone, Copy, Default)]
struct Step {
    span: Duration,
    received: u64,
    /// Messages the robot sent, as its sequence numbers tell.
    expected: u64,
    sent: u64,
    rtt_total: Duration,
    rtt_samples: u32,
}

/// One robot's link measurement.
#[derive(Debug, Clone)]
pub(super) struct LinkMeter {
    open: Step,
    opened: Instant,
    /// The last closed steps, a ring.
    closed: [Step; STEPS],
    next_step: usize,
    /// Newest sequence number received from the robot.
    newest: Option<u32>,
    /// The router heartbeats most recently sent to the robot (their `seq`
    /// and when), a ring: an echo names one of them.
    beats: [Option<(u32, Instant)>; BEATS],
    next_beat: usize,
    received: u64,
    expected: u64,
    sent: u64,
}

impl LinkMeter {
    pub(super) fn new(now: Instant) -> LinkMeter {
        LinkMeter {
            open: Step::default(),
            opened: now,
            closed: [Step::default(); STEPS],
            next_step: 0,
            newest: None,
            beats: [None; BEATS],
            next_beat: 0,
            received: 0,
            expected: 0,
            sent: 0,
        }
    }

    /// A message from the robot, numbered `seq`. A number ahead of the
    /// newest by n means n - 1 lost on the way; one behind is a late
    /// arrival (or a repeat), counted as received but not expected again.
    pub(super) fn received(&mut self, seq: u32) {
        self.open.received += 1;
        self.received += 1;
        let expected = match self.newest {
            None => 1,
            Some(newest) => {
                let ahead = seq.wrapping_sub(newest);
                if ahead != 0 && ahead <= MAX_GAP {
                    ahead
                } else if newest.wrapping_sub(seq) <= MAX_GAP {
                    0
                } else {
                    1
                }
            }
        };
        if expected > 0 {
            self.newest = Some(seq);
            self.open.expected += u64::from(expected);
            self.expected += u64::from(expected);
        }
    }

    /// The robot registered again (it restarted, or lost the router): it
    /// numbers its messages afresh from `seq`.
    pub(super) fn renumbered(&mut self, seq: u32) {
        self.newest = Some(seq);
    }

    /// A message sent to the robot.
    pub(super) fn sent(&mut self) {
        self.open.sent += 1;
        self.sent += 1;
    }

    /// The router's heartbeat numbered `seq` went to the robot at `now`.
    pub(super) fn beat_sent(&mut self, seq: u32, now: Instant) {
        self.beats[self.next_beat] = Some((seq, now));
        self.next_beat = (self.next_beat + 1) % BEATS;
    }

    /// The robot echoed one of the router's heartbeats: the round trip is
    /// from sending it to now, less the time the robot held it. An echo of
    /// a heartbeat no longer remembered (or already echoed) is ignored.
    pub(super) fn echoed(&mut self, echo: Echo, now: Instant) {
        let Some(slot) = self
            .beats
            .iter_mut()
            .find(|b| b.is_some_and(|(seq, _)| seq == echo.seq))
        else {
            return;
        };
        let Some((_, sent_at)) = slot.take() else {
            return;
        };
        let held = Duration::from_micros(echo.held_us);
        let rtt = now.saturating_duration_since(sent_at).saturating_sub(held);
        self.open.rtt_total += rtt;
        self.open.rtt_samples += 1;
    }

    /// Closes the open step once it is [`STEP`] old, and returns the
    /// figures over the closed steps.
    pub(super) fn roll(&mut self, now: Instant) -> Option<LinkQuality> {
        let span = now.saturating_duration_since(self.opened);
        if span < STEP {
            return None;
        }
        self.open.span = span;
        self.closed[self.next_step] = std::mem::take(&mut self.open);
        self.next_step = (self.next_step + 1) % STEPS;
        self.opened = now;
        Some(self.quality())
    }

    /// The figures over the closed steps, and the totals.
    pub(super) fn quality(&self) -> LinkQuality {
        let mut sum = Step::default();
        for s in &self.closed {
            sum.span += s.span;
            sum.received += s.received;
            sum.expected += s.expected;
            sum.sent += s.sent;
            sum.rtt_total += s.rtt_total;
            sum.rtt_samples += s.rtt_samples;
        }
        let secs = sum.span.as_secs_f64();
        let per_second = |n: u64| if secs > 0.0 { n as f64 / secs } else { 0.0 };
        LinkQuality {
            rx_hz: per_second(sum.received),
            tx_hz: per_second(sum.sent),
            loss: (sum.expected > 0)
                .then(|| sum.expected.saturating_sub(sum.received) as f64 / sum.expected as f64),
            rtt: (sum.rtt_samples > 0).then(|| sum.rtt_total / sum.rtt_samples),
            window: sum.span,
            received: self.received,
            sent: self.sent,
            lost: self.expected.saturating_sub(self.received),
        }
    }
}

impl Tables {
    /// A heartbeat: liveness was noted on the way in; an echo times the
    /// round trip. An unknown robot is told to register again.
    pub(super) fn on_heartbeat(
        &mut self,
        m: Incoming<'_>,
        hb: Heartbeat,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        match self.robots.get_mut(&m.header.sender) {
            Some(r) => {
                if let Some(echo) = hb.echo {
                    r.meter.echoed(echo, cx.now);
                }
            }
            None => self.unknown_robot(m, cx),
        }
        Delivery::Consumed
    }

    /// Counts a message sent to `robot` (no-op for other receivers).
    pub(super) fn count_sent(&mut self, robot: &str) {
        if let Some(r) = self.robots.get_mut(robot) {
            r.meter.sent();
        }
    }

    /// Closes each robot's step once a second and reports its figures.
    pub(super) fn roll_link_quality(&mut self, cx: &mut Ctx<'_>) {
        for (name, r) in self.robots.iter_mut() {
            if let Some(quality) = r.meter.roll(cx.now) {
                cx.event(Event::LinkQuality {
                    robot: name.clone(),
                    quality,
                });
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn after(t0: Instant, ms: u64) -> Instant {
        t0 + Duration::from_millis(ms)
    }

    #[test]
    fn loss_is_read_from_the_gaps_in_the_sequence() {
        let t0 = Instant::now();
        let mut m = LinkMeter::new(t0);
        // 100 messages numbered from u32::MAX - 10 (the count wraps), every
        // fifth lost, one arriving late and one twice.
        let mut seqs: Vec<u32> = (0..100u32)
            .filter(|k| k % 5 != 2)
            .map(|k| (u32::MAX - 10).wrapping_add(k))
            .collect();
        seqs.swap(10, 11);
        seqs.push(seqs[20]);
        for s in seqs {
            m.received(s);
        }
        let q = m.roll(after(t0, 1000)).expect("a second passed");
        // 81 received (80 + a repeat) of 100 sent.
        assert_eq!((q.received, q.lost), (81, 19));
        let loss = q.loss.expect("measured");
        assert!((loss - 0.19).abs() < 1e-9, "{loss}");
        assert!((q.rx_hz - 81.0).abs() < 1e-9);
    }

    #[test]
    fn a_late_message_is_not_a_loss_and_a_big_jump_is_a_restart() {
        let t0 = Instant::now();
        let mut m = LinkMeter::new(t0);
        for s in [1, 2, 4, 3, 5] {
            m.received(s);
        }
        m.received(900_000); // numbering afresh, not 900k lost
        m.received(900_001);
        let q = m.roll(after(t0, 1000)).unwrap();
        assert_eq!(q.loss, Some(0.0));
        assert_eq!(q.lost, 0);
    }

    #[test]
    fn rates_each_way_cover_the_last_five_seconds() {
        let t0 = Instant::now();
        let mut m = LinkMeter::new(t0);
        let mut seq = 0;
        for second in 0..8u64 {
            for _ in 0..20 {
                seq += 1;
                m.received(seq);
            }
            for _ in 0..4 {
                m.sent();
            }
            let q = m.roll(after(t0, 1000 * (second + 1))).unwrap();
            assert!((q.rx_hz - 20.0).abs() < 1e-9, "{q:?}");
            assert!((q.tx_hz - 4.0).abs() < 1e-9, "{q:?}");
            let covered = Duration::from_secs((second + 1).min(STEPS as u64));
            assert_eq!(q.window, covered);
        }
        assert!(m.roll(after(t0, 8500)).is_none(), "not a second yet");
    }

    #[test]
    fn the_round_trip_is_timed_from_the_echoed_heartbeat_less_the_hold() {
        let t0 = Instant::now();
        let mut m = LinkMeter::new(t0);
        m.beat_sent(7, after(t0, 0));
        m.beat_sent(8, after(t0, 250));
        // Echo of heartbeat 8, held 600 ms, back 603 ms after it left.
        let echo = |seq| Echo {
            seq,
            held_us: 600_000,
        };
        m.echoed(echo(8), after(t0, 853));
        m.echoed(echo(8), after(t0, 900)); // again: ignored
        m.echoed(echo(99), after(t0, 900)); // never sent: ignored
        let q = m.roll(after(t0, 1000)).unwrap();
        assert_eq!(q.rtt, Some(Duration::from_millis(3)));
        let q = m.roll(after(t0, 2000)).unwrap();
        assert_eq!(q.rtt, Some(Duration::from_millis(3)), "still in the window");
    }

    #[test]
    fn a_quiet_robot_has_no_loss_figure() {
        let t0 = Instant::now();
        let mut m = LinkMeter::new(t0);
        let q = m.roll(after(t0, 1000)).unwrap();
        assert_eq!((q.loss, q.rtt, q.rx_hz), (None, None, 0.0));
    }
}
