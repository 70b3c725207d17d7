//! One control period's vocabulary, shared by the controller concerns and
//! the task that runs them: what a period reads from the fleet model
//! ([`PeriodInputs`]), what it decided ([`PeriodOutput`]: what to publish,
//! what to log), and how a controller's events read in the log.

use std::collections::{BTreeMap, HashMap};

use mech_proto::{Command, MissionProgress, RobotCommand};

use crate::{ControlEvent, MemberState, PlatformLimits};
use mech_core::fleet::{Cluster, Fleet, Severity};

/// What the controllers read from the fleet model at the start of a period.
#[derive(Debug, Default)]
pub(super) struct PeriodInputs {
    /// Router time, s.
    pub now: f64,
    /// Every robot with telemetry (none while no controller runs).
    pub states: Vec<MemberState>,
    /// The channel each robot is routed to, as last requested of the router.
    pub routes: HashMap<String, Option<String>>,
    /// Cluster definitions, whose members the controllers follow.
    pub clusters: BTreeMap<String, Cluster>,
    /// Mission progress the robots report now.
    pub progress: Vec<(String, MissionProgress)>,
}

impl PeriodInputs {
    /// The inputs of a period at router time `now` read from `fleet`; with
    /// `idle` (no controller runs) no robot's state is gathered.
    pub fn read(fleet: &Fleet, now: f64, idle: bool) -> PeriodInputs {
        PeriodInputs {
            now,
            states: if idle {
                Vec::new()
            } else {
                member_states(fleet)
            },
            routes: fleet
                .robots
                .iter()
                .map(|(n, r)| (n.clone(), r.route.requested.clone()))
                .collect(),
            clusters: fleet.clusters.clone(),
            progress: fleet
                .robots
                .iter()
                .filter_map(|(n, r)| Some((n.clone(), r.telemetry.mission?)))
                .collect(),
        }
    }

    /// Whether `robot` is routed to `channel` now.
    pub fn routed_to(&self, robot: &str, channel: &str) -> bool {
        self.routes.get(robot).and_then(|r| r.as_deref()) == Some(channel)
    }

    /// The states of the robots routed to `channel`, and of `also` (a
    /// leader, wherever it is routed).
    pub fn routed_states(&self, channel: &str, also: Option<&str>) -> Vec<MemberState> {
        self.states
            .iter()
            .filter(|s| Some(s.robot.as_str()) == also || self.routed_to(&s.robot, channel))
            .cloned()
            .collect()
    }
}

/// What one control period decided to publish.
#[derive(Debug, Clone, PartialEq)]
pub(super) enum Outgoing {
    Fleet {
        channel: String,
        parts: Vec<RobotCommand>,
    },
    Nav {
        channel: String,
        robot: String,
        command: Command,
    },
}

/// What one control period decided: what to publish and what to log.
#[derive(Debug, Default)]
pub(super) struct PeriodOutput {
    pub outgoing: Vec<Outgoing>,
    pub log: Vec<(Severity, String)>,
}

impl PeriodOutput {
    /// Logs a controller's events, each named by `who` (a cluster or a
    /// channel).
    pub fn events(&mut self, who: &str, events: &[ControlEvent]) {
        self.log.extend(events.iter().map(|ev| event_line(who, ev)));
    }
}

/// How a controller's event reads in the fleet log.
pub(super) fn event_line(who: &str, ev: &ControlEvent) -> (Severity, String) {
    match ev {
        ControlEvent::MemberLost { robot } => (
            Severity::Warn,
            format!(
                "{who}: {robot} telemetry lost; no longer commanded (its failsafe will stop it)"
            ),
        ),
        ControlEvent::MemberRecovered { robot } => (
            Severity::Info,
            format!("{who}: {robot} telemetry back; commanded again"),
        ),
        ControlEvent::WaypointReached { index } => {
            (Severity::Info, format!("{who}: waypoint {index} reached"))
        }
        ControlEvent::Finished => (Severity::Info, format!("{who}: last waypoint reached")),
    }
}

/// Controller inputs from the fleet model: every robot with telemetry.
fn member_states(f: &Fleet) -> Vec<MemberState> {
    f.robots
        .values()
        .filter_map(|r| {
            let stamp = r.last_telemetry?;
            Some(MemberState {
                robot: r.name.clone(),
                platform: PlatformLimits::new(
                    &r.registration.hello.platform,
                    &r.registration.hello.capabilities,
                    r.registration.hello.max_speed,
                    r.registration.hello.max_yaw_rate,
                ),
                pose: r.telemetry.pose,
                velocity: r.telemetry.velocity,
                stamp: stamp.as_secs_f64(),
            })
        })
        .collect()
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use mech_proto::{CommandKind, Pose, Velocity};

    /// A holonomic robot at (`x`, `y`) with telemetry stamped `stamp`.
    pub fn state(robot: &str, x: f64, y: f64, stamp: f64) -> MemberState {
        MemberState {
            robot: robot.to_string(),
            platform: PlatformLimits::new("kiwi", &[CommandKind::Twist], 1.0, 2.0),
            pose: Pose {
                x,
                y,
                ..Pose::default()
            },
            velocity: Velocity::default(),
            stamp,
        }
    }

    /// Inputs at `now` with `states`, each robot routed as `routes` says.
    pub fn inputs(now: f64, states: Vec<MemberState>, routes: &[(&str, &str)]) -> PeriodInputs {
        PeriodInputs {
            now,
            states,
            routes: routes
                .iter()
                .map(|(r, c)| (r.to_string(), Some(c.to_string())))
                .collect(),
            ..PeriodInputs::default()
        }
    }

    #[test]
    fn a_controller_reads_only_the_robots_routed_to_it_and_its_leader() {
        let i = inputs(
            1.0,
            vec![
                state("a", 0.0, 0.0, 1.0),
                state("b", 1.0, 0.0, 1.0),
                state("c", 2.0, 0.0, 1.0),
            ],
            &[("a", "fleet/c1"), ("b", "joy/0"), ("c", "follow/b")],
        );
        let names = |v: Vec<MemberState>| v.into_iter().map(|s| s.robot).collect::<Vec<_>>();
        assert_eq!(names(i.routed_states("fleet/c1", None)), ["a"]);
        assert_eq!(names(i.routed_states("follow/b", Some("b"))), ["b", "c"]);
        assert!(i.routed_to("c", "follow/b") && !i.routed_to("d", "follow/b"));
    }

    #[test]
    fn controller_events_read_as_log_lines_naming_who() {
        let mut out = PeriodOutput::default();
        out.events(
            "fleet/c1",
            &[
                ControlEvent::MemberLost { robot: "a".into() },
                ControlEvent::Finished,
            ],
        );
        assert_eq!(out.log[0].0, Severity::Warn);
        assert!(out.log[0].1.starts_with("fleet/c1: a telemetry lost"));
        assert_eq!(
            out.log[1],
            (Severity::Info, "fleet/c1: last waypoint reached".into())
        );
    }
}
