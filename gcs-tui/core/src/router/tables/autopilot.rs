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
            return self.drop_for(DropReason::UnknownRobot);
        };
        entry.traffic.forwarded += 1;
        let Some(to) = self.target(&request.robot, cx.now) else {
            return self.drop_for(DropReason::UnknownRobot);
        };
        self.totals.forwarded += 1;
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
