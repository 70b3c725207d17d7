//! Counting a wheel encoder's edges from its pin changes, whatever reports
//! them (GPIO interrupts on a Pi: [`crate::drivers::rpi`]; a test's script).
//!
//! A quadrature encoder has two channels 90 degrees apart; each edge of
//! either moves the count one step up or down, by the Gray-code order of
//! the pair (A, B): forward is 00 -> 10 -> 11 -> 01 -> 00 (A leads B).
//! Each report names one channel and its new level, so a report of the level
//! the channel already had means its opposite edge was missed (an interrupt
//! lost): for a quadrature encoder the direction of the missed step is
//! unknown, so it is counted as an error, not guessed; a single-channel
//! encoder counts every edge of A up, so the missed edge and this one count
//! two.

use std::time::Duration;

use serde::Deserialize;

use crate::hal::{Counting, EdgeCount};

/// One wheel's encoder pins (BCM GPIO numbers), from `[encoders] channels`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EncoderPins {
    /// Channel A.
    pub a: u8,
    /// Channel B (quadrature encoders only).
    #[serde(default)]
    pub b: Option<u8>,
}

/// Which channel changed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Channel {
    A,
    B,
}

/// One wheel's count, fed with each pin change.
#[derive(Debug, Clone, PartialEq)]
pub struct EdgeCounter {
    counting: Counting,
    a: bool,
    b: bool,
    count: EdgeCount,
    /// Reports that reveal a missed edge.
    pub missed: u64,
}

impl EdgeCounter {
    /// A counter whose channels read `a` and `b` now.
    pub fn new(counting: Counting, a: bool, b: bool) -> EdgeCounter {
        EdgeCounter {
            counting,
            a,
            b,
            count: EdgeCount::default(),
            missed: 0,
        }
    }

    pub fn count(&self) -> EdgeCount {
        self.count
    }

    /// `channel` has just changed to `level`, at agent time `at`.
    pub fn edge(&mut self, channel: Channel, level: bool, at: Duration) {
        let (old_a, old_b) = (self.a, self.b);
        let same = match channel {
            Channel::A => std::mem::replace(&mut self.a, level) == level,
            Channel::B => std::mem::replace(&mut self.b, level) == level,
        };
        let step = match (self.counting, channel) {
            (Counting::SingleChannel, Channel::B) => return,
            (Counting::SingleChannel, Channel::A) if same => {
                self.missed += 1;
                2
            }
            (Counting::SingleChannel, Channel::A) => 1,
            (Counting::Quadrature, _) if same => {
                self.missed += 1;
                return;
            }
            (Counting::Quadrature, _) => gray_step(phase(old_a, old_b), phase(self.a, self.b)),
        };
        self.count.edges += step;
        self.count.last_edge = Some(at);
    }
}

/// Position of (A, B) in the forward cycle 00, 10, 11, 01.
fn phase(a: bool, b: bool) -> i8 {
    match (a, b) {
        (false, false) => 0,
        (true, false) => 1,
        (true, true) => 2,
        (false, true) => 3,
    }
}

/// +1 one step forward, -1 one step back (one channel changes at a time,
/// so the phase moves by one).
fn gray_step(from: i8, to: i8) -> i64 {
    if (to - from).rem_euclid(4) == 1 {
        1
    } else {
        -1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds the (A, B) levels in order, one per millisecond, changing one
    /// channel at a time as a real encoder does.
    fn feed(counter: &mut EdgeCounter, levels: &[(bool, bool)]) {
        for (i, &(a, b)) in levels.iter().enumerate() {
            let at = Duration::from_millis(i as u64 + 1);
            let (old_a, _) = (counter.a, counter.b);
            if a != old_a {
                counter.edge(Channel::A, a, at);
            }
            if b != counter.b {
                counter.edge(Channel::B, b, at);
            }
        }
    }

    const FORWARD: [(bool, bool); 4] = [(true, false), (true, true), (false, true), (false, false)];

    #[test]
    fn quadrature_counts_four_edges_per_cycle_with_direction() {
        let mut c = EdgeCounter::new(Counting::Quadrature, false, false);
        feed(&mut c, &FORWARD.repeat(3));
        assert_eq!(c.count().edges, 12);
        assert_eq!(c.count().last_edge, Some(Duration::from_millis(12)));
        let mut backward = FORWARD.to_vec();
        backward.reverse();
        let backward: Vec<_> = backward[1..]
            .iter()
            .copied()
            .chain([(false, false)])
            .collect();
        feed(&mut c, &backward);
        assert_eq!(c.count().edges, 8);
        assert_eq!(c.missed, 0);
    }

    #[test]
    fn a_missed_edge_is_counted_as_missed_not_guessed() {
        let ms = Duration::from_millis;
        let mut c = EdgeCounter::new(Counting::Quadrature, false, false);
        c.edge(Channel::A, true, ms(1));
        assert_eq!(c.count().edges, 1);
        // A rises again: its fall (and whatever B did meanwhile) was lost.
        c.edge(Channel::A, true, ms(2));
        assert_eq!((c.count().edges, c.missed), (1, 1));
        assert_eq!(c.count().last_edge, Some(ms(1)));
    }

    #[test]
    fn single_channel_counts_every_edge_of_a_up_and_ignores_b() {
        let ms = Duration::from_millis;
        let mut c = EdgeCounter::new(Counting::SingleChannel, false, false);
        for i in 0..10u64 {
            c.edge(Channel::A, i % 2 == 0, ms(i));
            c.edge(Channel::B, i % 2 == 1, ms(i));
        }
        assert_eq!(c.count().edges, 10);
        // A rising twice in a row: the fall between was missed, two edges.
        c.edge(Channel::A, true, ms(20));
        c.edge(Channel::A, true, ms(21));
        assert_eq!((c.count().edges, c.missed), (13, 1));
    }
}
