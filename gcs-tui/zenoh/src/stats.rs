//! What the bridge did, counted: every sample published, every one heard,
//! and every one refused, by reason; and how old other stations'
//! telemetry is when it reaches this station's fleet model.

use std::collections::VecDeque;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use serde::Serialize;

use mech_core::sync::lock;

/// Counters, shared by the bridge's tasks and callbacks.
#[derive(Debug, Default)]
pub struct Stats {
    pub published: AtomicU64,
    pub publish_failed: AtomicU64,
    /// Local robots or channels whose names cannot be key chunks.
    pub names_rejected: AtomicU64,
    /// Samples or queries whose key or payload could not be used.
    pub bad_input: AtomicU64,
    pub commands_forwarded: AtomicU64,
    /// Commands the router did not forward (not routed, unknown robot...).
    pub commands_dropped: AtomicU64,
    /// Commands `[auth]` does not permit the bridge's identity.
    pub commands_refused: AtomicU64,
    /// Commands that found the queue into the router full.
    pub commands_overflow: AtomicU64,
    pub route_requests_done: AtomicU64,
    pub route_requests_refused: AtomicU64,
    /// Updates about other stations' robots applied to the fleet model.
    pub remote_updates: AtomicU64,
    /// Of those, telemetry samples.
    pub remote_telemetry: AtomicU64,
    /// Router events this bridge's subscription missed (it lagged).
    pub events_missed: AtomicU64,
    ages: Mutex<VecDeque<u32>>,
}

/// Remote telemetry ages kept for percentiles (the most recent).
const AGES_KEPT: usize = 100_000;

/// A copy of the counters, for output.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct StatsSnapshot {
    pub published: u64,
    pub publish_failed: u64,
    pub names_rejected: u64,
    pub bad_input: u64,
    pub commands_forwarded: u64,
    pub commands_dropped: u64,
    pub commands_refused: u64,
    pub commands_overflow: u64,
    pub route_requests_done: u64,
    pub route_requests_refused: u64,
    pub remote_updates: u64,
    pub remote_telemetry: u64,
    pub events_missed: u64,
    /// Remote telemetry age (its station received it -> it is in this
    /// station's fleet model): p50, p95, p99, max, microseconds.
    pub remote_age_us: Option<[u32; 4]>,
}

impl Stats {
    pub fn bump(counter: &AtomicU64) {
        counter.fetch_add(1, Ordering::Relaxed);
    }

    /// Counts a sample or query that could not be used, and logs it: at
    /// warn for the 1st, 2nd, 4th, 8th... so a flood cannot flood the log.
    pub fn bad_input(&self, error: &dyn std::fmt::Display) {
        let n = self.bad_input.fetch_add(1, Ordering::Relaxed) + 1;
        if n.is_power_of_two() {
            tracing::warn!(count = n, "zenoh: refused: {error}");
        } else {
            tracing::debug!("zenoh: refused: {error}");
        }
    }

    /// Records the age of one remote telemetry sample.
    pub fn record_age(&self, age: Duration) {
        let us = u32::try_from(age.as_micros()).unwrap_or(u32::MAX);
        let mut ages = lock(&self.ages);
        if ages.len() == AGES_KEPT {
            ages.pop_front();
        }
        ages.push_back(us);
    }

    /// Forgets the recorded ages (a benchmark's warm-up).
    pub fn clear_ages(&self) {
        lock(&self.ages).clear();
    }

    pub fn snapshot(&self) -> StatsSnapshot {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        StatsSnapshot {
            published: get(&self.published),
            publish_failed: get(&self.publish_failed),
            names_rejected: get(&self.names_rejected),
            bad_input: get(&self.bad_input),
            commands_forwarded: get(&self.commands_forwarded),
            commands_dropped: get(&self.commands_dropped),
            commands_refused: get(&self.commands_refused),
            commands_overflow: get(&self.commands_overflow),
            route_requests_done: get(&self.route_requests_done),
            route_requests_refused: get(&self.route_requests_refused),
            remote_updates: get(&self.remote_updates),
            remote_telemetry: get(&self.remote_telemetry),
            events_missed: get(&self.events_missed),
            remote_age_us: self.age_percentiles(),
        }
    }

    fn age_percentiles(&self) -> Option<[u32; 4]> {
        let mut v: Vec<u32> = lock(&self.ages).iter().copied().collect();
        if v.is_empty() {
            return None;
        }
        v.sort_unstable();
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Some([at(0.50), at(0.95), at(0.99), at(1.0)])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ages_give_percentiles_and_are_bounded() {
        let s = Stats::default();
        assert_eq!(s.snapshot().remote_age_us, None);
        for us in 1..=100 {
            s.record_age(Duration::from_micros(us));
        }
        assert_eq!(s.snapshot().remote_age_us, Some([51, 95, 99, 100]));
        for _ in 0..AGES_KEPT {
            s.record_age(Duration::from_micros(7));
        }
        assert_eq!(s.snapshot().remote_age_us, Some([7, 7, 7, 7]));
        s.clear_ages();
        assert_eq!(s.snapshot().remote_age_us, None);
        Stats::bump(&s.published);
        assert_eq!(s.snapshot().published, 1);
    }
}
