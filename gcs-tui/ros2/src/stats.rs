//! What the bridge did, counted: samples published to ROS 2, commands and
//! goals forwarded to the station, samples refused by reason, and what the
//! station's side refused or lost. Shared by the bridge's tasks; read for
//! the log's summary lines and for `/diagnostics`.

use std::fmt;
use std::sync::atomic::{AtomicU64, Ordering};

use serde::Serialize;

use crate::inbound::Refusal;

/// Counters, updated with relaxed atomics (each is a tally on its own).
#[derive(Debug, Default)]
pub struct Stats {
    /// Telemetry samples received from the station (verified, decoded).
    pub telemetry: AtomicU64,
    /// Samples published on DDS (odometry, TF, battery, diagnostics,
    /// markers) and samples DDS refused to take.
    pub published: AtomicU64,
    pub publish_failed: AtomicU64,
    /// cmd_vel samples forwarded to the station as commands.
    pub cmd_forwarded: AtomicU64,
    /// Goals sent as missions, and acknowledged by their robot.
    pub goals_sent: AtomicU64,
    pub goals_acked: AtomicU64,
    /// Goals whose robot did not acknowledge the mission in time.
    pub goals_unacked: AtomicU64,
    /// E-stop engage requests taken from ROS 2 and sent to the station.
    pub estops_sent: AtomicU64,
    /// E-stop requests that could not be sent (no e-stop key at a station
    /// that authenticates).
    pub estops_refused: AtomicU64,
    /// Refusals of ROS 2 input, by [`Refusal`].
    refused: [AtomicU64; Refusal::ALL.len()],
    /// Robots whose names cannot be ROS 2 names (they are not bridged).
    pub names_rejected: AtomicU64,
    /// Datagrams from the station that did not verify or decode.
    pub link_rejected: AtomicU64,
    /// Messages the bridge could not send to the station (socket errors).
    pub send_failed: AtomicU64,
    /// Notices the station sent the bridge (logged, thinned out).
    pub notices: AtomicU64,
    /// Of them, refusals by the station's permissions (each logged).
    pub station_refusals: AtomicU64,
}

impl Stats {
    /// Counts one refusal.
    pub fn refuse(&self, reason: Refusal) {
        self.refused[reason as usize].fetch_add(1, Ordering::Relaxed);
    }

    /// Refusals so far for `reason`.
    pub fn refused(&self, reason: Refusal) -> u64 {
        self.refused[reason as usize].load(Ordering::Relaxed)
    }

    /// A copy, for output.
    pub fn snapshot(&self) -> StatsSnapshot {
        let get = |c: &AtomicU64| c.load(Ordering::Relaxed);
        StatsSnapshot {
            telemetry: get(&self.telemetry),
            published: get(&self.published),
            publish_failed: get(&self.publish_failed),
            cmd_forwarded: get(&self.cmd_forwarded),
            goals_sent: get(&self.goals_sent),
            goals_acked: get(&self.goals_acked),
            goals_unacked: get(&self.goals_unacked),
            estops_sent: get(&self.estops_sent),
            estops_refused: get(&self.estops_refused),
            refused_not_finite: self.refused(Refusal::NotFinite),
            refused_out_of_range: self.refused(Refusal::OutOfRange),
            refused_wrong_frame: self.refused(Refusal::WrongFrame),
            refused_unknown_robot: self.refused(Refusal::UnknownRobot),
            names_rejected: get(&self.names_rejected),
            link_rejected: get(&self.link_rejected),
            send_failed: get(&self.send_failed),
            notices: get(&self.notices),
            station_refusals: get(&self.station_refusals),
        }
    }
}

/// The counters at one moment. Each has one name everywhere: the field,
/// the summary line, `/diagnostics` and the closing JSON line all take it
/// from [`StatsSnapshot::pairs`], and `docs/ros2.md` lists the same.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct StatsSnapshot {
    pub telemetry: u64,
    pub published: u64,
    pub publish_failed: u64,
    pub cmd_forwarded: u64,
    pub goals_sent: u64,
    pub goals_acked: u64,
    pub goals_unacked: u64,
    pub estops_sent: u64,
    pub estops_refused: u64,
    pub refused_not_finite: u64,
    pub refused_out_of_range: u64,
    pub refused_wrong_frame: u64,
    pub refused_unknown_robot: u64,
    pub names_rejected: u64,
    pub link_rejected: u64,
    pub send_failed: u64,
    pub notices: u64,
    pub station_refusals: u64,
}

impl StatsSnapshot {
    /// Every counter as (name, value), in a fixed order: the summary line's
    /// and `/diagnostics`' key-values.
    pub fn pairs(&self) -> Vec<(&'static str, u64)> {
        vec![
            ("telemetry", self.telemetry),
            ("published", self.published),
            ("publish_failed", self.publish_failed),
            ("cmd_forwarded", self.cmd_forwarded),
            ("goals_sent", self.goals_sent),
            ("goals_acked", self.goals_acked),
            ("goals_unacked", self.goals_unacked),
            ("estops_sent", self.estops_sent),
            ("estops_refused", self.estops_refused),
            ("refused_not_finite", self.refused_not_finite),
            ("refused_out_of_range", self.refused_out_of_range),
            ("refused_wrong_frame", self.refused_wrong_frame),
            ("refused_unknown_robot", self.refused_unknown_robot),
            ("names_rejected", self.names_rejected),
            ("link_rejected", self.link_rejected),
            ("send_failed", self.send_failed),
            ("notices", self.notices),
            ("station_refusals", self.station_refusals),
        ]
    }

    /// Refusals of every reason together.
    pub fn refused(&self) -> u64 {
        self.refused_not_finite
            + self.refused_out_of_range
            + self.refused_wrong_frame
            + self.refused_unknown_robot
    }
}

impl Serialize for StatsSnapshot {
    /// `{"telemetry": 120, ..., "refused_not_finite": 2, ...}`: the names
    /// and order of [`StatsSnapshot::pairs`].
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let pairs = self.pairs();
        let mut map = serializer.serialize_map(Some(pairs.len()))?;
        for (k, v) in pairs {
            map.serialize_entry(k, &v)?;
        }
        map.end()
    }
}

impl fmt::Display for StatsSnapshot {
    /// `telemetry=120 published=480 ...`, one line.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, (k, v)) in self.pairs().into_iter().enumerate() {
            if i > 0 {
                f.write_str(" ")?;
            }
            write!(f, "{k}={v}")?;
        }
        Ok(())
    }
}

/// Whether the `n`th occurrence of something should be logged: the 1st,
/// 2nd, 4th, 8th..., so a flood of bad input cannot flood the log.
pub fn worth_logging(n: u64) -> bool {
    n.is_power_of_two()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refusals_are_counted_by_reason_and_printed_in_one_line() {
        let s = Stats::default();
        s.refuse(Refusal::NotFinite);
        s.refuse(Refusal::NotFinite);
        s.refuse(Refusal::UnknownRobot);
        s.cmd_forwarded.fetch_add(3, Ordering::Relaxed);
        let snap = s.snapshot();
        assert_eq!(
            (
                snap.refused_not_finite,
                snap.refused_unknown_robot,
                snap.refused()
            ),
            (2, 1, 3)
        );
        let line = snap.to_string();
        assert!(line.contains("cmd_forwarded=3"), "{line}");
        assert!(line.contains("refused_not_finite=2 "), "{line}");
        assert!(line.contains("refused_unknown_robot=1 "), "{line}");
    }

    /// The counters `docs/ros2.md` lists under *Counters* are the bridge's,
    /// by the same names, on every output: the summary line, the closing
    /// JSON line (and `/diagnostics`, which takes `pairs` too).
    #[test]
    fn the_counters_are_named_as_docs_ros2_shows_them() {
        let page = include_str!("../../../docs/ros2.md");
        let section = page
            .split("\n## Counters\n")
            .nth(1)
            .and_then(|s| s.split("\n## ").next())
            .expect("a Counters section");
        let documented: Vec<&str> = section
            .lines()
            .filter_map(|l| l.strip_prefix("| `"))
            .filter_map(|l| l.split('`').next())
            .collect();
        let snap = Stats::default().snapshot();
        let names: Vec<&str> = snap.pairs().into_iter().map(|(k, _)| k).collect();
        assert_eq!(documented, names);
        for r in Refusal::ALL {
            let name = format!("refused_{}", r.as_str());
            assert!(names.contains(&name.as_str()), "{name}");
        }
        let json = serde_json::to_value(&snap).unwrap();
        let keys: Vec<&str> = json
            .as_object()
            .unwrap()
            .keys()
            .map(String::as_str)
            .collect();
        let mut sorted = names.clone();
        sorted.sort_unstable();
        let mut keys_sorted = keys.clone();
        keys_sorted.sort_unstable();
        assert_eq!(keys_sorted, sorted);
        let line = snap.to_string();
        for name in &names {
            assert!(line.contains(&format!("{name}=0")), "{name}: {line}");
        }
    }

    #[test]
    fn logging_thins_out_as_a_count_grows() {
        let logged: Vec<u64> = (1..=20).filter(|n| worth_logging(*n)).collect();
        assert_eq!(logged, vec![1, 2, 4, 8, 16]);
    }
}
