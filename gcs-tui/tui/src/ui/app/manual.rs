//! Manual control on the App: keyboard teleop and gamepads, their outputs
//! turned into publish, cluster-velocity and e-stop requests, on the
//! App's own clock.

use std::time::Instant;

use mech_proto::Command;

use super::{App, LogLevel, Request};
use crate::gamepad::{DriveKey, Mapped, PadEvent, TeleopAction, TeleopOutput};

impl App {
    /// Time moves on: held pads and keys republish at their rate, and a key
    /// no longer held stops.
    pub(super) fn tick(&mut self, now: Instant) {
        self.now = now;
        let out = self.teleop.tick(now);
        self.teleop_outputs(out);
        if let Some(c) = self.key_teleop.tick(now) {
            let channel = self.key_channel.clone();
            self.publish(&channel, c);
        }
    }

    /// Turns keyboard teleop on or off; turning it off mid-drive publishes
    /// one stop.
    pub(super) fn toggle_key_teleop(&mut self) {
        self.key_teleop_on = !self.key_teleop_on;
        if !self.key_teleop_on && self.key_teleop.driving() {
            self.drive_stop();
        }
        let state = if self.key_teleop_on { "on" } else { "off" };
        self.log(
            LogLevel::Info,
            format!("keyboard teleop {state} (channel {})", self.key_channel),
        );
    }

    /// A drive key pressed (or repeated) in keyboard teleop.
    pub(super) fn drive(&mut self, key: DriveKey) {
        if let Some(c) = self.key_teleop.press(key, self.now) {
            let channel = self.key_channel.clone();
            self.publish(&channel, c);
        }
    }

    /// Keyboard teleop's stop: publishes one zero command.
    pub(super) fn drive_stop(&mut self) {
        let c = self.key_teleop.stop(self.now);
        let channel = self.key_channel.clone();
        self.publish(&channel, c);
    }

    /// One gamepad event through the pads' publish logic.
    pub(super) fn pad(&mut self, ev: &PadEvent) {
        let out = self.teleop.handle(ev, self.now);
        self.teleop_outputs(out);
    }

    /// Queues `command` on `channel` for the robots routed to it.
    fn publish(&mut self, channel: &str, command: Command) {
        let robots: Vec<String> = self
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
                    let Some(cluster) = self
                        .active_cluster
                        .as_ref()
                        .and_then(|n| self.clusters.iter().find(|c| &c.name == n))
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
                    self.log(LogLevel::Info, format!("{} mode {}", o.channel, m.as_str()));
                }
            }
        }
    }
}
