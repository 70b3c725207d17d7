//! Commands, the hot path: a command is forwarded, bytes unchanged (but
//! signed for the robot when the station authenticates), only to a robot
//! routed to its channel; a fleet command is split so each routed
//! robot gets only its part; a cluster command goes to the controller that
//! serves the channel. Every publisher is noted with its channel's rate.

use mech_proto::{Body, ClusterCommand, Envelope, FleetCommand, Header};
use tracing::warn;

use super::{Ctx, Delivery, Incoming, Peer, Tables};
use crate::counters::DropReason;
use crate::event::Event;

impl Tables {
    /// The hot path: forward a command if its robot is routed to its channel.
    pub(super) fn route_command(
        &mut self,
        head: &mech_proto::Peek<'_>,
        bytes: &[u8],
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        let (sender, destination, channel) = (head.sender, head.destination, head.channel);
        if channel.is_empty() {
            return self.ledger.dropped(DropReason::NotRouted);
        }
        self.note_publisher(sender, channel, cx);
        match self.check_route(destination, channel, cx) {
            Ok(to) => {
                self.pass_on(bytes, to, destination, cx);
                Delivery::Forwarded(1)
            }
            Err(reason) => Delivery::Dropped(reason),
        }
    }

    pub(super) fn on_fleet_command(
        &mut self,
        m: Incoming<'_>,
        fc: FleetCommand,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        let (h, channel) = (m.header, m.header.channel.as_str());
        self.note_publisher(&h.sender, channel, cx);
        let mut delivered = 0;
        for part in fc.parts {
            let Ok(target) = self.check_route(&part.robot, channel, cx) else {
                continue;
            };
            let header = Header {
                destination: part.robot.clone(),
                ..h.clone()
            };
            match mech_proto::encode(&Envelope::new(header, Body::Command(part.command))) {
                Ok(mut b) => {
                    b.pop(); // the nil auth element: signed for the robot
                    if let Some(b) = self.gate.seal(&b, &part.robot, cx.station_us) {
                        cx.send(target, b);
                        delivered += 1;
                    }
                }
                Err(e) => {
                    warn!(error = %e, robot = %part.robot, "cannot re-encode fleet command part")
                }
            }
        }
        Delivery::Forwarded(delivered)
    }

    pub(super) fn on_cluster(
        &mut self,
        m: Incoming<'_>,
        command: ClusterCommand,
        cx: &mut Ctx<'_>,
    ) -> Delivery {
        let channel = &m.header.channel;
        self.note_publisher(&m.header.sender, channel, cx);
        cx.event(Event::ClusterCommand {
            channel: channel.clone(),
            command,
        });
        Delivery::Consumed
    }

    /// Whether `robot` obeys `channel` now, and on which link to send to
    /// it; the outcome is counted by the ledger for the robot, the channel
    /// (which [`Tables::note_publisher`] created) and the router.
    fn check_route(
        &mut self,
        robot: &str,
        channel: &str,
        cx: &mut Ctx<'_>,
    ) -> Result<Peer, DropReason> {
        let on = self.channels.tally_mut(channel);
        let Some(r) = self.robots.get_mut(robot) else {
            return Err(self.ledger.dropped_on(DropReason::UnknownRobot, on));
        };
        if !r.route.is(channel) {
            return Err(self.ledger.not_routed(&mut r.traffic, on));
        }
        r.meter.sent();
        let to = r.links.target(cx.now, self.config.link_timeout);
        self.ledger.forwarded(&mut r.traffic, on, to)
    }
}
