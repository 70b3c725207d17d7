//! Telemetry: when it is due (on a fixed grid, so the rate does not drift
//! with jitter), and what one message says, gathered from the parts of the
//! core as a [`Snapshot`].

use std::time::Duration;

use mech_proto::{
    Computation, ControlMode, FailsafeState, Health, MissionProgress, SafetyReport, Telemetry,
};

use super::sensors::Motion;

/// When the next telemetry is due.
#[derive(Debug)]
pub(crate) struct TelemetrySchedule {
    period: Duration,
    next: Duration,
}

impl TelemetrySchedule {
    pub(crate) fn new(period: Duration) -> TelemetrySchedule {
        TelemetrySchedule {
            period,
            next: Duration::ZERO,
        }
    }

    /// Whether telemetry is due at `now`; if so, the next one is scheduled.
    pub(crate) fn due(&mut self, now: Duration) -> bool {
        if now < self.next {
            return false;
        }
        // Stay on the grid so the rate does not drift with jitter.
        self.next = (self.next + self.period).max(now);
        true
    }
}

/// What a telemetry message says, as the agent's parts know it now.
#[derive(Debug)]
pub(crate) struct Snapshot<'a> {
    pub(crate) motion: Motion,
    pub(crate) health: Health,
    pub(crate) failsafe: FailsafeState,
    pub(crate) mode: ControlMode,
    /// The routed channel.
    pub(crate) channel: &'a str,
    pub(crate) outputs: &'a [f64],
    /// The routed channel's mission.
    pub(crate) mission: Option<MissionProgress>,
    /// Messages ignored as stale.
    pub(crate) stale: u32,
    /// The fleet safety layer's state, intervention and counts.
    pub(crate) safety: SafetyReport,
}

impl Snapshot<'_> {
    /// The telemetry message. Velocity is in the world frame, as the
    /// protocol specifies; a channel named `offboard/...` means the station
    /// computes the control.
    pub(crate) fn telemetry(self) -> Telemetry {
        let estimate = self.motion.estimate;
        Telemetry {
            pose: estimate.map(|e| e.pose).unwrap_or_default(),
            velocity: self.motion.velocity,
            mode: self.mode,
            channel: self.channel.to_string(),
            computation: if self.channel.starts_with("offboard/") {
                Computation::Offboard
            } else {
                Computation::Onboard
            },
            failsafe: self.failsafe,
            health: self.health,
            battery: None,
            position_quality: estimate.map_or(0.0, |e| e.quality.clamp(0.0, 1.0)),
            actuators: self.outputs.to_vec(),
            mission: self.mission,
            stale: self.stale,
            velocity_source: self.motion.velocity_source,
            safety: Some(self.safety),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;

    #[test]
    fn telemetry_velocity_is_in_the_world_frame() {
        let mut a = routed("joy/0");
        // Enough samples facing +y to fill the median filter's window.
        for _ in 0..AgentSettings::new("r1").filter_window {
            a.observe_position(PositionSample {
                pose: Pose {
                    heading: std::f64::consts::FRAC_PI_2,
                    ..Pose::default()
                },
                stamp: ms(0),
                quality: 1.0,
                has_heading: true,
            });
        }
        a.handle(msg("joy/0", twist(0.2)), ms(0));
        a.tick(PERIOD);
        let v = a.telemetry(PERIOD).velocity;
        // Facing +y, driving forward moves the robot along world +y.
        assert!(v.vx.abs() < 1e-9, "vx {}", v.vx);
        assert!(v.vy > 0.1, "vy {}", v.vy);
    }
}

#[cfg(test)]
mod schedule_tests {
    use super::*;

    #[test]
    fn telemetry_stays_on_its_grid_through_jitter() {
        let ms = Duration::from_millis;
        let mut s = TelemetrySchedule::new(ms(50));
        let due: Vec<u64> = [0, 30, 53, 99, 101, 149, 150, 170, 199, 201]
            .into_iter()
            .filter(|&t| s.due(ms(t)))
            .collect();
        // 53 and 101 are late, yet the next are due at 100 and 150 (no
        // drift), and never two in one period.
        assert_eq!(due, [0, 53, 101, 150, 201]);
    }
}
