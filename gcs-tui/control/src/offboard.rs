//! Offboard waypoint navigation: the ground station closes the waypoint loop
//! on telemetry and sends vehicle-level commands on `offboard/<robot>`.
//!
//! The navigator runs the same [`Mission`] the agent would run onboard and
//! keeps the same progress index (`next`, the waypoint being approached), so
//! switching between onboard and offboard navigation resumes at the same
//! waypoint: start it at the agent's reported `MissionProgress::next`
//! ([`OffboardNavigator::resume_at`]), and hand back with
//! [`OffboardNavigator::onboard_mission`], a mission whose `start_index` is the
//! current `next`.
//!
//! Guidance: head for the next waypoint at cruise speed, or at the speed that
//! meets its arrival time when it has one, slowing down only for the last
//! waypoint of a non-looped mission. Holonomic robots get a body twist toward
//! it; differential-drive robots turn toward its bearing and drive forward in
//! proportion to `cos(bearing error)` (twist with `vy = 0`, or velocity-heading
//! for platforms without twist).

use mech_proto::{
    Command, CommandKind, Mission, MissionProgress, Stop, Twist, VelocityHeading, Waypoint,
};

use super::geometry::{norm, rotate, wrap_angle};
use super::{ControlEvent, Kinematics, MemberState};

/// Tuning of the offboard waypoint loop.
#[derive(Debug, Clone, PartialEq)]
pub struct NavConfig {
    /// Speed between waypoints without arrival times, m/s (capped by the
    /// platform's top speed).
    pub cruise_speed: f64,
    /// Slowest speed used to meet an arrival time, m/s.
    pub min_speed: f64,
    /// Distance to the final waypoint to speed, 1/s (the approach slope).
    pub k_position: f64,
    /// Bearing error to yaw rate, 1/s.
    pub k_heading: f64,
    /// Telemetry older than this (s) stops the loop commanding the robot.
    pub telemetry_timeout: f64,
}

impl Default for NavConfig {
    fn default() -> Self {
        NavConfig {
            cruise_speed: 0.3,
            min_speed: 0.05,
            k_position: 1.0,
            k_heading: 2.5,
            telemetry_timeout: 0.5,
        }
    }
}

/// Result of one navigation step.
#[derive(Debug, Clone, PartialEq)]
pub struct NavOutput {
    /// `None` while the robot's telemetry is stale or missing: the channel
    /// falls silent and the agent's failsafe stops the robot.
    pub command: Option<Command>,
    pub progress: MissionProgress,
    /// Distance to the waypoint being approached, m (`None` when finished or
    /// without telemetry).
    pub distance: Option<f64>,
    pub events: Vec<ControlEvent>,
}

/// Where one step leaves the robot in its mission.
enum Leg {
    /// Head for this waypoint, this far away (m).
    Toward(Waypoint, f64),
    /// Wait at the waypoint being approached, this far away (m), while
    /// navigation is handed back to the agent.
    Handover(f64),
    /// No waypoint left to approach: stop.
    Finished,
}

/// A GCS-side waypoint loop for one robot.
#[derive(Debug, Clone)]
pub struct OffboardNavigator {
    robot: String,
    mission: Mission,
    next: usize,
    /// When the mission started, s on the controller clock (arrival times are
    /// relative to it); set at the first step unless given.
    started: Option<f64>,
    config: NavConfig,
    lost: bool,
    /// While navigation is being handed back to the agent, progress is frozen:
    /// the robot waits at the next waypoint instead of passing it, so the
    /// mission the agent receives starts where the robot really is.
    handover: bool,
}

impl OffboardNavigator {
    /// Navigates `mission` from its `start_index`.
    pub fn new(robot: impl Into<String>, mission: Mission, config: NavConfig) -> Self {
        let next = (mission.start_index as usize).min(mission.waypoints.len());
        OffboardNavigator {
            robot: robot.into(),
            mission,
            next,
            started: None,
            config,
            lost: false,
            handover: false,
        }
    }

    /// Takes navigation over from the agent: `mission` is the one the agent
    /// holds and `reported` its last reported progress; navigation resumes at
    /// the reported next waypoint when the progress is for this mission, else
    /// at the mission's start index.
    pub fn take_over(
        robot: impl Into<String>,
        mission: Mission,
        reported: Option<MissionProgress>,
        config: NavConfig,
    ) -> Self {
        let mut nav = OffboardNavigator::new(robot, mission, config);
        if let Some(p) = reported.filter(|p| p.id == nav.mission.id) {
            nav.resume_at(p.next as usize);
        }
        nav
    }

    pub fn robot(&self) -> &str {
        &self.robot
    }

    pub fn mission(&self) -> &Mission {
        &self.mission
    }

    /// Continues from waypoint `next` (e.g. the agent's reported progress when
    /// taking over from onboard navigation).
    pub fn resume_at(&mut self, next: usize) {
        self.next = next.min(self.mission.waypoints.len());
    }

    /// Freezes (`true`) or releases progress while navigation is handed back
    /// to the agent; see [`OffboardNavigator::onboard_mission`].
    pub fn set_handover(&mut self, handover: bool) {
        self.handover = handover;
    }

    /// Progress in the form the agent reports it.
    pub fn progress(&self) -> MissionProgress {
        MissionProgress {
            id: self.mission.id,
            next: self.next as u32,
            total: self.mission.waypoints.len() as u32,
        }
    }

    /// Whether the last waypoint of a non-looped mission has been reached.
    pub fn finished(&self) -> bool {
        self.next >= self.mission.waypoints.len()
    }

    /// The mission to hand navigation back to the agent: same waypoints,
    /// starting at the current `next`. It needs a fresh `id`, because an agent
    /// treats a repeated id as a retransmission and keeps its old progress.
    pub fn onboard_mission(&self, id: u32) -> Mission {
        Mission {
            id,
            start_index: self.next as u32,
            ..self.mission.clone()
        }
    }

    /// One step at `now` (s) on the robot's latest state.
    pub fn step(&mut self, now: f64, state: Option<&MemberState>) -> NavOutput {
        let mut events = Vec::new();
        let state = state.filter(|s| s.robot == self.robot);
        let fresh = state.filter(|s| !s.is_stale(now, self.config.telemetry_timeout));
        self.note_telemetry(fresh.is_some(), &mut events);
        let (command, distance) = match fresh {
            Some(s) => self.guide(now, s, &mut events),
            None => (None, None),
        };
        NavOutput {
            command,
            progress: self.progress(),
            distance,
            events,
        }
    }

    /// Reports the robot lost when its telemetry goes stale or missing, and
    /// recovered when fresh telemetry is back.
    fn note_telemetry(&mut self, fresh: bool, events: &mut Vec<ControlEvent>) {
        match (fresh, self.lost) {
            (false, false) => {
                self.lost = true;
                events.push(ControlEvent::MemberLost {
                    robot: self.robot.clone(),
                });
            }
            (true, true) => {
                self.lost = false;
                events.push(ControlEvent::MemberRecovered {
                    robot: self.robot.clone(),
                });
            }
            _ => {}
        }
    }

    /// The command for a robot with fresh telemetry, and its distance to the
    /// waypoint being approached.
    fn guide(
        &mut self,
        now: f64,
        s: &MemberState,
        events: &mut Vec<ControlEvent>,
    ) -> (Option<Command>, Option<f64>) {
        let started = *self.started.get_or_insert(now);
        match self.leg(s, events) {
            Leg::Toward(w, distance) => {
                let speed = self.leg_speed(s, &w, distance, now - started);
                let command = self.command_toward(s, w.x, w.y, speed);
                (Some(command), Some(distance))
            }
            Leg::Handover(distance) => (Some(Command::Stop(Stop {})), Some(distance)),
            Leg::Finished => (Some(Command::Stop(Stop {})), None),
        }
    }

    /// Where the robot is in its mission: the waypoint to head for, passing
    /// the one being approached once within the arrival radius.
    fn leg(&mut self, s: &MemberState, events: &mut Vec<ControlEvent>) -> Leg {
        let total = self.mission.waypoints.len();
        if self.next >= total && self.mission.looped && total > 0 {
            self.next = 0;
        }
        let Some(w) = self.mission.waypoints.get(self.next).copied() else {
            return Leg::Finished;
        };
        let distance = norm(w.x - s.pose.x, w.y - s.pose.y);
        if distance <= self.mission.arrival_radius {
            if self.handover {
                return Leg::Handover(distance);
            }
            return self.pass_waypoint(s, events);
        }
        Leg::Toward(w, distance)
    }

    /// Counts the waypoint being approached as reached and goes on to the
    /// next one (the first again when looped).
    fn pass_waypoint(&mut self, s: &MemberState, events: &mut Vec<ControlEvent>) -> Leg {
        events.push(ControlEvent::WaypointReached { index: self.next });
        self.next += 1;
        if self.next >= self.mission.waypoints.len() {
            if self.mission.looped {
                self.next = 0;
            } else {
                events.push(ControlEvent::Finished);
                return Leg::Finished;
            }
        }
        // `next` is a valid index here: it was one before the increment, or
        // it wrapped round to the first waypoint.
        match self.mission.waypoints.get(self.next).copied() {
            Some(w) => Leg::Toward(w, norm(w.x - s.pose.x, w.y - s.pose.y)),
            None => Leg::Finished,
        }
    }

    /// Speed along the leg to `w`, `distance` away, `elapsed` s into the
    /// mission: cruise within the platform's top speed, or what meets `w`'s
    /// arrival time; slowing down only for the last waypoint of a non-looped
    /// mission.
    fn leg_speed(&self, s: &MemberState, w: &Waypoint, distance: f64, elapsed: f64) -> f64 {
        let cfg = &self.config;
        let max_speed = s.platform.max_speed;
        let speed = match w.time {
            Some(t) => {
                let remaining = t - elapsed;
                if remaining > 1e-3 {
                    // A platform slower than the least speed: its top speed.
                    (distance / remaining).max(cfg.min_speed).min(max_speed)
                } else {
                    max_speed
                }
            }
            None => max_speed.min(cfg.cruise_speed.max(cfg.min_speed)),
        };
        if self.next + 1 >= self.mission.waypoints.len() && !self.mission.looped {
            speed.min((cfg.k_position * distance).max(cfg.min_speed))
        } else {
            speed
        }
    }

    fn command_toward(&self, s: &MemberState, x: f64, y: f64, speed: f64) -> Command {
        let p = &s.platform;
        let (dx, dy) = (x - s.pose.x, y - s.pose.y);
        let d = norm(dx, dy).max(1e-9);
        let bearing = dy.atan2(dx);
        let error = wrap_angle(bearing - s.pose.heading);
        match p.kinematics {
            Kinematics::Holonomic if p.accepts(CommandKind::Twist) => {
                let (vx, vy) = rotate(speed * dx / d, speed * dy / d, -s.pose.heading);
                Command::Twist(Twist {
                    vx,
                    vy,
                    vz: 0.0,
                    wz: 0.0,
                })
            }
            _ if p.accepts(CommandKind::Twist) => {
                let wz = (self.config.k_heading * error).clamp(-p.max_yaw_rate, p.max_yaw_rate);
                Command::Twist(Twist {
                    vx: speed * error.cos().max(0.0),
                    vy: 0.0,
                    vz: 0.0,
                    wz,
                })
            }
            _ if p.accepts(CommandKind::VelocityHeading) => {
                Command::VelocityHeading(VelocityHeading {
                    speed: speed * error.cos().max(0.0),
                    heading: bearing,
                })
            }
            _ => Command::Stop(Stop {}),
        }
    }
}
