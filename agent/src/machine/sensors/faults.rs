//! Driver and actuator faults: counted, told to the station at most once a
//! second, and, for the actuators, held: the outputs stay at zero (failsafe
//! state `Fault`) for a second, then the robot obeys commands again if the
//! driver recovered.

use std::time::Duration;

use mech_proto::{Level, NoticeCode};

use super::super::step::Step;
use crate::control::Controller;

/// How long a fault shows in health, and holds the actuators.
const FAULT_HOLD: Duration = Duration::from_secs(1);

/// When drivers last failed.
#[derive(Debug, Default)]
pub(crate) struct Faults {
    last_driver_fault: Option<Duration>,
    /// Actuators are held at zero until then after an actuator driver error.
    actuator_fault_until: Option<Duration>,
}

impl Faults {
    /// An actuator or position driver failed: counted; the station is told
    /// unless it was told less than a second ago.
    pub(crate) fn driver_fault(&mut self, what: &str, step: &mut Step) {
        step.counters.driver_faults += 1;
        let recent = self.recent(step.now);
        self.last_driver_fault = Some(step.now);
        if !recent {
            step.notice(
                mech_proto::ROUTER,
                Level::Error,
                NoticeCode::DriverFault,
                what,
            );
        }
    }

    /// Writing the actuators failed (or a wheel stalled): the controller
    /// idles and the outputs are held at zero for a second.
    pub(crate) fn actuator_fault(
        &mut self,
        what: &str,
        controller: &mut Controller,
        step: &mut Step,
    ) {
        self.actuator_fault_until = Some(step.now + FAULT_HOLD);
        controller.idle();
        self.driver_fault(what, step);
    }

    /// The vehicle cannot be driven now (a ROS 2 base without odometry):
    /// the outputs are held at zero until `until`, the controller (a
    /// mission) kept for when it can. Counted and told as a fault when a
    /// hold begins (no fault in the second before), not for each period
    /// it lasts.
    pub(crate) fn hold(&mut self, what: &str, until: Duration, step: &mut Step) {
        let held = self.actuators_held(step.now) || self.recent(step.now);
        self.actuator_fault_until = Some(self.actuator_fault_until.map_or(until, |t| t.max(until)));
        if held {
            self.last_driver_fault = Some(step.now);
        } else {
            self.driver_fault(what, step);
        }
    }

    /// Whether the actuators are held after an actuator fault.
    pub(crate) fn actuators_held(&self, now: Duration) -> bool {
        self.actuator_fault_until.is_some_and(|t| now < t)
    }

    /// A driver failed within the last second: health `Fault`.
    pub(crate) fn recent(&self, now: Duration) -> bool {
        self.last_driver_fault
            .is_some_and(|t| now.saturating_sub(t) < FAULT_HOLD)
    }
}

#[cfg(test)]
mod tests {
    use super::super::super::testing::*;

    #[test]
    fn actuator_fault_holds_outputs_at_zero_then_recovers() {
        let mut a = routed("joy/0");
        a.handle(msg("joy/0", twist(0.2)), ms(10));
        assert!(moving(&a.tick(ms(20)).outputs));
        assert!(a.actuator_fault("left motor: I/O error", ms(25)).is_some());
        assert!(
            a.actuator_fault("left motor: I/O error", ms(26)).is_none(),
            "one notice a second"
        );
        a.handle(msg("joy/0", twist(0.2)), ms(30));
        let t = a.tick(ms(40));
        assert!(!moving(&t.outputs));
        assert_eq!(a.failsafe_state(ms(40)), FailsafeState::Fault);
        assert_eq!(a.telemetry(ms(40)).health, Health::Fault);
        router_heartbeat(&mut a, ms(1100));
        a.handle(msg("joy/0", twist(0.2)), ms(1100));
        assert!(
            moving(&a.tick(ms(1110)).outputs),
            "recovers once the driver works"
        );
        assert_eq!(a.counters().driver_faults, 2);
    }

    #[test]
    fn a_hold_keeps_the_mission_and_is_told_once() {
        let mut a = routed("wp/gcs");
        a.handle(msg("wp/gcs", one_waypoint(1)), ms(10));
        assert!(moving(&a.tick(ms(10)).outputs), "the mission drives");
        assert!(a.hold_outputs("no odometry", ms(21), ms(20)).is_some());
        assert!(!moving(&a.tick(ms(20)).outputs));
        assert_eq!(a.failsafe_state(ms(20)), FailsafeState::Fault);
        for t in (70..=1070u64).step_by(50) {
            router_heartbeat(&mut a, ms(t));
            assert!(a.hold_outputs("no odometry", ms(t + 1), ms(t)).is_none());
            assert!(!moving(&a.tick(ms(t)).outputs));
        }
        assert_eq!(a.counters().driver_faults, 1, "one hold, however long");
        // Held no more, a second after the last (as after any fault): the
        // mission was kept (an actuator fault ends it), and drives again.
        for t in (1120..=2100u64).step_by(50) {
            router_heartbeat(&mut a, ms(t));
            a.tick(ms(t));
        }
        router_heartbeat(&mut a, ms(2150));
        assert!(moving(&a.tick(ms(2150)).outputs));
    }
}
