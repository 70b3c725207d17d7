//! The fleet model as events: what a replay applies first so that a file
//! begun mid-run (`record start`, or the next file of a rotation) shows the
//! arena, robots, routes, safety switches, missions and e-stop as they
//! stood. Applying them to an empty [`Fleet`] gives the same arena, robots,
//! routes, switches, missions, e-stop and last telemetry (trails and log
//! lines start afresh).

use mech_proto::Hello;

use crate::event::{Event, LinkState};
use crate::fleet::{Fleet, MissionDelivery, Robot};

/// Events that rebuild `fleet`.
pub(crate) fn events(fleet: &Fleet) -> Vec<Event> {
    let mut out = Vec::new();
    if let Some(udp) = fleet.udp {
        out.push(Event::Listening {
            udp,
            tcp: fleet.tcp,
        });
    }
    if fleet.arena.is_some() {
        out.push(Event::Arena {
            arena: fleet.arena.clone(),
        });
    }
    for r in fleet.robots.values() {
        robot(r, &mut out);
    }
    if fleet.estop.id != 0 {
        out.push(Event::EStop {
            engage: fleet.estop.engaged,
            id: fleet.estop.id,
        });
    }
    out
}

fn robot(r: &Robot, out: &mut Vec<Event>) {
    let name = r.name.clone();
    out.push(Event::Registered {
        hello: Hello {
            name: name.clone(),
            ..r.registration.hello.clone()
        },
        id: r.registration.id,
        addr: r.registration.addr.clone(),
        known: false,
    });
    if r.route.epoch != 0 {
        out.push(Event::RouteChanged {
            robot: name.clone(),
            channel: r.route.requested.clone(),
            epoch: r.route.epoch,
        });
    }
    if r.route.acked_epoch != 0 {
        out.push(Event::RouteAcked {
            robot: name.clone(),
            channel: r.route.acknowledged.clone(),
            epoch: r.route.acked_epoch,
        });
    }
    mission(r, out);
    if !r.safety_enabled {
        out.push(Event::SafetySwitched {
            robot: name.clone(),
            enabled: false,
            id: r.telemetry.safety.map_or(0, |s| s.arena),
        });
    }
    if r.last_telemetry.is_some() {
        out.push(Event::Telemetry {
            robot: name.clone(),
            telemetry: r.telemetry.clone(),
        });
    }
    if r.link != LinkState::Connected {
        out.push(Event::Link {
            robot: name,
            state: r.link,
        });
    }
}

fn mission(r: &Robot, out: &mut Vec<Event>) {
    let Some(sent) = &r.waypoints.sent else {
        return;
    };
    let robot = r.name.clone();
    out.push(Event::MissionSent {
        robot: robot.clone(),
        channel: sent.channel.clone(),
        id: sent.id,
        waypoints: sent.waypoints.clone(),
        looped: sent.looped,
    });
    let id = sent.id;
    match &sent.delivery {
        MissionDelivery::Sending => {}
        // A lost mission was acknowledged before its robot restarted; the
        // snapshot replays the acknowledgement (the loss is not restated).
        MissionDelivery::Acked | MissionDelivery::Lost => out.push(Event::MissionAcked {
            robot,
            id,
            accepted: true,
            reason: String::new(),
        }),
        MissionDelivery::Refused(reason) => out.push(Event::MissionAcked {
            robot,
            id,
            accepted: false,
            reason: reason.clone(),
        }),
        MissionDelivery::Failed(reason) => out.push(Event::MissionFailed {
            robot,
            id,
            reason: reason.clone(),
        }),
    }
}
