//! Fleet safety trials: simulated robots stepped in lock-step, each with
//! the onboard controller and the [`SafetyLayer`] between its controller
//! and its motors, the station's neighbour messages simulated at a rate,
//! with an age, or not at all; and what was measured: the smallest gap
//! between two robots, the smallest clearance to the arena's edges,
//! violations, breaches, arrival times. Used by the safety tests
//! (`agent/tests/safety.rs`) and the benchmark (`cargo run --release -p
//! mech-agent --example safety_bench`).
//!
//! Poses are true poses (no position noise) and every robot sees the same
//! arena; the layer is "off" the way an operator switches it off (an arena
//! with `enabled = false`), so a trial with it off differs in nothing else.

use std::collections::VecDeque;
use std::time::Duration;

use mech_proto::{Arena, Command, Mission, Neighbour, Neighbours, Pose, Twist};

use super::robot::SimRobot;
use crate::control::{Controller, Gains, MissionRun};
use crate::platform::{Platform, PlatformSpec};
use crate::safety::{Fence, SafetyConfig, SafetyLayer, Vec2};

/// One simulated robot of a trial.
#[derive(Debug)]
pub struct TrialRobot {
    pub sim: SimRobot,
    pub controller: Controller,
    pub mission: Option<MissionRun>,
    pub layer: SafetyLayer,
    /// Simulated time its mission finished.
    pub arrived: Option<Duration>,
}

impl TrialRobot {
    /// Planar position, m.
    pub fn position(&self) -> Vec2 {
        let p = self.sim.pose();
        Vec2::new(p.x, p.y)
    }

    /// Planar velocity in the map frame, m/s.
    pub fn velocity(&self) -> Vec2 {
        let t = self.sim.twist();
        Vec2::new(t.vx, t.vy).rotated(self.sim.pose().heading)
    }

    pub fn radius(&self) -> f64 {
        self.layer.config().radius
    }
}

/// What a trial measured.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrialMetrics {
    /// Smallest distance between two robots' discs over the run, m
    /// (negative: they overlapped).
    pub min_gap: f64,
    /// Control periods in which two robots' discs were closer than the
    /// arena's margin, by more than the trial's tolerance.
    pub separation_violations: u64,
    /// Smallest distance between a robot's disc and the arena's edges
    /// (boundary and keep-outs) over the run, m (negative: outside or
    /// inside a keep-out).
    pub min_clearance: f64,
    /// Control periods in which a robot's disc came closer to an edge than
    /// the margin, by more than the tolerance.
    pub margin_violations: u64,
    /// Control periods in which a robot's disc crossed the boundary or
    /// entered a keep-out (a geofence breach).
    pub breaches: u64,
    /// Fastest speed any robot had while its neighbour information had
    /// been stale for a quarter of a second (time to slow down), m/s.
    pub max_stale_speed: f64,
}

/// A lock-step fleet in one arena.
#[derive(Debug)]
pub struct SafetyTrial {
    pub robots: Vec<TrialRobot>,
    arena: Arena,
    fence: Fence,
    safety: SafetyConfig,
    layer_on: bool,
    /// Control period, s.
    pub dt: f64,
    time: Duration,
    /// Time between neighbour messages.
    pub neighbour_period: Duration,
    /// Age of the states a neighbour message carries.
    pub latency: Duration,
    /// No neighbour message is delivered from this time on.
    pub neighbours_until: Option<Duration>,
    next_neighbours: Duration,
    /// Robot states (position, velocity) of the recent past, for `latency`.
    history: VecDeque<(Duration, Vec<(Vec2, Vec2)>)>,
    /// Shortfall below the margin that is not counted as a violation, m.
    pub tolerance: f64,
    metrics: TrialMetrics,
}

impl SafetyTrial {
    /// A trial in `arena` (its `enabled` is set by `layer_on`), robots with
    /// `safety` settings, 50 Hz control, neighbours at 10 Hz 50 ms old.
    pub fn new(arena: Arena, safety: SafetyConfig, layer_on: bool) -> SafetyTrial {
        let fence = Fence::from_arena(&arena);
        SafetyTrial {
            robots: Vec::new(),
            arena: Arena {
                enabled: layer_on,
                ..arena
            },
            fence,
            safety,
            layer_on,
            dt: 0.02,
            time: Duration::ZERO,
            neighbour_period: Duration::from_millis(100),
            latency: Duration::from_millis(50),
            neighbours_until: None,
            next_neighbours: Duration::ZERO,
            history: VecDeque::new(),
            tolerance: 0.0,
            metrics: TrialMetrics {
                min_gap: f64::INFINITY,
                separation_violations: 0,
                min_clearance: f64::INFINITY,
                margin_violations: 0,
                breaches: 0,
                max_stale_speed: 0.0,
            },
        }
    }

    /// Adds a robot of `platform` at `pose`; returns its index.
    pub fn add(&mut self, platform: &PlatformSpec, pose: Pose) -> usize {
        let mut layer = SafetyLayer::new(self.safety);
        layer.registered(self.robots.len() as u16 + 1);
        layer.apply_arena(&self.arena);
        self.robots.push(TrialRobot {
            sim: SimRobot::new(platform, pose),
            controller: Controller::new(platform.build(), Gains::default(), true),
            mission: None,
            layer,
            arrived: None,
        });
        self.robots.len() - 1
    }

    /// Gives robot `i` a command (its mode follows, as on the agent).
    pub fn command(&mut self, i: usize, command: &Command) {
        // Commands in a trial are built for the robot's capabilities.
        let _ = self.robots[i].controller.command(command);
    }

    /// Starts robot `i` on `mission`.
    pub fn mission(&mut self, i: usize, mission: Mission) {
        let r = &mut self.robots[i];
        if r.controller.follow_mission().is_ok() {
            r.mission = Some(MissionRun::new(mission));
            r.arrived = None;
        }
    }

    pub fn time(&self) -> Duration {
        self.time
    }

    pub fn metrics(&self) -> TrialMetrics {
        self.metrics
    }

    /// Whether every robot with a mission has finished it.
    pub fn all_arrived(&self) -> bool {
        self.robots
            .iter()
            .all(|r| r.mission.is_none() || r.arrived.is_some())
    }

    /// Latest arrival, s (`None` until all arrived).
    pub fn last_arrival(&self) -> Option<f64> {
        self.robots
            .iter()
            .filter(|r| r.mission.is_some())
            .map(|r| r.arrived.map(|t| t.as_secs_f64()))
            .try_fold(0.0f64, |m, t| t.map(|t| m.max(t)))
    }

    /// Runs until `seconds` of simulated time have passed.
    pub fn run_for(&mut self, seconds: f64) {
        let end = self.time + Duration::from_secs_f64(seconds);
        while self.time < end {
            self.step();
        }
    }

    /// One control period: neighbour messages due, every robot's
    /// controller, filter and motion, then the measurements.
    pub fn step(&mut self) {
        let now = self.time;
        self.remember(now);
        if now >= self.next_neighbours {
            self.next_neighbours = now + self.neighbour_period;
            if self.neighbours_until.is_none_or(|until| now < until) {
                self.send_neighbours(now);
            }
        }
        for r in &mut self.robots {
            let pose = r.sim.pose();
            let velocity = r.velocity();
            let outputs = r.controller.update(&pose, now, r.mission.as_mut()).to_vec();
            let platform: &dyn Platform = r.controller.platform();
            r.layer.steered_by(r.controller.bearing_gain());
            let filtered = r.layer.filter(platform, &pose, velocity, &outputs, now);
            let settled = now.checked_sub(Duration::from_millis(250));
            if settled.is_some_and(|t| r.layer.stale(t)) {
                let speed = r.velocity().norm();
                self.metrics.max_stale_speed = self.metrics.max_stale_speed.max(speed);
            }
            r.sim.step_outputs(&filtered.outputs, self.dt);
            if r.arrived.is_none() && r.mission.as_ref().is_some_and(MissionRun::finished) {
                r.arrived = Some(now);
            }
        }
        self.time += Duration::from_secs_f64(self.dt);
        self.measure();
    }

    fn remember(&mut self, now: Duration) {
        let states = self
            .robots
            .iter()
            .map(|r| (r.position(), r.velocity()))
            .collect();
        self.history.push_back((now, states));
        while self
            .history
            .front()
            .is_some_and(|(t, _)| *t + self.latency + self.neighbour_period < now)
        {
            self.history.pop_front();
        }
    }

    /// Every robot gets the others' states as they were `latency` ago.
    fn send_neighbours(&mut self, now: Duration) {
        let then = now.saturating_sub(self.latency);
        let Some((at, states)) = self.history.iter().find(|(t, _)| *t >= then) else {
            return;
        };
        let age_ms = now.saturating_sub(*at).as_millis() as u32;
        let radii: Vec<f64> = self.robots.iter().map(TrialRobot::radius).collect();
        for (i, r) in self.robots.iter_mut().enumerate() {
            let robots = states
                .iter()
                .enumerate()
                .filter(|(j, _)| *j != i)
                .map(|(j, (p, v))| Neighbour {
                    id: j as u16 + 1,
                    x: p.x,
                    y: p.y,
                    z: 0.0,
                    vx: v.x,
                    vy: v.y,
                    vz: 0.0,
                    radius: radii[j],
                    age_ms,
                    cooperative: self.layer_on,
                })
                .collect();
            let message = Neighbours {
                robot: format!("robot_{}", i + 1),
                stamp_us: now.as_micros() as u64,
                robots,
                obstacles: vec![],
            };
            r.layer.apply_neighbours(&message, now);
        }
    }

    fn measure(&mut self) {
        let margin = self.fence.margin;
        let m = &mut self.metrics;
        let mut violated = false;
        for (i, a) in self.robots.iter().enumerate() {
            for b in &self.robots[i + 1..] {
                let gap = (a.position() - b.position()).norm() - a.radius() - b.radius();
                m.min_gap = m.min_gap.min(gap);
                violated |= gap < margin - self.tolerance;
            }
        }
        m.separation_violations += u64::from(violated);
        let (mut short, mut breached) = (false, false);
        for r in &self.robots {
            let clearance = clearance(&self.fence, r.position()) - r.radius();
            m.min_clearance = m.min_clearance.min(clearance);
            short |= clearance < margin - self.tolerance;
            breached |= clearance < 0.0;
        }
        m.margin_violations += u64::from(short);
        m.breaches += u64::from(breached);
    }
}

/// Signed distance from `p` to the arena's edges ([`Fence::clearance`]).
pub fn clearance(fence: &Fence, p: Vec2) -> f64 {
    fence.clearance(p)
}

/// The demo simulator's arena ([`super::Arena::default`], 3.9 m x 2.8 m)
/// as an [`Arena`] message with a 0.1 m margin.
pub fn demo_arena() -> Arena {
    let a = super::Arena::default();
    let p = |x, y| mech_proto::Point { x, y };
    Arena {
        robot: "robot_1".into(),
        id: 1,
        enabled: true,
        boundary: vec![
            p(a.min_x, a.min_y),
            p(a.max_x, a.min_y),
            p(a.max_x, a.max_y),
            p(a.min_x, a.max_y),
        ],
        keep_out: vec![],
        slow_zones: vec![],
        margin: 0.1,
    }
}

/// A twist at `fraction` of the platform's top speed and yaw rate.
pub fn twist(platform: &dyn Platform, forward: f64, sideways: f64, turn: f64) -> Command {
    let l = platform.limits();
    Command::Twist(Twist {
        vx: forward * l.max_speed,
        vy: if platform.holonomic() {
            sideways * l.max_speed
        } else {
            0.0
        },
        vz: 0.0,
        wz: turn * l.max_yaw_rate,
    })
}
