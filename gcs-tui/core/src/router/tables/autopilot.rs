//! Autopilot requests (arm, disarm, mode changes, land, take off): an
//! operator's request goes to the named robot whatever its route, signed
//! for it; the robot answers with a notice. The gate lets only operators
//! (and the station's own operator, in process) send one.

use mech_proto::AutopilotRequest;
use tracing::info;

use super::{Ctx, Delivery, Incoming, Tables};
use crate::counters::DropReason;

impl Tables {
    pub(super) fn on_autopilot(
        &mut self,
        m: Incoming<'_>,
        request: AutopilotRequest,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        let Some(entry) = self.robots.get_mut(&request.robot) else {
            return self.ledger.dropped(DropReason::UnknownRobot);
        };
        let to = entry.links.target(cx.now, self.config.link_timeout);
        // Sent whatever the robot's route: counted by no channel.
        let Ok(to) = self.ledger.forwarded(&mut entry.traffic, None, to) else {
            return Delivery::Dropped(DropReason::UnknownRobot);
        };
        info!(
            robot = %request.robot,
            action = request.action.as_str(),
            from = %m.header.sender,
            "autopilot request"
        );
        self.pass_on(m.bytes, to, &request.robot, cx);
        Delivery::Forwarded(1)
    }
}
