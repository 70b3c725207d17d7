//! In-process controllers: a [`Publisher`] publishes on one channel under
//! one sender name (the TUI's keyboard, a gamepad, a fleet or offboard
//! controller), [`Publishers`] one per channel under one name. What they
//! publish takes exactly the path of a message from a peer.

use std::collections::HashMap;

use mech_proto::{Body, Command, FleetCommand, RobotCommand};

use super::handle::envelope;
use super::tables::Delivery;
use super::{RouterError, RouterHandle};

/// Making in-process publishers.
impl RouterHandle {
    /// An in-process publisher on `channel`, named `sender` (e.g. `gamepad`
    /// on `joy/0`). Its commands take the same routing path as UDP ones.
    pub fn publisher(&self, sender: &str, channel: &str) -> Publisher {
        Publisher {
            router: self.clone(),
            sender: sender.to_string(),
            channel: channel.to_string(),
            seq: 0,
        }
    }

    /// In-process publishers named `sender`, one per channel, made on first
    /// use.
    pub fn publishers(&self, sender: &str) -> Publishers {
        Publishers {
            router: self.clone(),
            sender: sender.to_string(),
            by_channel: HashMap::new(),
        }
    }
}

/// An in-process controller publishing on one channel (the TUI's keyboard,
/// a gamepad, a fleet or offboard controller).
#[derive(Debug, Clone)]
pub struct Publisher {
    router: RouterHandle,
    sender: String,
    channel: String,
    seq: u32,
}

impl Publisher {
    pub fn channel(&self) -> &str {
        &self.channel
    }

    /// Publishes one command for `robot`; it is forwarded only if the robot
    /// is routed to this publisher's channel.
    pub async fn send(&mut self, robot: &str, command: Command) -> Result<Delivery, RouterError> {
        self.send_body(robot, Body::Command(command)).await
    }

    /// Publishes commands for several robots at once; each robot routed to
    /// this channel receives only its own part.
    pub async fn send_fleet(&mut self, parts: Vec<RobotCommand>) -> Result<Delivery, RouterError> {
        self.send_body(
            mech_proto::ROUTER,
            Body::FleetCommand(FleetCommand { parts }),
        )
        .await
    }

    /// Publishes any body on this channel.
    pub async fn send_body(
        &mut self,
        destination: &str,
        body: Body,
    ) -> Result<Delivery, RouterError> {
        self.seq = self.seq.wrapping_add(1);
        let env = envelope(&self.sender, destination, &self.channel, self.seq, body);
        let bytes = mech_proto::encode(&env)?;
        Ok(self.router.inject(&bytes).await)
    }
}

/// In-process publishers under one sender name, one per channel, made on
/// first use: a channel keeps one steady publisher, so its sequence numbers
/// run on and the router's per-channel rate is that publisher's.
#[derive(Debug)]
pub struct Publishers {
    router: RouterHandle,
    sender: String,
    by_channel: HashMap<String, Publisher>,
}

impl Publishers {
    /// The publisher on `channel`.
    pub fn on(&mut self, channel: &str) -> &mut Publisher {
        let (router, sender) = (&self.router, &self.sender);
        self.by_channel
            .entry(channel.to_string())
            .or_insert_with(|| router.publisher(sender, channel))
    }
}
