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
            return self.drop_for(DropReason::NotRouted);
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
    /// it; counts the outcome for the robot and the channel (which
    /// [`Tables::note_publisher`] created).
    fn check_route(
        &mut self,
        robot: &str,
        channel: &str,
        cx: &mut Ctx<'_>,
    ) -> Result<Peer, DropReason> {
        let timeout = self.config.link_timeout;
        let outcome = match self.robots.get_mut(robot) {
            None => Err(DropReason::UnknownRobot),
            Some(r) if r.route.is(channel) => {
                r.traffic.forwarded += 1;
                r.meter.sent();
                r.links
                    .target(cx.now, timeout)
                    .ok_or(DropReason::UnknownRobot)
            }
            Some(r) => {
                r.traffic.dropped.count(DropReason::NotRouted);
                Err(DropReason::NotRouted)
            }
        };
        let traffic = self.channels.traffic_mut(channel);
        match outcome {
            Ok(_) => {
                self.totals.forwarded += 1;
                if let Some(t) = traffic {
                    t.forwarded += 1;
                }
            }
            Err(reason) => match traffic {
                Some(t) => t.dropped.count(reason),
                None => self.totals.dropped.count(reason),
            },
        }
        outcome
    }
}
