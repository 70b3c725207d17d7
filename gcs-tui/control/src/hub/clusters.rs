//! The cluster controllers the hub runs, one per cluster on
//! `fleet/<cluster>`: their state (the controller, its last status, the
//! tracking statistics, the waypoint draft and when a gamepad's velocity
//! lapses), one period of each, and the hub's requests that change them.
//!
//! A cluster is defined in the fleet model (command language, TUI,
//! configuration); its controller is created, in a line formation, by the
//! first request that names it, and takes the definition's members at
//! every period.

use std::collections::BTreeMap;
use std::collections::btree_map::Entry;

use mech_proto::{ClusterVelocity, Formation, FormationKind};

use super::period::{Outgoing, PeriodInputs, PeriodOutput};
use super::{ControlError, ControlHub, cluster_channel};
use crate::ControlEvent;
use crate::cluster::{
    ClusterConfig, ClusterController, ClusterMotion, ClusterStatus, ClusterWaypoint,
};
use crate::spec::DEFAULT_SPACING;
use mech_core::fleet::{Cluster, Severity};
use mech_core::sync::lock;

/// Running tracking-error statistics of a cluster since its last mission
/// started (or since it was created).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct TrackingStats {
    /// Member-period samples.
    pub samples: u64,
    /// Largest slot error, m.
    pub max: f64,
    sum_sq: f64,
}

impl TrackingStats {
    fn add(&mut self, error: f64) {
        self.samples += 1;
        self.max = self.max.max(error);
        self.sum_sq += error * error;
    }

    /// Root-mean-square slot error, m.
    pub fn rms(&self) -> f64 {
        if self.samples == 0 {
            0.0
        } else {
            (self.sum_sq / self.samples as f64).sqrt()
        }
    }
}

/// A cluster as displays show it.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterView {
    pub channel: String,
    /// Last step's status: desired and measured cluster pose, slot targets
    /// with per-member tracking error, lost and absent members.
    pub status: ClusterStatus,
    pub stats: TrackingStats,
    /// What the cluster pose is doing: holding, a velocity, or waypoints.
    pub motion: ClusterMotion,
    /// Cluster waypoints set but not sent yet.
    pub draft: Vec<ClusterWaypoint>,
    /// The last waypoint list sent was completed.
    pub finished: bool,
}

/// Every cluster controller, by cluster name.
#[derive(Debug, Default)]
pub(super) struct Clusters {
    entries: BTreeMap<String, ClusterEntry>,
}

/// One cluster's controller and what the hub keeps beside it.
#[derive(Debug)]
pub(super) struct ClusterEntry {
    controller: ClusterController,
    status: Option<ClusterStatus>,
    stats: TrackingStats,
    draft: Vec<ClusterWaypoint>,
    draft_looped: bool,
    finished: bool,
    /// Router time (s) at which a gamepad velocity lapses.
    drive_expires: Option<f64>,
}

impl Clusters {
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Cluster `name`'s entry, its controller created with `members` in a
    /// line formation if it has none yet.
    pub fn entry(
        &mut self,
        name: &str,
        members: Vec<String>,
        config: &ClusterConfig,
    ) -> Result<&mut ClusterEntry, ControlError> {
        match self.entries.entry(name.to_string()) {
            Entry::Occupied(e) => Ok(e.into_mut()),
            Entry::Vacant(v) => {
                let formation = Formation {
                    kind: FormationKind::Line,
                    spacing: DEFAULT_SPACING,
                    offsets: Vec::new(),
                };
                let controller = ClusterController::new(name, members, formation, config.clone())?;
                Ok(v.insert(ClusterEntry::new(controller)))
            }
        }
    }

    pub fn get(&self, name: &str) -> Option<&ClusterEntry> {
        self.entries.get(name)
    }

    /// One period of every cluster.
    pub fn step(&mut self, inputs: &PeriodInputs, output: &mut PeriodOutput) {
        for (name, e) in self.entries.iter_mut() {
            e.step(name, inputs, output);
        }
    }

    /// The clusters that have stepped at least once since their last
    /// change.
    pub fn views(&self) -> Vec<ClusterView> {
        self.entries.iter().filter_map(|(n, e)| e.view(n)).collect()
    }
}

impl ClusterEntry {
    fn new(controller: ClusterController) -> ClusterEntry {
        ClusterEntry {
            controller,
            status: None,
            stats: TrackingStats::default(),
            draft: Vec::new(),
            draft_looped: false,
            finished: false,
            drive_expires: None,
        }
    }

    pub fn set_formation(&mut self, formation: Formation) -> Result<(), ControlError> {
        Ok(self.controller.set_formation(formation)?)
    }

    /// Moves at `velocity` until told otherwise, or, with `expires`, until
    /// that router time unless refreshed.
    pub fn move_at(&mut self, velocity: ClusterVelocity, expires: Option<f64>) {
        self.controller.set_velocity(velocity);
        self.drive_expires = expires;
        self.finished = false;
    }

    /// Visits `list` (a goal from outside the draft: an external pose).
    pub fn go_to(&mut self, list: Vec<ClusterWaypoint>) {
        self.controller.set_waypoints(list, false);
        self.drive_expires = None;
        self.finished = false;
    }

    pub fn hold(&mut self) {
        self.controller.hold();
        self.drive_expires = None;
    }

    pub fn set_draft(&mut self, waypoints: Vec<ClusterWaypoint>, looped: bool) {
        self.draft = waypoints;
        self.draft_looped = looped;
    }

    /// What the cluster pose is doing.
    pub fn motion(&self) -> &ClusterMotion {
        self.controller.motion()
    }

    pub fn has_draft(&self) -> bool {
        !self.draft.is_empty()
    }

    /// Starts on the draft and resets the tracking statistics; the number
    /// of waypoints.
    pub fn send(&mut self, name: &str) -> Result<usize, ControlError> {
        if self.draft.is_empty() {
            return Err(ControlError::NoClusterWaypoints(name.to_string()));
        }
        self.controller
            .set_waypoints(self.draft.clone(), self.draft_looped);
        self.drive_expires = None;
        self.finished = false;
        self.stats = TrackingStats::default();
        Ok(self.draft.len())
    }

    /// Forgets the last status: the next period's is the first to reflect
    /// a change.
    fn invalidate_status(&mut self) {
        self.status = None;
    }

    /// One period of cluster `name` on the robots routed to `fleet/<name>`.
    fn step(&mut self, name: &str, inputs: &PeriodInputs, output: &mut PeriodOutput) {
        let channel = cluster_channel(name);
        if let Some(def) = inputs.clusters.get(name) {
            self.follow_definition(name, def, &mut output.log);
        }
        if self.drive_expires.is_some_and(|t| inputs.now > t) {
            self.hold();
        }
        let routed = inputs.routed_states(&channel, None);
        let result = self.controller.step(inputs.now, &routed);
        for s in &result.status.slots {
            self.stats.add(s.error);
        }
        if result.events.contains(&ControlEvent::Finished) {
            self.finished = true;
        }
        output.events(name, &result.events);
        self.status = Some(result.status);
        if !result.commands.is_empty() {
            output.outgoing.push(Outgoing::Fleet {
                channel,
                parts: result.commands,
            });
        }
    }

    /// Takes the members of the fleet model's cluster definition when they
    /// changed: clusters are defined there (command language, TUI,
    /// configuration), not on the controller.
    fn follow_definition(&mut self, name: &str, def: &Cluster, log: &mut Vec<(Severity, String)>) {
        if def.members.as_slice() == self.controller.members() {
            return;
        }
        if let Err(err) = self.controller.set_members(def.members.clone()) {
            log.push((
                Severity::Warn,
                format!("{name}: members not updated: {err}"),
            ));
        }
    }

    fn view(&self, name: &str) -> Option<ClusterView> {
        Some(ClusterView {
            channel: cluster_channel(name),
            status: self.status.clone()?,
            stats: self.stats,
            motion: self.motion().clone(),
            draft: self.draft.clone(),
            finished: self.finished,
        })
    }
}

impl ControlHub {
    /// Sets a cluster's formation; slots are re-assigned at the next period.
    pub fn set_formation(&self, cluster: &str, formation: Formation) -> Result<(), ControlError> {
        self.with_cluster(cluster, |e| e.set_formation(formation))
    }

    /// Moves a cluster at a cluster-frame velocity until told otherwise.
    pub fn cluster_move(
        &self,
        cluster: &str,
        velocity: ClusterVelocity,
    ) -> Result<(), ControlError> {
        self.with_cluster(cluster, |e| {
            e.move_at(velocity, None);
            Ok(())
        })
    }

    /// Moves a cluster at a velocity that lapses (the cluster holds) unless
    /// refreshed within [`super::HubConfig::drive_timeout`]: the gamepad
    /// mapping.
    pub fn drive_cluster(
        &self,
        cluster: &str,
        velocity: ClusterVelocity,
    ) -> Result<(), ControlError> {
        let expires = self.shared.gcs.router().elapsed().as_secs_f64()
            + self.shared.config.drive_timeout.as_secs_f64();
        self.change_cluster(cluster, false, |e| {
            e.move_at(velocity, Some(expires));
            Ok(())
        })
    }

    /// Stops a cluster where it is.
    pub fn hold_cluster(&self, cluster: &str) -> Result<(), ControlError> {
        self.with_cluster(cluster, |e| {
            e.hold();
            Ok(())
        })
    }

    /// Sets a cluster's waypoint draft (sent with [`ControlHub::send_cluster`]).
    pub fn set_cluster_waypoints(
        &self,
        cluster: &str,
        waypoints: Vec<ClusterWaypoint>,
        looped: bool,
    ) -> Result<(), ControlError> {
        self.with_cluster(cluster, |e| {
            e.set_draft(waypoints, looped);
            Ok(())
        })
    }

    /// A cluster's waypoint draft and whether it loops (what `mission
    /// save` keeps); `None` for a cluster without one.
    pub fn cluster_draft(&self, cluster: &str) -> Option<(Vec<ClusterWaypoint>, bool)> {
        lock(&self.shared.clusters)
            .get(cluster)
            .filter(|e| e.has_draft())
            .map(|e| (e.draft.clone(), e.draft_looped))
    }

    /// Whether `cluster` has cluster waypoints waiting to be sent.
    pub fn has_cluster_draft(&self, cluster: &str) -> bool {
        lock(&self.shared.clusters)
            .get(cluster)
            .is_some_and(ClusterEntry::has_draft)
    }

    /// Starts the cluster on its waypoint draft and resets its tracking
    /// statistics. Returns the number of waypoints.
    pub fn send_cluster(&self, cluster: &str) -> Result<usize, ControlError> {
        self.with_cluster(cluster, |e| e.send(cluster))
    }

    /// The status of one cluster.
    pub fn cluster_view(&self, cluster: &str) -> Option<ClusterView> {
        lock(&self.shared.clusters)
            .get(cluster)
            .and_then(|e| e.view(cluster))
    }

    /// Changes the cluster's controller (created, in a line formation, on
    /// first use) and runs a period at once.
    pub(super) fn with_cluster<R>(
        &self,
        name: &str,
        f: impl FnOnce(&mut ClusterEntry) -> Result<R, ControlError>,
    ) -> Result<R, ControlError> {
        self.change_cluster(name, true, f)
    }

    /// [`ControlHub::with_cluster`]; `stale_status` says whether the change
    /// invalidates the last status (a new formation or goal does; a refreshed
    /// gamepad velocity does not, and must not blank displays 20 times a
    /// second).
    fn change_cluster<R>(
        &self,
        name: &str,
        stale_status: bool,
        f: impl FnOnce(&mut ClusterEntry) -> Result<R, ControlError>,
    ) -> Result<R, ControlError> {
        let members = self
            .shared
            .gcs
            .with_fleet(|fl| fl.clusters.get(name).map(|c| c.members.clone()))
            .ok_or_else(|| ControlError::UnknownCluster(name.to_string()))?;
        let r = {
            let mut clusters = lock(&self.shared.clusters);
            let entry = clusters.entry(name, members, &self.shared.config.cluster)?;
            let r = f(entry);
            if r.is_ok() && stale_status {
                entry.invalidate_status();
            }
            r
        };
        self.kick();
        r
    }
}

#[cfg(test)]
mod tests {
    use super::super::period::tests::{inputs, state};
    use super::*;

    fn members() -> Vec<String> {
        vec!["a".into(), "b".into()]
    }

    fn c1(clusters: &mut Clusters) -> &mut ClusterEntry {
        clusters
            .entry("c1", members(), &ClusterConfig::default())
            .unwrap()
    }

    fn routed_pair(now: f64) -> PeriodInputs {
        inputs(
            now,
            vec![state("a", 0.0, 0.0, now), state("b", 1.0, 0.0, now)],
            &[("a", "fleet/c1"), ("b", "fleet/c1")],
        )
    }

    #[test]
    fn a_gamepad_velocity_lapses_into_a_hold_and_a_typed_one_does_not() {
        let v = ClusterVelocity {
            vx: 0.2,
            vy: 0.0,
            wz: 0.0,
            scale_rate: 0.0,
        };
        let mut clusters = Clusters::default();
        c1(&mut clusters).move_at(v, Some(1.0));
        clusters.step(&routed_pair(0.9), &mut PeriodOutput::default());
        assert_eq!(
            clusters.get("c1").unwrap().controller.motion(),
            &ClusterMotion::Velocity(v)
        );
        clusters.step(&routed_pair(1.1), &mut PeriodOutput::default());
        assert_eq!(
            clusters.get("c1").unwrap().controller.motion(),
            &ClusterMotion::Hold
        );
        c1(&mut clusters).move_at(v, None);
        clusters.step(&routed_pair(100.0), &mut PeriodOutput::default());
        assert_eq!(
            clusters.get("c1").unwrap().controller.motion(),
            &ClusterMotion::Velocity(v)
        );
    }

    #[test]
    fn a_draft_is_sent_only_when_there_is_one_and_resets_the_statistics() {
        let mut clusters = Clusters::default();
        let e = c1(&mut clusters);
        assert!(matches!(
            e.send("c1"),
            Err(ControlError::NoClusterWaypoints(_))
        ));
        e.stats.add(0.3);
        let wp = |x| ClusterWaypoint {
            x,
            y: 0.0,
            heading: None,
        };
        e.set_draft(vec![wp(1.0), wp(2.0)], false);
        assert!(e.has_draft());
        assert_eq!(e.send("c1").unwrap(), 2);
        assert_eq!(e.stats, TrackingStats::default());
        assert!(matches!(
            e.controller.motion(),
            ClusterMotion::Waypoints { list, .. } if list.len() == 2
        ));
    }

    #[test]
    fn only_routed_members_are_commanded_and_a_view_waits_for_a_step() {
        let mut clusters = Clusters::default();
        c1(&mut clusters);
        assert!(clusters.views().is_empty(), "no status before a step");
        let only_a = inputs(
            1.0,
            vec![state("a", 0.0, 0.0, 1.0), state("b", 1.0, 0.0, 1.0)],
            &[("a", "fleet/c1"), ("b", "joy/0")],
        );
        let mut out = PeriodOutput::default();
        clusters.step(&only_a, &mut out);
        let Some(Outgoing::Fleet { channel, parts }) = out.outgoing.first() else {
            panic!("a fleet command: {:?}", out.outgoing);
        };
        assert_eq!(channel, "fleet/c1");
        assert!(parts.iter().all(|p| p.robot == "a"), "{parts:?}");
        let view = clusters.views().pop().expect("a view after a step");
        assert_eq!(view.status.absent, ["b"]);
    }

    #[test]
    fn members_follow_the_fleet_models_definition() {
        let mut clusters = Clusters::default();
        c1(&mut clusters);
        let mut i = routed_pair(1.0);
        i.clusters.insert(
            "c1".into(),
            Cluster {
                members: vec!["a".into(), "b".into(), "c".into()],
                ..Cluster::default()
            },
        );
        clusters.step(&i, &mut PeriodOutput::default());
        assert_eq!(
            clusters.get("c1").unwrap().controller.members(),
            ["a", "b", "c"]
        );
    }
}
