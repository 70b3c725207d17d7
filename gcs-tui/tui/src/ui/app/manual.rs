//! Manual control: keyboard teleop and gamepads, on the App's own clock,
//! their outputs turned into publish, cluster-velocity and e-stop requests.

use std::time::Instant;

use mech_proto::Command;

use super::{App, LogLevel, Request};
use crate::gamepad::{
    DriveKey, KEY_CHANNEL, KeyTeleop, Mapped, PadEvent, PadState, Teleop, TeleopAction,
    TeleopConfig, TeleopOutput,
};

/// The gamepads and the keyboard's teleop, and the time they run on.
#[derive(Debug, Clone)]
pub struct ManualControl {
    /// Connected pads and their publish logic.
    pub pads: Teleop,
    pub keys: KeyTeleop,
    /// Keyboard teleop is on: the drive keys drive.
    pub keys_on: bool,
    /// The channel keyboard teleop publishes on (the station names it).
    pub key_channel: String,
    /// The App's clock, moved on by each tick.
    pub now: Instant,
}

impl ManualControl {
    /// No pads, keyboard teleop off on [`KEY_CHANNEL`], the clock at `now`.
    pub fn new(now: Instant) -> ManualControl {
        ManualControl {
            pads: Teleop::new(TeleopConfig::default()),
            keys: KeyTeleop::default(),
            keys_on: false,
            key_channel: KEY_CHANNEL.to_string(),
            now,
        }
    }
}

impl App {
    /// Connected pads, for display.
    pub fn pads(&self) -> Vec<&PadState> {
        self.manual.pads.pads().collect()
    }

    /// Time moves on: held pads and keys republish at their rate, and a key
    /// no longer held stops.
    pub(super) fn tick(&mut self, now: Instant) {
        self.manual.now = now;
        let out = self.manual.pads.tick(now);
        self.teleop_outputs(out);
        if let Some(c) = self.manual.keys.tick(now) {
            self.publish_keys(c);
        }
    }

    /// Turns keyboard teleop on or off; turning it off mid-drive publishes
    /// one stop.
    pub(super) fn toggle_key_teleop(&mut self) {
        let m = &mut self.manual;
        m.keys_on = !m.keys_on;
        if !m.keys_on && m.keys.driving() {
            self.drive_stop();
        }
        let state = if self.manual.keys_on { "on" } else { "off" };
        let line = format!(
            "keyboard teleop {state} (channel {})",
            self.manual.key_channel
        );
        self.log(LogLevel::Info, line);
    }

    /// A drive key pressed (or repeated) in keyboard teleop.
    pub(super) fn drive(&mut self, key: DriveKey) {
        if let Some(c) = self.manual.keys.press(key, self.manual.now) {
            self.publish_keys(c);
        }
    }

    /// Keyboard teleop's stop: publishes one zero command.
    pub(super) fn drive_stop(&mut self) {
        let c = self.manual.keys.stop(self.manual.now);
        self.publish_keys(c);
    }

    /// One gamepad event through the pads' publish logic.
    pub(super) fn pad(&mut self, ev: &PadEvent) {
        let out = self.manual.pads.handle(ev, self.manual.now);
        self.teleop_outputs(out);
    }

    /// Queues a keyboard teleop command on its channel.
    fn publish_keys(&mut self, command: Command) {
        let channel = self.manual.key_channel.clone();
        self.publish(&channel, command);
    }

    /// Queues `command` on `channel` for the robots routed to it.
    fn publish(&mut self, channel: &str, command: Command) {
        let robots: Vec<String> = self
            .fleet
            .robots
            .iter()
            .filter(|r| r.route.channel == channel)
            .map(|r| r.name.clone())
            .collect();
        self.outbox.push(Request::Publish {
            channel: channel.to_string(),
            robots,
            command,
        });
    }

    /// Turns teleop outputs into requests and log lines; a pad's cluster
    /// velocity goes to the active cluster, or nowhere without one.
    fn teleop_outputs(&mut self, out: Vec<TeleopOutput>) {
        for o in out {
            match o.action {
                TeleopAction::Publish(Mapped::Command(c)) => self.publish(&o.channel, c),
                TeleopAction::Publish(Mapped::Cluster(velocity)) => {
                    let fleet = &self.fleet;
                    let Some(cluster) = fleet
                        .active_cluster
                        .as_ref()
                        .and_then(|n| fleet.clusters.iter().find(|c| &c.name == n))
                    else {
                        continue;
                    };
                    self.outbox.push(Request::ClusterVelocity {
                        cluster: cluster.name.clone(),
                        velocity,
                    });
                }
                TeleopAction::EStop => self.set_estop(true),
                TeleopAction::Connected(name) => {
                    self.log(LogLevel::Info, format!("gamepad {name} on {}", o.channel));
                }
                TeleopAction::Disconnected => {
                    self.log(
                        LogLevel::Warn,
                        format!("gamepad on {} unplugged", o.channel),
                    );
                }
                TeleopAction::ModeChanged(m) => {
                    self.log(LogLevel::Info, format!("{} mode {}", o.channel, m.label()));
                }
            }
        }
    }
}
