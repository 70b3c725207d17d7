//! Missions stored at the robot, one per channel that sent one: upload and
//! acknowledgement (a retry of an upload already held keeps its progress),
//! delayed copies of replaced missions ignored, pause and resume. A
//! mission runs only while its channel is the routed one; a stop or an
//! e-stop pauses it until it is re-sent or re-routed.

use std::collections::HashMap;

use mech_proto::{Body, CommandKind, Mission, MissionAck};

use super::step::Step;
use crate::control::{Controller, MissionRun};
use crate::order::is_older;

/// Most channels a robot keeps a mission for. A mission for one more
/// forgets the one uploaded longest ago on a channel the robot is not
/// routed to (counted, and logged).
pub const MISSION_CHANNELS: usize = 16;

/// The stored missions, by the channel that sent them.
#[derive(Debug, Default)]
pub(crate) struct Missions {
    runs: HashMap<String, MissionRun>,
    /// The channels of `runs`, the one uploaded to longest ago first.
    uploads: Vec<String>,
}

impl Missions {
    /// The stored mission for `channel`, if any.
    pub(crate) fn get(&self, channel: &str) -> Option<&MissionRun> {
        self.runs.get(channel)
    }

    /// Whether `channel`'s mission can be followed: stored, not paused,
    /// not finished.
    pub(crate) fn runnable(&self, channel: &str) -> bool {
        self.runs
            .get(channel)
            .is_some_and(|m| !m.paused && !m.finished())
    }

    /// Whether `channel`'s mission is finished (and not paused): the robot
    /// holds at its last waypoint, as told.
    pub(crate) fn done(&self, channel: &str) -> bool {
        self.runs
            .get(channel)
            .is_some_and(|m| !m.paused && m.finished())
    }

    /// The mission the controller follows on `channel`, unless paused.
    pub(crate) fn following(&mut self, channel: &str) -> Option<&mut MissionRun> {
        self.runs.get_mut(channel).filter(|m| !m.paused)
    }

    /// A stop on `channel` holds: its mission must not resume by itself (on
    /// a re-registration or a mission resend) until re-sent or re-routed.
    pub(crate) fn pause(&mut self, channel: &str) {
        if let Some(m) = self.runs.get_mut(channel) {
            m.paused = true;
        }
    }

    /// Room for a mission on `channel`: with [`MISSION_CHANNELS`] held and
    /// none for `channel`, the one uploaded longest ago, not `routed`'s, is
    /// forgotten.
    fn make_room(&mut self, channel: &str, routed: &str, step: &mut Step) {
        if self.runs.contains_key(channel) || self.runs.len() < MISSION_CHANNELS {
            return;
        }
        let Some(i) = self.uploads.iter().position(|c| c != routed) else {
            return;
        };
        let forgotten = self.uploads.remove(i);
        self.runs.remove(&forgotten);
        step.counters.missions_forgotten += 1;
        tracing::warn!(
            robot = %step.robot(),
            channel = %forgotten,
            "mission forgotten: missions held for {MISSION_CHANNELS} channels"
        );
    }

    /// An e-stop pauses every mission.
    pub(crate) fn pause_all(&mut self) {
        self.runs.values_mut().for_each(|m| m.paused = true);
    }

    /// Re-routing to `channel` resumes its paused mission.
    pub(crate) fn unpause(&mut self, channel: &str) {
        if let Some(m) = self.runs.get_mut(channel) {
            m.paused = false;
        }
    }

    /// A mission upload on `channel`: refused with the reason
    /// `cannot_follow` gives when the robot cannot follow waypoints, stored
    /// (paused while `estopped`) and acknowledged otherwise. Returns whether
    /// the stored mission may start now (it is not paused). The mission of
    /// `routed`, the channel the robot obeys, is never forgotten for room.
    pub(crate) fn receive(
        &mut self,
        channel: &str,
        mission: Mission,
        cannot_follow: Option<&str>,
        estopped: bool,
        routed: &str,
        step: &mut Step,
    ) -> bool {
        let id = mission.id;
        if channel.is_empty() {
            // A robot routed to none has the empty channel: a mission on it
            // would run without anyone having routed the robot.
            step.counters.refused += 1;
            step.send(
                mech_proto::ROUTER,
                nack(id, "a mission must be sent on a channel"),
            );
            return false;
        }
        if let Some(reason) = cannot_follow {
            step.send(mech_proto::ROUTER, nack(id, reason));
            return false;
        }
        if self
            .runs
            .get(channel)
            .is_some_and(|run| is_older(id, run.mission.id))
        {
            // A delayed copy of a mission already replaced on this channel:
            // not acknowledged (the router stopped retrying it long ago).
            step.counters.stale_missions += 1;
            return false;
        }
        let paused = match self.runs.get_mut(channel) {
            // A repeated id is a retry of an upload already held (its ack was
            // lost): progress and pause are kept, so a retry never restarts a
            // stopped or e-stopped mission. A re-send uses a new id.
            Some(run) if run.mission.id == id => {
                run.paused |= estopped;
                run.paused
            }
            _ => {
                let mut run = MissionRun::new(mission);
                run.paused = estopped;
                self.make_room(channel, routed, step);
                self.runs.insert(channel.to_string(), run);
                self.uploads.retain(|c| c != channel);
                self.uploads.push(channel.to_string());
                estopped
            }
        };
        let ack = Body::MissionAck(MissionAck {
            id,
            accepted: true,
            reason: String::new(),
        });
        step.send(mech_proto::ROUTER, ack);
        !paused
    }
}

/// Why a robot with this controller cannot follow a mission, if it cannot.
/// `has_position`: the robot has a position source.
pub(crate) fn cannot_follow(controller: &Controller, has_position: bool) -> Option<&'static str> {
    if controller.capabilities().contains(&CommandKind::Waypoints) {
        None
    } else if has_position {
        Some("this platform does not follow waypoints")
    } else {
        Some("this robot has no position source")
    }
}

/// A refused upload's acknowledgement.
fn nack(id: u32, reason: &str) -> Body {
    Body::MissionAck(MissionAck {
        id,
        accepted: false,
        reason: reason.to_string(),
    })
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;

    #[test]
    fn mission_runs_only_while_routed_and_ignores_channel_silence() {
        let mut a = routed("joy/0");
        let mission = mission_to(1, 5.0);
        let out = a.handle(msg("wp/gcs", Body::Mission(mission)), ms(10));
        assert!(
            matches!(&out[0].body, Body::MissionAck(m) if m.accepted),
            "stored and acked while not routed"
        );
        a.tick(ms(20));
        assert_ne!(*a.mode(), Mode::Waypoints);
        a.handle(msg("", route("wp/gcs", 2)), ms(30));
        assert_eq!(*a.mode(), Mode::Waypoints);
        let mut now = ms(30);
        while now < ms(3000) {
            now += PERIOD;
            router_heartbeat(&mut a, now);
            assert!(
                moving(&a.tick(now).outputs),
                "mission is its own controller"
            );
        }
        let tel = a.telemetry(now);
        assert_eq!(
            tel.mission.map(|m| (m.id, m.next, m.total)),
            Some((1, 0, 1))
        );
        assert_eq!(tel.mode, mech_proto::ControlMode::Waypoints);
    }

    /// Missions on ever more channels do not pile up at the robot: past
    /// `MISSION_CHANNELS` the one uploaded longest ago is forgotten
    /// (counted), never the routed channel's, which still runs.
    #[test]
    fn missions_on_many_channels_forget_the_oldest_but_never_the_routed_one() {
        let mut a = routed("wp/gcs");
        a.handle(msg("wp/gcs", Body::Mission(mission_to(1, 5.0))), ms(10));
        let extra = super::MISSION_CHANNELS + 20;
        for k in 0..extra {
            let channel = format!("ext/{k}");
            let out = a.handle(msg(&channel, Body::Mission(mission_to(1, 1.0))), ms(20));
            assert!(
                matches!(&out[0].body, Body::MissionAck(m) if m.accepted),
                "{channel} stored and acknowledged"
            );
        }
        assert!(a.missions.runs.len() <= super::MISSION_CHANNELS);
        assert_eq!(a.missions.uploads.len(), a.missions.runs.len());
        assert_eq!(
            a.counters().missions_forgotten,
            (extra + 1 - super::MISSION_CHANNELS) as u64
        );
        let newest = format!("ext/{}", extra - 1);
        assert!(a.missions.get(&newest).is_some(), "the newest is held");
        assert!(a.missions.get("ext/0").is_none(), "the oldest is forgotten");
        assert!(a.missions.runnable("wp/gcs"), "the routed one is kept");
        a.tick(ms(30));
        assert_eq!(*a.mode(), Mode::Waypoints);
    }

    #[test]
    fn a_finished_mission_holds_without_reading_as_channel_silence() {
        let mut a = routed("wp/gcs");
        // The robot is at the origin: a waypoint there is reached at once.
        a.handle(msg("wp/gcs", Body::Mission(mission_to(1, 0.0))), ms(10));
        let mut now = ms(10);
        while now < ms(2000) {
            now += PERIOD;
            router_heartbeat(&mut a, now);
            assert!(!moving(&a.tick(now).outputs), "holds at the waypoint");
        }
        let tel = a.telemetry(now);
        assert_eq!(tel.mission.map(|m| (m.next, m.total)), Some((1, 1)));
        assert_eq!(tel.failsafe, FailsafeState::Ok, "done, not silent");
        // A controller that goes quiet on a channel without a mission still
        // reads as silent.
        let mut b = routed("joy/0");
        router_heartbeat(&mut b, ms(2000));
        assert_eq!(b.failsafe_state(ms(2000)), FailsafeState::ChannelSilent);
    }

    #[test]
    fn mission_on_router_loss_follows_config() {
        for continues in [false, true] {
            let mut settings = AgentSettings::new("r1");
            settings.failsafe.mission_continues_on_link_loss = continues;
            let mut a = Agent::new(settings, PlatformSpec::diff_drive().build(), 0);
            a.observe_position(PositionSample {
                pose: Pose::default(),
                stamp: ms(0),
                quality: 1.0,
                has_heading: true,
            });
            a.handle(
                msg(
                    "",
                    Body::Welcome(Welcome {
                        robot_id: 1,
                        route: Route {
                            robot: "r1".into(),
                            channel: "wp/gcs".into(),
                            epoch: 1,
                        },
                        router_version: "t".into(),
                    }),
                ),
                ms(0),
            );
            let mission = mission_to(1, 5.0);
            a.handle(msg("wp/gcs", Body::Mission(mission)), ms(0));
            let t = a.tick(ms(2000));
            assert_eq!(a.failsafe_state(ms(2000)), FailsafeState::RouterLost);
            assert_eq!(moving(&t.outputs), continues, "continues = {continues}");
        }
    }

    /// The radio example's failsafe: a 2 s router timeout for a radio's
    /// bursts, and the 0.5 s channel timeout.
    fn mission_robot(continues: bool) -> Agent {
        let mut settings = AgentSettings::new("r1");
        settings.failsafe.router_timeout = ms(2000);
        settings.failsafe.mission_continues_on_link_loss = continues;
        let mut a = Agent::new(settings, PlatformSpec::diff_drive().build(), 0);
        a.observe_position(PositionSample {
            pose: Pose::default(),
            stamp: ms(0),
            quality: 1.0,
            has_heading: true,
        });
        let w = Body::Welcome(Welcome {
            robot_id: 1,
            route: Route {
                robot: "r1".into(),
                channel: "wp/gcs".into(),
                epoch: 1,
            },
            router_version: "t".into(),
        });
        a.handle(msg("", w), ms(0));
        a.handle(msg("wp/gcs", Body::Mission(mission_to(1, 50.0))), ms(0));
        a
    }

    /// The first period from `from` (in steps of [`PERIOD`], until
    /// `until`) whose outputs are zero.
    fn first_still(a: &mut Agent, from: u64, until: u64) -> Option<Duration> {
        (from..until)
            .step_by(PERIOD.as_millis() as usize)
            .map(ms)
            .find(|&t| !moving(&a.tick(t).outputs))
    }

    #[test]
    fn a_mission_stops_within_the_channel_timeout_of_every_link_going_silent() {
        let mut a = mission_robot(false);
        router_heartbeat(&mut a, ms(100));
        assert!(moving(&a.tick(ms(120)).outputs), "flying its mission");
        // Nothing from the router after 100 ms: stopped within the channel
        // timeout and one period, not after the 2 s router timeout.
        let stopped = first_still(&mut a, 140, 2_000).expect("it stops");
        assert!(stopped <= ms(100 + 500) + PERIOD, "stopped at {stopped:?}");
        assert_eq!(a.failsafe_state(stopped), FailsafeState::RouterLost);
        assert!(!moving(&a.tick(ms(900)).outputs), "and stays stopped");
        // The link returns before the router timeout: the mission goes on
        // where it was, without being sent again.
        router_heartbeat(&mut a, ms(1_000));
        assert!(moving(&a.tick(ms(1_020)).outputs), "resumed");
        assert_eq!(a.mission("wp/gcs").map(|m| m.next), Some(0));
        // A longer outage: stopped as fast, registered again once the router
        // answers, and the mission resumed.
        let stopped = first_still(&mut a, 1_040, 4_000).expect("it stops");
        assert!(
            stopped <= ms(1_000 + 500) + PERIOD,
            "stopped at {stopped:?}"
        );
        let start = stopped.as_millis() as u64 + 20;
        let moved = (start..3_100)
            .step_by(20)
            .any(|t| moving(&a.tick(ms(t)).outputs));
        assert!(!moved, "still through the router timeout");
        assert!(!a.registered(), "the router timeout passed");
        let w = Body::Welcome(Welcome {
            robot_id: 1,
            route: Route {
                robot: "r1".into(),
                channel: "wp/gcs".into(),
                epoch: 1,
            },
            router_version: "t".into(),
        });
        a.handle(msg("", w), ms(4_000));
        assert!(moving(&a.tick(ms(4_020)).outputs), "resumed on registering");
    }

    #[test]
    fn a_mission_configured_to_continue_flies_on_without_links() {
        let mut a = mission_robot(true);
        router_heartbeat(&mut a, ms(100));
        assert_eq!(first_still(&mut a, 120, 5_000), None, "never stopped");
    }

    #[test]
    fn a_mission_without_a_channel_is_refused_by_an_unrouted_robot() {
        let mut a = routed("");
        let out = a.handle(msg("", one_waypoint(3)), ms(0));
        assert!(matches!(&out[0].body, Body::MissionAck(m) if m.id == 3 && !m.accepted));
        assert!(
            !moving(&a.tick(ms(20)).outputs),
            "routed to none, it holds still"
        );
    }

    #[test]
    fn a_stop_holds_the_mission_through_a_re_registration() {
        let mut a = routed("wp/gcs");
        a.handle(msg("wp/gcs", one_waypoint(5)), ms(0));
        assert!(moving(&a.tick(ms(20)).outputs));
        a.handle(
            msg("wp/gcs", Body::Command(Command::Stop(mech_proto::Stop {}))),
            ms(30),
        );
        assert!(!moving(&a.tick(ms(40)).outputs));
        // The router repeats the mission (its ack was lost), then the robot
        // re-registers after a link drop: neither restarts the mission.
        a.handle(msg("wp/gcs", one_waypoint(5)), ms(50));
        let w = Body::Welcome(Welcome {
            robot_id: 1,
            route: Route {
                robot: "r1".into(),
                channel: "wp/gcs".into(),
                epoch: 1,
            },
            router_version: "t".into(),
        });
        a.handle(msg("", w), ms(2000));
        assert!(!moving(&a.tick(ms(2020)).outputs), "the stop holds");
    }
}
