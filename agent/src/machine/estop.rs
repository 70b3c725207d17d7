//! The e-stop at the robot: the latch, the order of e-stops and releases,
//! and their acknowledgement.
//!
//! An engaged e-stop idles the controller and pauses every stored mission;
//! while it is latched no command is admitted ([`super::intake`]), no
//! mission starts or resumes ([`super::missions`]), no autopilot request
//! that could start motion is queued, and the failsafe holds the outputs
//! at zero ([`crate::failsafe`]). A release lifts the latch only: the
//! controller stays idle until the next command, and missions stay paused
//! until re-sent or re-routed.
//! The router numbers e-stops and releases in order, so an older one (a
//! delayed resend of a release, overtaken by a new e-stop) never undoes a
//! newer one.

use mech_proto::{Body, EStop, EStopAck};

use super::missions::Missions;
use super::step::Step;
use crate::control::Controller;
use crate::order::is_older;

/// The e-stop latch and the newest e-stop or release obeyed.
#[derive(Debug, Default)]
pub(crate) struct EStopLatch {
    /// Id of the e-stop in force, while latched.
    engaged: Option<u32>,
    /// Id of the newest e-stop or release obeyed since registering.
    newest: Option<u32>,
}

impl EStopLatch {
    /// Whether an e-stop is latched.
    pub(crate) fn engaged(&self) -> bool {
        self.engaged.is_some()
    }

    /// Forgets the order of e-stops (the robot registered: a restarted
    /// router numbers them afresh). The latch itself holds.
    pub(crate) fn forget_ids(&mut self) {
        self.newest = None;
    }

    /// An e-stop or release, unless older than the last one obeyed;
    /// acknowledged to the router when obeyed.
    pub(crate) fn receive(
        &mut self,
        e: EStop,
        controller: &mut Controller,
        missions: &mut Missions,
        step: &mut Step,
    ) {
        if self.newest.is_some_and(|newest| is_older(e.id, newest)) {
            step.counters.stale_estops += 1;
            return;
        }
        self.newest = Some(e.id);
        if e.engage {
            if !self.engaged() {
                step.counters.estopped_at_us = step.stamp_us();
            }
            self.engaged = Some(e.id);
            controller.idle();
            missions.pause_all();
        } else {
            self.engaged = None;
        }
        let ack = Body::EStopAck(EStopAck {
            engage: e.engage,
            id: e.id,
        });
        step.send(mech_proto::ROUTER, ack);
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;

    #[test]
    fn estop_latches_until_release_and_pauses_missions() {
        let mut a = routed("wp/gcs");
        let mission = mission_to(5, 2.0);
        let out = a.handle(msg("wp/gcs", Body::Mission(mission.clone())), ms(10));
        assert!(matches!(&out[0].body, Body::MissionAck(m) if m.id == 5 && m.accepted));
        assert!(moving(&a.tick(ms(20)).outputs));
        let out = a.handle(
            msg(
                "",
                Body::EStop(EStop {
                    engage: true,
                    id: 9,
                }),
            ),
            ms(30),
        );
        assert!(matches!(&out[0].body, Body::EStopAck(e) if e.engage && e.id == 9));
        assert!(!moving(&a.tick(ms(40)).outputs));
        a.handle(msg("wp/gcs", twist(0.2)), ms(50));
        assert!(
            !moving(&a.tick(ms(60)).outputs),
            "commands ignored while latched"
        );
        assert_eq!(a.failsafe_state(ms(60)), FailsafeState::EStopped);
        a.handle(
            msg(
                "",
                Body::EStop(EStop {
                    engage: false,
                    id: 10,
                }),
            ),
            ms(70),
        );
        assert!(
            !moving(&a.tick(ms(80)).outputs),
            "mission stays paused after release"
        );
        a.handle(msg("wp/gcs", twist(0.2)), ms(90));
        assert!(moving(&a.tick(ms(100)).outputs), "obeys the next command");
        // Re-sending the mission (a new upload, so a new id) resumes it.
        let resent = Mission { id: 6, ..mission };
        a.handle(msg("wp/gcs", Body::Mission(resent)), ms(110));
        assert_eq!(*a.mode(), Mode::Waypoints);
        assert!(moving(&a.tick(ms(120)).outputs));
    }

    #[test]
    fn a_delayed_release_cannot_undo_a_newer_estop() {
        let mut a = routed("joy/0");
        a.handle(msg("", estop(true, 9)), ms(0));
        a.handle(msg("", estop(false, 10)), ms(10));
        a.handle(msg("", estop(true, 11)), ms(20));
        // A resend of release 10, overtaken on the way by e-stop 11.
        let out = a.handle(msg("", estop(false, 10)), ms(30));
        assert!(out.is_empty(), "a stale release is not acknowledged");
        assert_eq!(a.failsafe_state(ms(30)), FailsafeState::EStopped);
        assert_eq!(a.counters().stale_estops, 1);
        a.handle(msg("", estop(false, 12)), ms(40));
        assert_eq!(a.failsafe_state(ms(40)), FailsafeState::Ok);
    }

    #[test]
    fn re_routing_while_estopped_keeps_missions_paused() {
        let mut a = routed("wp/gcs");
        a.handle(msg("wp/gcs", one_waypoint(5)), ms(0));
        a.handle(msg("", estop(true, 1)), ms(10));
        a.handle(msg("", route("joy/0", 2)), ms(20));
        a.handle(msg("", route("wp/gcs", 3)), ms(30));
        a.handle(msg("", estop(false, 2)), ms(40));
        // A resend of the route after the release must not start it either.
        a.handle(msg("", route("wp/gcs", 3)), ms(50));
        assert!(
            !moving(&a.tick(ms(60)).outputs),
            "the mission stays paused until re-sent"
        );
    }
}

#[cfg(test)]
mod latch_tests {
    use super::super::testing::*;
    use super::*;
    use crate::control::{Controller, Gains};

    fn controller() -> Controller {
        Controller::new(PlatformSpec::diff_drive().build(), Gains::default(), true)
    }

    fn one_mission(missions: &mut Missions, bench: &mut Bench) {
        let mission = mission_to(1, 2.0);
        assert!(missions.receive(
            "wp/gcs",
            mission,
            None,
            false,
            "wp/gcs",
            &mut bench.step(ms(0))
        ));
    }

    #[test]
    fn an_estop_idles_the_controller_and_pauses_missions_and_a_release_lifts_only_the_latch() {
        let (mut bench, mut latch, mut c, mut missions) = (
            Bench::new(),
            EStopLatch::default(),
            controller(),
            Missions::default(),
        );
        one_mission(&mut missions, &mut bench);
        c.command(&Command::Twist(Twist::default())).unwrap();
        latch.receive(
            EStop {
                engage: true,
                id: 4,
            },
            &mut c,
            &mut missions,
            &mut bench.step(ms(10)),
        );
        assert!(latch.engaged());
        assert_eq!(*c.mode(), Mode::Idle);
        assert!(!missions.runnable("wp/gcs"), "paused");
        assert_eq!(bench.counters.estopped_at_us, 10_000);
        latch.receive(
            EStop {
                engage: false,
                id: 5,
            },
            &mut c,
            &mut missions,
            &mut bench.step(ms(20)),
        );
        assert!(!latch.engaged());
        assert!(
            !missions.runnable("wp/gcs"),
            "still paused after the release"
        );
        let acks: Vec<_> = bench
            .out
            .iter()
            .filter_map(|e| match &e.body {
                Body::EStopAck(a) => Some((a.engage, a.id)),
                _ => None,
            })
            .collect();
        assert_eq!(acks, [(true, 4), (false, 5)]);
    }

    #[test]
    fn a_repeated_estop_keeps_its_first_time_and_a_restarted_routers_numbering_is_obeyed() {
        let (mut bench, mut latch, mut c, mut missions) = (
            Bench::new(),
            EStopLatch::default(),
            controller(),
            Missions::default(),
        );
        latch.receive(
            EStop {
                engage: true,
                id: 50,
            },
            &mut c,
            &mut missions,
            &mut bench.step(ms(10)),
        );
        latch.receive(
            EStop {
                engage: true,
                id: 51,
            },
            &mut c,
            &mut missions,
            &mut bench.step(ms(20)),
        );
        assert_eq!(
            bench.counters.estopped_at_us, 10_000,
            "when it first stopped"
        );
        latch.receive(
            EStop {
                engage: false,
                id: 1,
            },
            &mut c,
            &mut missions,
            &mut bench.step(ms(30)),
        );
        assert!(latch.engaged(), "older than 51: stale");
        assert_eq!(bench.counters.stale_estops, 1);
        // A restarted router numbers afresh; the robot forgets the order
        // when it registers with it, and the latch holds until released.
        latch.forget_ids();
        assert!(latch.engaged());
        latch.receive(
            EStop {
                engage: false,
                id: 1,
            },
            &mut c,
            &mut missions,
            &mut bench.step(ms(40)),
        );
        assert!(!latch.engaged());
    }
}
