//! Operators' requests to the robot's autopilot (arm, take off, land...):
//! queued for the vehicle that flies it ([`crate::autopilot`]), refused
//! with a notice when the robot has no autopilot, or when it is e-stopped
//! and the request could start it moving.

use mech_proto::{AutopilotRequest, Level, NoticeCode};

use super::step::Step;

/// The requests not yet taken by the vehicle.
#[derive(Debug, Default)]
pub(crate) struct AutopilotRequests {
    /// Whether an autopilot flies this robot.
    fitted: bool,
    queue: Vec<AutopilotRequest>,
}

impl AutopilotRequests {
    pub(crate) fn new(fitted: bool) -> AutopilotRequests {
        AutopilotRequests {
            fitted,
            queue: Vec::new(),
        }
    }

    /// A request: queued, or refused with a notice in the station's event
    /// log.
    pub(crate) fn receive(&mut self, r: AutopilotRequest, estopped: bool, step: &mut Step) {
        if r.robot != step.robot() {
            step.counters.not_for_me += 1;
            return;
        }
        let refusal = if !self.fitted {
            Some(format!(
                "{} has no autopilot: {} refused",
                step.robot(),
                r.action.as_str()
            ))
        } else if estopped && r.action.starts_motion() {
            Some(format!(
                "{} is e-stopped: {} refused until release",
                step.robot(),
                r.action.as_str()
            ))
        } else {
            None
        };
        match refusal {
            Some(text) => {
                step.counters.refused += 1;
                step.notice(
                    mech_proto::ROUTER,
                    Level::Warn,
                    NoticeCode::Unsupported,
                    &text,
                );
            }
            None => self.queue.push(r),
        }
    }

    /// The requests received since the last call, oldest first.
    pub(crate) fn take(&mut self) -> Vec<AutopilotRequest> {
        std::mem::take(&mut self.queue)
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;
    use super::*;
    use mech_proto::AutopilotAction;

    fn request(robot: &str, action: AutopilotAction) -> AutopilotRequest {
        AutopilotRequest {
            robot: robot.into(),
            action,
            altitude: 1.0,
        }
    }

    #[test]
    fn requests_are_queued_in_order_and_taken_once() {
        let mut bench = Bench::new();
        let mut q = AutopilotRequests::new(true);
        q.receive(
            request("r1", AutopilotAction::Arm),
            false,
            &mut bench.step(ms(0)),
        );
        q.receive(
            request("r1", AutopilotAction::Takeoff),
            false,
            &mut bench.step(ms(1)),
        );
        q.receive(
            request("r2", AutopilotAction::Land),
            false,
            &mut bench.step(ms(2)),
        );
        assert_eq!(bench.counters.not_for_me, 1);
        let actions: Vec<_> = q.take().into_iter().map(|r| r.action).collect();
        assert_eq!(actions, [AutopilotAction::Arm, AutopilotAction::Takeoff]);
        assert!(q.take().is_empty());
        assert!(bench.out.is_empty());
    }

    #[test]
    fn while_estopped_only_what_cannot_start_motion_is_queued() {
        let mut bench = Bench::new();
        let mut q = AutopilotRequests::new(true);
        q.receive(
            request("r1", AutopilotAction::Arm),
            true,
            &mut bench.step(ms(0)),
        );
        q.receive(
            request("r1", AutopilotAction::Land),
            true,
            &mut bench.step(ms(1)),
        );
        let actions: Vec<_> = q.take().into_iter().map(|r| r.action).collect();
        assert_eq!(actions, [AutopilotAction::Land]);
        assert_eq!(bench.counters.refused, 1);
        assert!(
            matches!(&bench.out[..], [e] if matches!(&e.body, Body::Notice(n)
                if n.code == NoticeCode::Unsupported && n.text.contains("e-stopped")))
        );
    }
}
