//! The agent's counters: everything it refused or could not use, and when
//! it last stopped. Each part of the core counts its own events here.

/// Counters of everything the agent refused or could not use.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Counters {
    /// Commands on a channel other than the acknowledged route.
    pub not_routed: u64,
    /// Commands this robot cannot obey (capability or motor count).
    pub refused: u64,
    /// Commands ignored while e-stopped.
    pub ignored_estopped: u64,
    /// E-stops and releases older than one already obeyed (delayed resends).
    pub stale_estops: u64,
    /// Commands older than one already obeyed from the same sender on the
    /// same channel (overtaken on the way).
    pub stale_commands: u64,
    /// Routes with an epoch older than the one in force.
    pub stale_routes: u64,
    /// Missions with an id older than the one held for their channel.
    pub stale_missions: u64,
    /// Stored missions forgotten to make room for another channel's (the
    /// robot keeps [`super::missions::MISSION_CHANNELS`]).
    pub missions_forgotten: u64,
    /// Messages addressed to another robot.
    pub not_for_me: u64,
    /// Bytes that did not decode as a message.
    pub bad_messages: u64,
    /// Times the failsafe stopped the robot.
    pub failsafe_trips: u64,
    /// Actuator or position driver errors.
    pub driver_faults: u64,
    /// Position fixes used.
    pub position_samples: u64,
    /// Times a wheel stalled (driven without turning) and the outputs were
    /// zeroed.
    pub stalls: u64,
    /// Commands obeyed.
    pub commands: u64,
    /// Times the router said it did not know this robot (it restarted),
    /// and the robot registered again at once.
    pub reregistered: u64,
    /// When the failsafe last stopped the robot, and when it last obeyed a
    /// new e-stop: the robot's clock, µs since the Unix epoch (0: never).
    pub tripped_at_us: u64,
    pub estopped_at_us: u64,
}

impl Counters {
    /// Messages ignored as stale, for telemetry.
    pub(crate) fn stale_total(&self) -> u32 {
        let n = self.stale_commands + self.stale_estops + self.stale_routes + self.stale_missions;
        u32::try_from(n).unwrap_or(u32::MAX)
    }
}
