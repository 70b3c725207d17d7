//! Failsafe: decides, each control period, whether the robot may drive.
//!
//! Actuators are zeroed when the routed channel has been silent for
//! `channel_timeout` (a running onboard mission is exempt: the mission is the
//! controller), when nothing has been heard from the router for
//! `router_timeout`, while an e-stop is latched, and while an actuator fault
//! holds them. An onboard mission is the one controller the station cannot
//! stop once every link is gone, so for it the router's silence counts from
//! `channel_timeout`, not `router_timeout`: it stops within the same time a
//! silent controller's robot does, and goes on when the router is heard
//! again. It continues through a link loss only if configured to
//! (`mission_continues_on_link_loss`).
//!
//! Each fact is owned by the part of the agent core that learns it (router
//! liveness by registration, channel silence by command intake, each a
//! [`Watchdog`]; the latch by the e-stop; the fault hold by the sensors);
//! this module turns them, gathered as [`Conditions`], into a
//! [`FailsafeState`] and each period's [`Verdict`]. Time is passed in, never
//! read.

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
    /// silent (default: it stops once the router has been silent for
    /// `channel_timeout`, as a robot whose controller went quiet does, since
    /// nobody can stop it while every link is down).
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

/// How long since something was last heard, against a timeout: the
/// router's liveness (kept by registration) and the routed channel's silence
/// (kept by command intake) are each one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Watchdog {
    timeout: Duration,
    last: Option<Duration>,
}

impl Watchdog {
    pub fn new(timeout: Duration) -> Watchdog {
        Watchdog {
            timeout,
            last: None,
        }
    }

    pub fn timeout(&self) -> Duration {
        self.timeout
    }

    /// Something was heard at `now`.
    pub fn heard(&mut self, now: Duration) {
        self.last = Some(now);
    }

    /// Silent from now on, as if never heard (the router said goodbye).
    pub fn forget(&mut self) {
        self.last = None;
    }

    /// Nothing heard yet, or nothing for longer than the timeout.
    pub fn silent(&self, now: Duration) -> bool {
        self.silent_for(self.timeout, now)
    }

    /// Nothing heard yet, or nothing for longer than `timeout` (another
    /// limit than the watchdog's own).
    pub fn silent_for(&self, timeout: Duration, now: Duration) -> bool {
        self.last.is_none_or(|t| now.saturating_sub(t) > timeout)
    }
}

/// What the failsafe judges, as the parts of the agent that own each fact
/// know it now.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Conditions {
    /// An e-stop is latched.
    pub estopped: bool,
    /// Actuators are held at zero after a driver error.
    pub actuator_fault: bool,
    /// Nothing heard from the router for `router_timeout`, or it said Bye.
    pub router_lost: bool,
    /// Nothing heard from the router for `channel_timeout` (every link
    /// silent that long): enough to stop an onboard mission.
    pub link_silent: bool,
    /// The robot has a route (its channel is not empty).
    pub routed: bool,
    /// Nothing accepted on the routed channel for `channel_timeout`.
    pub channel_silent: bool,
    /// A mission on the routed channel is the robot's controller, running or
    /// done: silence on that channel is not a fault.
    pub mission_controls: bool,
}

impl Conditions {
    /// The failsafe state: an e-stop first, then an actuator fault, then
    /// router loss (for a robot a mission controls, the router silent for
    /// the channel timeout), then channel silence.
    pub fn state(&self) -> FailsafeState {
        if self.estopped {
            FailsafeState::EStopped
        } else if self.actuator_fault {
            FailsafeState::Fault
        } else if self.router_lost || (self.mission_controls && self.link_silent) {
            FailsafeState::RouterLost
        } else if self.routed && !self.mission_controls && self.channel_silent {
            FailsafeState::ChannelSilent
        } else {
            FailsafeState::Ok
        }
    }
}

/// One control period's verdict.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Verdict {
    pub state: FailsafeState,
    /// Whether actuators may be driven.
    pub drive: bool,
    /// The state of the period before.
    pub previous: FailsafeState,
}

impl Verdict {
    /// The robot left `Ok` this period: a failsafe trip.
    pub fn tripped(&self) -> bool {
        self.state != FailsafeState::Ok && self.previous == FailsafeState::Ok
    }
}

/// The verdict of each control period, and the state of the last one (so a
/// trip is seen once, when the robot leaves `Ok`).
#[derive(Debug, Clone)]
pub struct Failsafe {
    pub config: FailsafeConfig,
    last: FailsafeState,
}

impl Failsafe {
    pub fn new(config: FailsafeConfig) -> Failsafe {
        Failsafe {
            config,
            // Nothing heard from a router yet: not a trip when the first
            // period finds the router lost.
            last: FailsafeState::RouterLost,
        }
    }

    /// Whether actuators may be driven in `state`; `mission_running`: an
    /// onboard mission is being followed.
    pub fn may_drive(&self, state: FailsafeState, mission_running: bool) -> bool {
        match state {
            FailsafeState::Ok => true,
            FailsafeState::RouterLost => {
                mission_running && self.config.mission_continues_on_link_loss
            }
            _ => false,
        }
    }

    /// This period's verdict in `state`, remembered for the next one.
    pub fn judge(&mut self, state: FailsafeState, mission_running: bool) -> Verdict {
        let verdict = Verdict {
            state,
            drive: self.may_drive(state, mission_running),
            previous: self.last,
        };
        self.last = state;
        verdict
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: fn(u64) -> Duration = Duration::from_millis;

    /// The facts as the agent's parts keep them: the router's and the
    /// channel's watchdogs and the e-stop latch.
    struct Watch {
        router: Watchdog,
        channel: Watchdog,
        estopped: bool,
    }

    impl Watch {
        fn new() -> Watch {
            let c = FailsafeConfig::default();
            Watch {
                router: Watchdog::new(c.router_timeout),
                channel: Watchdog::new(c.channel_timeout),
                estopped: false,
            }
        }

        fn state(&self, now: Duration, routed: bool, mission_running: bool) -> FailsafeState {
            Conditions {
                estopped: self.estopped,
                actuator_fault: false,
                router_lost: self.router.silent(now),
                link_silent: self.router.silent_for(self.channel.timeout(), now),
                routed,
                channel_silent: self.channel.silent(now),
                mission_controls: mission_running,
            }
            .state()
        }
    }

    #[test]
    fn channel_silence_trips_after_the_timeout_only() {
        let mut f = Watch::new();
        // The router is heard meanwhile: only the channel is silent.
        f.router.heard(MS(400));
        f.channel.heard(MS(0));
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
        f.channel.heard(MS(501));
        assert_eq!(f.state(MS(600), true, false), FailsafeState::Ok);
    }

    #[test]
    fn router_loss_and_estop() {
        let mut f = Watch::new();
        let mut failsafe = Failsafe::new(FailsafeConfig::default());
        assert_eq!(
            f.state(MS(0), false, false),
            FailsafeState::RouterLost,
            "never heard"
        );
        f.router.heard(MS(100));
        f.channel.heard(MS(100));
        assert_eq!(f.state(MS(1101), true, true), FailsafeState::RouterLost);
        assert!(!failsafe.may_drive(FailsafeState::RouterLost, true));
        failsafe.config.mission_continues_on_link_loss = true;
        assert!(failsafe.may_drive(FailsafeState::RouterLost, true));
        assert!(!failsafe.may_drive(FailsafeState::RouterLost, false));
        f.estopped = true;
        f.router.heard(MS(1200));
        assert_eq!(f.state(MS(1200), true, false), FailsafeState::EStopped);
        f.estopped = false;
        assert_eq!(f.state(MS(1200), true, false), FailsafeState::ChannelSilent);
    }

    #[test]
    fn a_router_bye_makes_it_lost_at_once() {
        let mut router = Watchdog::new(FailsafeConfig::default().router_timeout);
        router.heard(MS(100));
        assert!(!router.silent(MS(100)));
        router.forget();
        assert!(router.silent(MS(100)));
    }

    #[test]
    fn an_actuator_fault_outranks_everything_but_an_estop() {
        let mut c = Conditions {
            actuator_fault: true,
            router_lost: true,
            routed: true,
            channel_silent: true,
            ..Conditions::default()
        };
        assert_eq!(c.state(), FailsafeState::Fault);
        c.estopped = true;
        assert_eq!(c.state(), FailsafeState::EStopped);
    }

    #[test]
    fn a_trip_is_seen_once_when_the_robot_leaves_ok() {
        let mut f = Failsafe::new(FailsafeConfig::default());
        let lost = f.judge(FailsafeState::RouterLost, false);
        assert!(!lost.tripped() && !lost.drive, "never heard is not a trip");
        let ok = f.judge(FailsafeState::Ok, false);
        assert!(!ok.tripped() && ok.drive);
        let silent = f.judge(FailsafeState::ChannelSilent, false);
        assert!(silent.tripped() && !silent.drive);
        assert_eq!(silent.previous, FailsafeState::Ok);
        assert!(!f.judge(FailsafeState::RouterLost, false).tripped());
    }

    #[test]
    fn a_mission_counts_the_routers_silence_from_the_channel_timeout() {
        let mut f = Watch::new();
        f.router.heard(MS(0));
        f.channel.heard(MS(0));
        assert_eq!(f.state(MS(500), true, true), FailsafeState::Ok);
        assert_eq!(
            f.state(MS(501), true, true),
            FailsafeState::RouterLost,
            "a mission stops once every link has been silent 0.5 s"
        );
        assert_eq!(
            f.state(MS(501), true, false),
            FailsafeState::ChannelSilent,
            "any other robot: its channel's silence, as before"
        );
        assert_eq!(f.state(MS(1001), true, false), FailsafeState::RouterLost);
        f.router.heard(MS(600));
        assert_eq!(
            f.state(MS(700), true, true),
            FailsafeState::Ok,
            "heard again"
        );
    }
}
