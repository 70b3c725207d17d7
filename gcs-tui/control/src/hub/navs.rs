//! Offboard navigation as the hub runs it, one navigator per robot on
//! `offboard/<robot>`, and the handover between the agent's loop and the
//! station's: taking a mission over at the agent's reported progress,
//! handing it back (the mission sent again from the next waypoint, the
//! robot routed back once the agent acknowledges it), and the last
//! mission progress every robot reported, which a take-over starts from.

use std::collections::BTreeMap;
use std::time::Duration;

use mech_proto::{Mission, MissionProgress};
use tokio::time::Instant;

use super::period::{Outgoing, PeriodInputs, PeriodOutput};
use super::{ControlError, ControlHub, SENDER, offboard_channel};
use crate::offboard::{NavConfig, OffboardNavigator};
use mech_core::Event;
use mech_core::router::Subscription;
use mech_core::sync::lock;

/// One robot's offboard navigation as displays show it.
#[derive(Debug, Clone, PartialEq)]
pub struct NavView {
    pub robot: String,
    pub channel: String,
    pub progress: MissionProgress,
    /// Distance to the waypoint being approached, m.
    pub distance: Option<f64>,
    /// Telemetry stale: not commanded.
    pub lost: bool,
    /// Time from the `nav ... offboard` request to the first offboard command
    /// the router forwarded to the robot.
    pub switch_latency: Option<Duration>,
}

/// Every robot under offboard navigation, and every robot's last reported
/// mission progress.
#[derive(Debug, Default)]
pub(super) struct Navs {
    entries: BTreeMap<String, NavEntry>,
    /// Last mission progress each robot reported: an agent reports progress
    /// only while routed to the mission's channel, and a switch to offboard
    /// must still know where it got to.
    progress: BTreeMap<String, MissionProgress>,
}

/// One robot's navigator and what its last period found.
#[derive(Debug)]
struct NavEntry {
    nav: OffboardNavigator,
    distance: Option<f64>,
    lost: bool,
    /// When the switch to offboard was requested, until the first command is
    /// forwarded.
    requested_at: Option<Instant>,
    switch_latency: Option<Duration>,
}

impl Navs {
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Keeps the progress the robots report now.
    pub fn note_progress(&mut self, progress: Vec<(String, MissionProgress)>) {
        self.progress.extend(progress);
    }

    /// Puts `robot` under offboard navigation of `mission` (the one it
    /// holds), from `reported` progress or else the last it reported; a
    /// robot already under it (routed away and back) just continues.
    /// `requested_at` starts the switch's latency.
    fn switch_offboard(
        &mut self,
        robot: &str,
        mission: Option<Mission>,
        reported: Option<MissionProgress>,
        config: &NavConfig,
        requested_at: Instant,
    ) -> Result<(), ControlError> {
        if let Some(e) = self.entries.get_mut(robot) {
            e.nav.set_handover(false);
            e.requested_at = Some(requested_at);
            e.switch_latency = None;
            return Ok(());
        }
        let mission = mission.ok_or_else(|| ControlError::NoMission(robot.to_string()))?;
        let reported = reported.or_else(|| self.progress.get(robot).copied());
        let nav = OffboardNavigator::take_over(robot, mission, reported, config.clone());
        self.entries.insert(
            robot.to_string(),
            NavEntry {
                nav,
                distance: None,
                lost: false,
                requested_at: Some(requested_at),
                switch_latency: None,
            },
        );
        Ok(())
    }

    /// Freezes `robot`'s progress for a handover to the agent; the mission
    /// to send it (id to be set by the sender).
    fn start_handover(&mut self, robot: &str) -> Result<Mission, ControlError> {
        let e = self
            .entries
            .get_mut(robot)
            .ok_or_else(|| ControlError::NotOffboard(robot.to_string()))?;
        e.nav.set_handover(true);
        Ok(e.nav.onboard_mission(0))
    }

    /// A handover that failed: the station's loop goes on.
    fn release_handover(&mut self, robot: &str) {
        if let Some(e) = self.entries.get_mut(robot) {
            e.nav.set_handover(false);
        }
    }

    fn remove(&mut self, robot: &str) {
        self.entries.remove(robot);
    }

    /// Records that an offboard command for `robot` was forwarded at `now`;
    /// whether that completed a switch to offboard.
    pub fn forwarded(&mut self, robot: &str, now: Instant) -> bool {
        let Some(e) = self.entries.get_mut(robot) else {
            return false;
        };
        let Some(at) = e.requested_at.take() else {
            return false;
        };
        e.switch_latency = Some(now.saturating_duration_since(at));
        true
    }

    /// One period of every robot's navigation, while it is routed to
    /// `offboard/<robot>`; `timeout` is the navigators' telemetry timeout.
    pub fn step(&mut self, inputs: &PeriodInputs, timeout: f64, output: &mut PeriodOutput) {
        for (robot, e) in self.entries.iter_mut() {
            let channel = offboard_channel(robot);
            if !inputs.routed_to(robot, &channel) {
                continue;
            }
            let s = inputs.states.iter().find(|s| &s.robot == robot);
            let result = e.nav.step(inputs.now, s);
            output.events(&channel, &result.events);
            e.distance = result.distance;
            e.lost = s.is_none_or(|s| s.is_stale(inputs.now, timeout));
            if let Some(command) = result.command {
                output.outgoing.push(Outgoing::Nav {
                    channel,
                    robot: robot.clone(),
                    command,
                });
            }
        }
    }

    pub fn view(&self, robot: &str) -> Option<NavView> {
        self.entries.get(robot).map(|e| e.view(robot))
    }

    pub fn views(&self) -> Vec<NavView> {
        self.entries.iter().map(|(r, e)| e.view(r)).collect()
    }
}

impl NavEntry {
    fn view(&self, robot: &str) -> NavView {
        NavView {
            robot: robot.to_string(),
            channel: offboard_channel(robot),
            progress: self.nav.progress(),
            distance: self.distance,
            lost: self.lost,
            switch_latency: self.switch_latency,
        }
    }
}

impl ControlHub {
    /// Switches `robot` from onboard to offboard navigation of the mission it
    /// holds: the GCS loop takes over at the agent's reported next waypoint
    /// and the robot is routed to `offboard/<robot>`. Returns the view of the
    /// new navigation once its first command has been forwarded (or after
    /// two control periods if it could not be).
    pub async fn nav_offboard(&self, robot: &str) -> Result<NavView, ControlError> {
        let requested_at = Instant::now();
        let gcs = &self.shared.gcs;
        let radius = gcs.config().fleet.arrival_radius;
        let found = gcs.with_fleet(|f| {
            f.robot(robot).map(|r| {
                let mission = r.waypoints.sent.as_ref().map(|s| Mission {
                    id: s.id,
                    waypoints: s.waypoints.clone(),
                    looped: s.looped,
                    arrival_radius: radius,
                    start_index: 0,
                });
                (mission, r.telemetry.mission)
            })
        });
        let Some((mission, reported)) = found else {
            return Err(ControlError::UnknownRobot(robot.to_string()));
        };
        lock(&self.shared.navs).switch_offboard(
            robot,
            mission,
            reported,
            &self.shared.config.nav,
            requested_at,
        )?;
        gcs.router()
            .set_route(robot, Some(&offboard_channel(robot)))
            .await?;
        self.kick();
        self.switched(robot, requested_at + self.shared.config.period() * 2)
            .await
    }

    /// The view of `robot`'s navigation once its first offboard command was
    /// forwarded, or at `deadline`.
    async fn switched(&self, robot: &str, deadline: Instant) -> Result<NavView, ControlError> {
        loop {
            // Registered before looking, so a command forwarded in between
            // still wakes this wait.
            let forwarded = self.shared.forwarded.notified();
            tokio::pin!(forwarded);
            forwarded.as_mut().enable();
            match self.nav_view(robot) {
                Some(v) if v.switch_latency.is_some() || Instant::now() >= deadline => {
                    return Ok(v);
                }
                Some(_) => {}
                None => return Err(ControlError::NotOffboard(robot.to_string())),
            }
            // Timing out is not an error: the view is returned as it is.
            let _ = tokio::time::timeout_at(deadline, forwarded).await;
        }
    }

    /// Hands navigation back to the agent: the mission goes out again with
    /// `start_index` = the current next waypoint (fresh id), progress is
    /// frozen until the agent acknowledges it, then the robot is routed to
    /// the mission channel and the GCS loop stops. Returns the progress
    /// handed over.
    pub async fn nav_onboard(&self, robot: &str) -> Result<MissionProgress, ControlError> {
        let gcs = &self.shared.gcs;
        let mission = lock(&self.shared.navs).start_handover(robot)?;
        let progress = MissionProgress {
            id: mission.id,
            next: mission.start_index,
            total: mission.waypoints.len() as u32,
        };
        let channel = gcs.config().fleet.mission_channel.clone();
        // Watch the router's events rather than the fleet model's delivery
        // state: an agent on loopback can acknowledge before the model has
        // recorded the mission as sent.
        let events = gcs.router().subscribe(1024, false);
        let id = match gcs
            .router()
            .send_mission(SENDER, robot, &channel, mission)
            .await
        {
            Ok(id) => id,
            Err(e) => {
                lock(&self.shared.navs).release_handover(robot);
                return Err(e.into());
            }
        };
        let verdict = tokio::time::timeout(
            self.shared.config.handover_timeout,
            mission_verdict(events, robot, id),
        )
        .await
        .unwrap_or_else(|_| Err(format!("mission {id} not acknowledged in time")));
        if let Err(reason) = verdict {
            lock(&self.shared.navs).release_handover(robot);
            return Err(ControlError::Handover {
                robot: robot.to_string(),
                reason,
            });
        }
        lock(&self.shared.navs).remove(robot);
        gcs.router().set_route(robot, Some(&channel)).await?;
        Ok(MissionProgress { id, ..progress })
    }

    /// Switches `robot` to the other side: offboard if the GCS loop is not
    /// running for it, onboard if it is (one key in the TUI).
    pub async fn toggle_nav(&self, robot: &str) -> Result<String, ControlError> {
        if self.nav_view(robot).is_some() {
            let p = self.nav_onboard(robot).await?;
            Ok(format!(
                "{robot} onboard from waypoint {} of {}",
                p.next, p.total
            ))
        } else {
            let v = self.nav_offboard(robot).await?;
            Ok(format!(
                "{robot} offboard from waypoint {} of {}",
                v.progress.next, v.progress.total
            ))
        }
    }

    /// The status of one robot's offboard navigation.
    pub fn nav_view(&self, robot: &str) -> Option<NavView> {
        lock(&self.shared.navs).view(robot)
    }
}

/// Whether `robot` accepted mission `id`, as the router's `events` tell:
/// accepted, or why not (refused, not delivered, the router stopped).
async fn mission_verdict(mut events: Subscription, robot: &str, id: u32) -> Result<(), String> {
    while let Some(ev) = events.recv().await {
        match &ev.event {
            Event::MissionAcked {
                robot: r,
                id: i,
                accepted,
                reason,
            } if r == robot && *i == id => {
                return if *accepted {
                    Ok(())
                } else {
                    Err(format!("mission {id} refused: {reason}"))
                };
            }
            Event::MissionFailed {
                robot: r,
                id: i,
                reason,
            } if r == robot && *i == id => {
                return Err(format!("mission {id} not delivered: {reason}"));
            }
            _ => {}
        }
    }
    Err("the router stopped".to_string())
}

#[cfg(test)]
mod tests {
    use super::super::period::tests::{inputs, state};
    use super::*;
    use mech_proto::Waypoint;

    fn mission(id: u32) -> Mission {
        let wp = |x| Waypoint {
            x,
            y: 0.0,
            z: 0.0,
            time: None,
        };
        Mission {
            id,
            waypoints: vec![wp(1.0), wp(2.0), wp(3.0)],
            looped: false,
            arrival_radius: 0.05,
            start_index: 0,
        }
    }

    fn progress(id: u32, next: u32) -> MissionProgress {
        MissionProgress { id, next, total: 3 }
    }

    #[test]
    fn a_take_over_starts_from_the_last_progress_the_robot_reported() {
        let mut navs = Navs::default();
        navs.note_progress(vec![("r".into(), progress(7, 2))]);
        let config = NavConfig::default();
        let now = Instant::now();
        navs.switch_offboard("r", Some(mission(7)), None, &config, now)
            .unwrap();
        assert_eq!(navs.view("r").unwrap().progress, progress(7, 2));
        // Progress reported now wins over what was kept.
        navs.remove("r");
        navs.switch_offboard("r", Some(mission(7)), Some(progress(7, 1)), &config, now)
            .unwrap();
        assert_eq!(navs.view("r").unwrap().progress.next, 1);
        assert!(matches!(
            navs.switch_offboard("s", None, None, &config, now),
            Err(ControlError::NoMission(_))
        ));
    }

    #[test]
    fn the_first_forwarded_command_completes_the_switch_and_sets_its_latency() {
        let mut navs = Navs::default();
        let t0 = Instant::now();
        navs.switch_offboard("r", Some(mission(1)), None, &NavConfig::default(), t0)
            .unwrap();
        assert_eq!(navs.view("r").unwrap().switch_latency, None);
        assert!(navs.forwarded("r", t0 + Duration::from_millis(3)));
        assert!(!navs.forwarded("r", t0 + Duration::from_millis(9)), "once");
        assert_eq!(
            navs.view("r").unwrap().switch_latency,
            Some(Duration::from_millis(3))
        );
        assert!(!navs.forwarded("unknown", t0));
    }

    #[test]
    fn a_handover_freezes_progress_and_a_failed_one_releases_it() {
        let mut navs = Navs::default();
        let config = NavConfig::default();
        navs.switch_offboard(
            "r",
            Some(mission(1)),
            Some(progress(1, 1)),
            &config,
            Instant::now(),
        )
        .unwrap();
        let back = navs.start_handover("r").unwrap();
        assert_eq!(back.start_index, 1, "sent again from the next waypoint");
        assert!(matches!(
            navs.start_handover("s"),
            Err(ControlError::NotOffboard(_))
        ));
        // At waypoint 1 (x = 2 m): held there while handing over...
        let at_wp1 = inputs(1.0, vec![state("r", 2.0, 0.0, 1.0)], &[("r", "offboard/r")]);
        navs.step(&at_wp1, 0.5, &mut PeriodOutput::default());
        assert_eq!(navs.view("r").unwrap().progress.next, 1);
        // ...and passed once the handover failed and the loop goes on.
        navs.release_handover("r");
        navs.step(&at_wp1, 0.5, &mut PeriodOutput::default());
        assert_eq!(navs.view("r").unwrap().progress.next, 2);
    }

    #[test]
    fn a_robot_is_navigated_only_while_routed_to_its_offboard_channel() {
        let mut navs = Navs::default();
        navs.switch_offboard(
            "r",
            Some(mission(1)),
            None,
            &NavConfig::default(),
            Instant::now(),
        )
        .unwrap();
        let at = |route: &str| inputs(1.0, vec![state("r", 0.0, 0.0, 1.0)], &[("r", route)]);
        let mut out = PeriodOutput::default();
        navs.step(&at("wp/gcs"), 0.5, &mut out);
        assert!(out.outgoing.is_empty());
        navs.step(&at("offboard/r"), 0.5, &mut out);
        assert!(matches!(
            out.outgoing.as_slice(),
            [Outgoing::Nav { channel, robot, .. }] if channel == "offboard/r" && robot == "r"
        ));
        let mut out = PeriodOutput::default();
        navs.step(
            &inputs(5.0, vec![state("r", 0.0, 0.0, 1.0)], &[("r", "offboard/r")]),
            0.5,
            &mut out,
        );
        assert!(navs.view("r").unwrap().lost, "stale telemetry: lost");
        assert!(out.outgoing.is_empty(), "and not commanded");
    }
}
