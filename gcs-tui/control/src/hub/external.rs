//! Cluster commands that external programs publish on `fleet/<cluster>`
//! ([`ClusterCommand`]: a velocity or a pose goal, optionally a new
//! formation), applied to that cluster's controller. A command whose
//! cluster is not the one its channel names is ignored; one the controller
//! refuses is logged in the fleet log.

use mech_proto::{ClusterCommand, ClusterGoal};

use super::clusters::ClusterEntry;
use super::{ControlError, ControlHub};
use crate::cluster::ClusterWaypoint;
use mech_core::fleet::Severity;

/// The cluster a command on `channel` drives: the one both the channel
/// (`fleet/<cluster>`) and the command name.
fn target<'a>(channel: &str, command: &'a ClusterCommand) -> Option<&'a str> {
    let name = channel.strip_prefix("fleet/")?;
    (name == command.cluster).then_some(command.cluster.as_str())
}

/// Applies `command` to a cluster's controller: the formation first (a
/// refused one refuses the whole command), then the goal.
fn apply(entry: &mut ClusterEntry, command: &ClusterCommand) -> Result<(), ControlError> {
    if let Some(f) = &command.formation {
        entry.set_formation(f.clone())?;
    }
    match &command.goal {
        ClusterGoal::Velocity(v) => entry.move_at(*v, None),
        ClusterGoal::Pose(p) => entry.go_to(vec![ClusterWaypoint {
            x: p.x,
            y: p.y,
            heading: Some(p.heading),
        }]),
    }
    Ok(())
}

impl ControlHub {
    /// Applies a cluster command an external program published on
    /// `channel`.
    pub(super) fn external(&self, channel: &str, command: &ClusterCommand) {
        let Some(name) = target(channel, command) else {
            return;
        };
        if let Err(e) = self.with_cluster(name, |entry| apply(entry, command)) {
            self.shared.gcs.update_fleet(|f| {
                f.log(
                    Severity::Warn,
                    format!("{channel}: cluster command refused: {e}"),
                )
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::clusters::Clusters;
    use super::*;
    use crate::cluster::{ClusterConfig, ClusterMotion};
    use mech_proto::{ClusterPose, ClusterVelocity, Formation, FormationKind};

    fn command(cluster: &str, goal: ClusterGoal, formation: Option<Formation>) -> ClusterCommand {
        ClusterCommand {
            cluster: cluster.into(),
            members: Vec::new(),
            goal,
            formation,
        }
    }

    fn pose(x: f64) -> ClusterGoal {
        ClusterGoal::Pose(ClusterPose {
            x,
            y: 1.0,
            heading: 0.5,
            scale: 1.0,
        })
    }

    #[test]
    fn a_command_drives_only_the_cluster_its_channel_names() {
        let c = command("c1", pose(0.0), None);
        assert_eq!(target("fleet/c1", &c), Some("c1"));
        assert_eq!(target("fleet/c2", &c), None);
        assert_eq!(target("joy/c1", &c), None);
    }

    #[test]
    fn a_pose_is_one_waypoint_a_velocity_a_motion_and_a_bad_formation_refuses_all() {
        let mut clusters = Clusters::default();
        let members = vec!["a".to_string(), "b".to_string(), "c".to_string()];
        let e = clusters
            .entry("c1", members, &ClusterConfig::default())
            .unwrap();
        apply(e, &command("c1", pose(2.0), None)).unwrap();
        let ClusterMotion::Waypoints { list, looped, .. } = e_motion(&clusters) else {
            panic!("waypoints");
        };
        assert_eq!(
            (list, looped),
            (
                vec![ClusterWaypoint {
                    x: 2.0,
                    y: 1.0,
                    heading: Some(0.5)
                }],
                false
            )
        );
        let v = ClusterVelocity {
            vx: 0.1,
            vy: 0.0,
            wz: 0.2,
            scale_rate: 0.0,
        };
        let e = clusters
            .entry("c1", Vec::new(), &ClusterConfig::default())
            .unwrap();
        apply(e, &command("c1", ClusterGoal::Velocity(v), None)).unwrap();
        assert_eq!(e_motion(&clusters), ClusterMotion::Velocity(v));
        // Custom offsets for two robots do not fit three members.
        let bad = Formation {
            kind: FormationKind::Custom,
            spacing: 1.0,
            offsets: vec![mech_proto::Offset { x: 0.0, y: 0.0 }; 2],
        };
        let e = clusters
            .entry("c1", Vec::new(), &ClusterConfig::default())
            .unwrap();
        assert!(apply(e, &command("c1", pose(9.0), Some(bad))).is_err());
        assert_eq!(
            e_motion(&clusters),
            ClusterMotion::Velocity(v),
            "goal not taken"
        );
    }

    fn e_motion(clusters: &Clusters) -> ClusterMotion {
        clusters.get("c1").unwrap().motion().clone()
    }
}
