//! Link failover for a robot with several links to the router (Wi-Fi and a
//! radio, say), with no sockets or clocks: the runtime tells it when the
//! router was heard on which link, and asks which links to send on.
//!
//! A link is alive while the router was heard on it within the link
//! timeout (the router's heartbeat comes every 0.25 s on each link). The
//! robot sends on the first live link in its configured order, so it
//! returns to Wi-Fi as soon as Wi-Fi is heard again; with no live link it
//! sends on every link, so whichever works carries its Hello. Every
//! `probe_period` it sends a heartbeat on each link it is not using, so the
//! router knows that link is there (and fails over to it when the one in
//! use goes silent). A radio link may cap the telemetry rate sent on it.

use std::time::Duration;

/// Which link to use, from when the router was last heard on each.
#[derive(Debug, Clone)]
pub struct LinkChoice {
    heard: Vec<Option<Duration>>,
    timeout: Duration,
    probe_period: Duration,
    next_probe: Duration,
    /// Shortest time between two telemetry messages on each link.
    telemetry_gap: Vec<Option<Duration>>,
    last_telemetry: Vec<Option<Duration>>,
    /// The link in use at the last [`LinkChoice::targets`], to log changes.
    in_use: Option<usize>,
    /// Links whose port is down (reported by their threads, until they say
    /// it is open again): nothing is sent on them, not even a probe, since
    /// it would only be dropped, a numbered message the router counts lost.
    port_down: Vec<bool>,
}

impl LinkChoice {
    /// `gaps`: per link, the shortest time between telemetry messages on it.
    pub fn new(gaps: Vec<Option<Duration>>, timeout: Duration, probe_period: Duration) -> Self {
        let n = gaps.len();
        LinkChoice {
            heard: vec![None; n],
            timeout,
            probe_period,
            next_probe: Duration::ZERO,
            telemetry_gap: gaps,
            last_telemetry: vec![None; n],
            in_use: None,
            port_down: vec![false; n],
        }
    }

    /// Number of links.
    pub fn len(&self) -> usize {
        self.heard.len()
    }

    pub fn is_empty(&self) -> bool {
        self.heard.is_empty()
    }

    /// The router was heard on `link` at `now`.
    pub fn heard(&mut self, link: usize, now: Duration) {
        if let Some(h) = self.heard.get_mut(link) {
            *h = Some(now);
        }
    }

    /// `link`'s port failed: it is not live until the router is heard on
    /// it again, so what is sent next (the notice reporting the outage
    /// first) goes on another link without waiting for the link timeout,
    /// and nothing goes on it until [`LinkChoice::up`].
    pub fn down(&mut self, link: usize) {
        if let Some(h) = self.heard.get_mut(link) {
            *h = None;
        }
        if let Some(d) = self.port_down.get_mut(link) {
            *d = true;
        }
    }

    /// `link`'s port is open again: messages may go on it.
    pub fn up(&mut self, link: usize) {
        if let Some(d) = self.port_down.get_mut(link) {
            *d = false;
        }
    }

    /// Whether a message may go on `link`: its port is not known down.
    pub fn usable(&self, link: usize) -> bool {
        !self.port_down.get(link).copied().unwrap_or(false)
    }

    /// Whether the router was heard on `link` within the link timeout.
    pub fn live(&self, link: usize, now: Duration) -> bool {
        self.heard
            .get(link)
            .copied()
            .flatten()
            .is_some_and(|t| now.saturating_sub(t) < self.timeout)
    }

    /// The link messages go on now: the first live one; `None` when none
    /// is live (then they go on every link).
    pub fn preferred(&self, now: Duration) -> Option<usize> {
        (0..self.len()).find(|&i| self.live(i, now))
    }

    /// The links to send a message on now.
    pub fn targets(&mut self, now: Duration) -> std::ops::Range<usize> {
        let preferred = self.preferred(now);
        if preferred != self.in_use {
            tracing::info!(from = ?self.in_use, to = ?preferred, "link in use (none: every link)");
            self.in_use = preferred;
        }
        match preferred {
            Some(i) => i..i + 1,
            None => 0..self.len(),
        }
    }

    /// Whether a telemetry message may go on `link` now (its rate cap);
    /// records it if so.
    pub fn telemetry_allowed(&mut self, link: usize, now: Duration) -> bool {
        let gap = self.telemetry_gap.get(link).copied().flatten();
        let last = self.last_telemetry.get(link).copied().flatten();
        let allowed = match (gap, last) {
            (Some(gap), Some(last)) => now.saturating_sub(last) >= gap,
            _ => true,
        };
        if allowed && let Some(l) = self.last_telemetry.get_mut(link) {
            *l = Some(now);
        }
        allowed
    }

    /// The links due a probe heartbeat now: every `probe_period`, each
    /// link but the one in use and those whose port is down.
    pub fn probes_due(&mut self, now: Duration) -> Vec<usize> {
        if self.len() < 2 || now < self.next_probe {
            return Vec::new();
        }
        self.next_probe = now + self.probe_period;
        let preferred = self.preferred(now);
        (0..self.len())
            .filter(|i| Some(*i) != preferred && self.usable(*i))
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ms(v: u64) -> Duration {
        Duration::from_millis(v)
    }

    #[test]
    fn a_link_reported_down_is_left_at_once() {
        let mut c = LinkChoice::new(vec![None, None], ms(600), ms(250));
        c.heard(1, ms(10));
        assert_eq!(c.targets(ms(20)), 1..2, "only the radio heard");
        c.down(1);
        assert_eq!(
            c.targets(ms(30)),
            0..2,
            "its outage is told on every link, not on the radio alone"
        );
        c.heard(0, ms(40));
        c.heard(1, ms(40));
        c.down(0);
        assert_eq!(c.targets(ms(50)), 1..2, "Wi-Fi down: the radio");
        c.down(7);
        assert_eq!(c.targets(ms(50)), 1..2, "no such link: nothing changes");
    }

    #[test]
    fn a_link_whose_port_is_down_gets_no_probe_until_it_is_up() {
        let mut c = LinkChoice::new(vec![None, None], ms(600), ms(250));
        c.heard(0, ms(0));
        c.heard(1, ms(0));
        assert_eq!(c.probes_due(ms(10)), vec![1], "the radio not in use");
        c.down(1);
        assert!(!c.usable(1) && c.usable(0));
        assert_eq!(
            c.probes_due(ms(300)),
            Vec::<usize>::new(),
            "a probe on a radio that is down would only be lost"
        );
        c.up(1);
        assert!(c.usable(1));
        c.heard(0, ms(500));
        assert_eq!(c.probes_due(ms(600)), vec![1]);
    }

    #[test]
    fn the_first_live_link_in_order_then_the_next_then_back() {
        let mut c = LinkChoice::new(vec![None, None], ms(600), ms(250));
        assert_eq!(c.targets(ms(0)), 0..2, "nothing heard: every link");
        c.heard(1, ms(10));
        assert_eq!(c.targets(ms(20)), 1..2, "only the radio heard");
        c.heard(0, ms(30));
        assert_eq!(c.targets(ms(40)), 0..1, "Wi-Fi first");
        c.heard(1, ms(600));
        assert_eq!(c.targets(ms(629)), 0..1);
        assert_eq!(c.targets(ms(630)), 1..2, "Wi-Fi silent 600 ms: radio");
        c.heard(0, ms(700));
        assert_eq!(c.targets(ms(701)), 0..1, "Wi-Fi back");
        assert_eq!(c.targets(ms(5_000)), 0..2, "both silent: every link");
    }

    #[test]
    fn probes_go_on_the_links_not_in_use_and_telemetry_keeps_to_a_link_cap() {
        let mut c = LinkChoice::new(vec![None, Some(ms(200))], ms(600), ms(250));
        c.heard(0, ms(0));
        assert_eq!(c.probes_due(ms(0)), vec![1]);
        assert!(c.probes_due(ms(100)).is_empty());
        assert_eq!(c.probes_due(ms(250)), vec![1]);
        assert!(c.telemetry_allowed(1, ms(0)));
        assert!(!c.telemetry_allowed(1, ms(150)));
        assert!(c.telemetry_allowed(1, ms(200)));
        assert!(c.telemetry_allowed(0, ms(201)) && c.telemetry_allowed(0, ms(202)));
        let single = &mut LinkChoice::new(vec![None], ms(600), ms(250));
        assert!(single.probes_due(ms(0)).is_empty(), "one link: no probes");
    }
}
