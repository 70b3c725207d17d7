//! Commands from Zenoh into the station. A command published on
//! `mech/<station>/<robot>/cmd/<channel>` enters the router as an
//! in-process publisher's, under the bridge's sender name (`zenoh.identity`)
//! on that channel: the router forwards it only if the robot is routed to
//! the channel, exactly as for a local controller. When the station
//! authenticates, `[auth]`'s key of that name must permit the channel
//! first. A bad key or payload is refused, counted and logged; nothing
//! reaches the router that did not parse and check.

use std::sync::Arc;

use mech_core::{Delivery, Gcs};
use mech_proto::{Body, Command};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tracing::warn;
use zenoh::Session;
use zenoh::pubsub::Subscriber;
use zenoh::sample::{Locality, Sample};

use crate::keys::{self, Key};
use crate::payload::CommandMsg;
use crate::stats::Stats;

/// Commands waiting for the router. Beyond this many the newest are
/// dropped and counted: a command late by a full queue is worse than none.
const QUEUE: usize = 1024;

/// One command on its way into the station.
#[derive(Debug)]
struct Incoming {
    robot: String,
    channel: String,
    command: Command,
}

/// The command intake: its subscription and the task that feeds the router.
#[derive(Debug)]
pub(crate) struct Intake {
    pub(crate) subscriber: Subscriber<()>,
    pub(crate) task: JoinHandle<()>,
}

/// Subscribes to this station's command keys and starts forwarding.
pub(crate) async fn declare(
    session: &Session,
    station: &str,
    identity: &str,
    gcs: Gcs,
    stats: Arc<Stats>,
) -> zenoh::Result<Intake> {
    let (tx, rx) = mpsc::channel(QUEUE);
    let task = tokio::spawn(forward(rx, gcs, identity.to_string(), stats.clone()));
    let key = format!("{}/{station}/*/cmd/**", keys::ROOT);
    let subscriber = session
        .declare_subscriber(key)
        .allowed_origin(Locality::Any)
        .callback(move |sample| heard(&sample, &tx, &stats))
        .await?;
    Ok(Intake { subscriber, task })
}

/// Checks one sample and queues its command.
fn heard(sample: &Sample, tx: &mpsc::Sender<Incoming>, stats: &Stats) {
    let key = sample.key_expr().as_str();
    let (robot, channel) = match keys::parse(key) {
        Ok(Key::Command { robot, channel, .. }) => (robot, channel),
        Ok(_) => return stats.bad_input(&format!("{key:?} is not a command key")),
        Err(e) => return stats.bad_input(&e),
    };
    let command = match CommandMsg::read(&sample.payload().to_bytes()) {
        Ok(c) => c,
        Err(e) => return stats.bad_input(&format!("command on {key:?}: {e}")),
    };
    let incoming = Incoming {
        robot: robot.to_string(),
        channel: channel.to_string(),
        command,
    };
    if tx.try_send(incoming).is_err() {
        Stats::bump(&stats.commands_overflow);
    }
}

/// Publishes queued commands into the router, after `[auth]`'s word on the
/// bridge's identity.
async fn forward(mut rx: mpsc::Receiver<Incoming>, gcs: Gcs, identity: String, stats: Arc<Stats>) {
    let router = gcs.router().clone();
    let mut publishers = router.publishers(&identity);
    while let Some(c) = rx.recv().await {
        let body = Body::Command(c.command);
        if router.permit_as(&identity, &body, &c.channel).is_err() {
            Stats::bump(&stats.commands_refused);
            continue;
        }
        let Body::Command(command) = body else {
            continue;
        };
        match publishers.on(&c.channel).send(&c.robot, command).await {
            Ok(Delivery::Forwarded(n)) if n > 0 => Stats::bump(&stats.commands_forwarded),
            Ok(_) => Stats::bump(&stats.commands_dropped),
            Err(e) => {
                warn!(robot = %c.robot, channel = %c.channel, error = %e, "cannot publish a command from Zenoh");
                Stats::bump(&stats.commands_dropped);
            }
        }
    }
}
