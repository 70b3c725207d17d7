//! Failsafe: decides, each control period, whether the robot may drive.
//!
//! Actuators are zeroed when the routed channel has been silent for
//! `channel_timeout` (a running onboard mission is exempt: the mission is the
//! controller), when nothing has been heard from the router for
//! `router_timeout` (a mission continues only if configured to), and while an
//! e-stop is latched. Time is passed in, never read.

use std::time::Duration;

use mech_proto::FailsafeState;
use serde::Deserialize;

/// Failsafe settings, the config's `[failsafe]` table.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FailsafeConfig {
    /// Silence on the routed channel that stops the robot (default 0.5 s,
    /// as twist_mux, PX4 RC loss and Crazyflie use).
    pub channel_timeout: Duration,
    /// Silence from the router that declares it lost (default 1 s, four
    /// router heartbeats).
    pub router_timeout: Duration,
    /// Whether an onboard waypoint mission keeps running when the router is
    /// lost (default: stop).
    pub mission_continues_on_link_loss: bool,
}

impl Default for FailsafeConfig {
    fn default() -> Self {
        FailsafeConfig {
            channel_timeout: Duration::from_millis(500),
            router_timeout: Duration::from_secs(1),
            mission_continues_on_link_loss: false,
        }
    }
}

/// The `[failsafe]` table as written (seconds).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FailsafeToml {
    pub channel_timeout: f64,
    pub router_timeout: f64,
    pub mission_continues_on_link_loss: bool,
}

impl Default for FailsafeToml {
    fn default() -> Self {
        let d = FailsafeConfig::default();
        FailsafeToml {
            channel_timeout: d.channel_timeout.as_secs_f64(),
            router_timeout: d.router_timeout.as_secs_f64(),
            mission_continues_on_link_loss: d.mission_continues_on_link_loss,
        }
    }
}

/// Liveness timers and the e-stop latch.
#[derive(Debug, Clone)]
pub struct Failsafe {
    pub config: FailsafeConfig,
    last_router: Option<Duration>,
    last_command: Option<Duration>,
    estop: Option<u32>,
}

impl Failsafe {
    pub fn new(config: FailsafeConfig) -> Failsafe {
        Failsafe {
            config,
            last_router: None,
            last_command: None,
            estop: None,
        }
    }

    /// Anything arrived from the router.
    pub fn router_heard(&mut self, now: Duration) {
        self.last_router = Some(now);
    }

    /// The router said goodbye: it counts as lost from now on.
    pub fn router_gone(&mut self) {
        self.last_router = None;
    }

    /// A command on the routed channel was accepted, or the route changed
    /// (which restarts the channel-silence timer).
    pub fn channel_heard(&mut self, now: Duration) {
        self.last_command = Some(now);
    }

    pub fn engage_estop(&mut self, id: u32) {
        self.estop = Some(id);
    }

    pub fn release_estop(&mut self) {
        self.estop = None;
    }

    pub fn estopped(&self) -> bool {
        self.estop.is_some()
    }

    pub fn router_lost(&self, now: Duration) -> bool {
        self.last_router
            .is_none_or(|t| now.saturating_sub(t) > self.config.router_timeout)
    }

    pub fn channel_silent(&self, now: Duration) -> bool {
        self.last_command
            .is_none_or(|t| now.saturating_sub(t) > self.config.channel_timeout)
    }

    /// The failsafe state now. `routed`: the robot has a route (channel not
    /// empty); `mission_running`: an onboard mission is being followed.
    pub fn state(&self, now: Duration, routed: bool, mission_running: bool) -> FailsafeState {
        if self.estopped() {
            FailsafeState::EStopped
        } else if self.router_lost(now) {
            FailsafeState::RouterLost
        } else if routed && !mission_running && self.channel_silent(now) {
            FailsafeState::ChannelSilent
        } else {
            FailsafeState::Ok
        }
    }

    /// Whether actuators may be driven in `state`.
    pub fn may_drive(&self, state: FailsafeState, mission_running: bool) -> bool {
        match state {
            FailsafeState::Ok => true,
            FailsafeState::RouterLost => {
                mission_running && self.config.mission_continues_on_link_loss
            }
            _ => false,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: fn(u64) -> Duration = Duration::from_millis;

    #[test]
    fn channel_silence_trips_after_the_timeout_only() {
        let mut f = Failsafe::new(FailsafeConfig::default());
        f.router_heard(MS(0));
        f.channel_heard(MS(0));
        assert_eq!(f.state(MS(500), true, false), FailsafeState::Ok);
        assert_eq!(f.state(MS(501), true, false), FailsafeState::ChannelSilent);
        assert_eq!(
            f.state(MS(501), false, false),
            FailsafeState::Ok,
            "unrouted robots hold still anyway"
        );
        assert_eq!(
            f.state(MS(501), true, true),
            FailsafeState::Ok,
            "a mission is not subject to silence"
        );
        f.channel_heard(MS(501));
        assert_eq!(f.state(MS(600), true, false), FailsafeState::Ok);
    }

    #[test]
    fn router_loss_and_estop() {
        let mut f = Failsafe::new(FailsafeConfig::default());
        assert_eq!(
            f.state(MS(0), false, false),
            FailsafeState::RouterLost,
            "never heard"
        );
        f.router_heard(MS(100));
        f.channel_heard(MS(100));
        assert_eq!(f.state(MS(1101), true, true), FailsafeState::RouterLost);
        assert!(!f.may_drive(FailsafeState::RouterLost, true));
        f.config.mission_continues_on_link_loss = true;
        assert!(f.may_drive(FailsafeState::RouterLost, true));
        assert!(!f.may_drive(FailsafeState::RouterLost, false));
        f.engage_estop(3);
        f.router_heard(MS(1200));
        assert_eq!(f.state(MS(1200), true, false), FailsafeState::EStopped);
        f.release_estop();
        assert_eq!(f.state(MS(1200), true, false), FailsafeState::ChannelSilent);
    }
}
