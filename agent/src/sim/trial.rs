//! Repeatable waypoint trials: one simulated agent (real core, UWB-like
//! noise, median filter; optionally wheel encoders, odometry fused with the
//! fixes and closed-loop wheel speed) driven through a mission exactly as
//! the router would drive it, stepped in simulated time. Used by the
//! accuracy benchmark (`cargo run --release -p mech-agent --example
//! waypoint_accuracy`) and its test.

use std::time::Duration;

use mech_proto::{Body, Envelope, Header, Heartbeat, Mission, Pose, Route, Waypoint, Welcome};

use super::agent::SimAgent;
use super::encoder::SimEncoderModel;
use super::noise::{UwbNoise, UwbNoiseModel};
use crate::fusion::FusionSettings;
use crate::machine::AgentSettings;
use crate::platform::PlatformSpec;
use crate::wheels::{PiGains, StallSettings, WheelSettings};

/// Outcome of one trial.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrialResult {
    /// True distance from the final waypoint once the robot has stopped, m.
    pub final_error: f64,
    /// Whether the agent reported the mission finished.
    pub finished: bool,
    /// Simulated time taken, s.
    pub seconds: f64,
    /// Root mean square of the agent's planar pose error (estimate against
    /// truth) over the run, m.
    pub pose_rms: f64,
    /// 95th percentile of that error over the run, m.
    pub pose_p95: f64,
    /// The same for the position the robot reports (its estimate moved on
    /// to now, as telemetry and the safety layer take it): 99th
    /// percentile, m.
    pub reported_p99: f64,
    /// Largest error of the reported position, m.
    pub reported_max: f64,
    /// Fraction of periods in which the reported position was further
    /// from the truth than the error bound the robot reported with it.
    pub beyond_bound: f64,
}

/// Parameters of a trial.
#[derive(Debug, Clone, PartialEq)]
pub struct Trial {
    pub platform: PlatformSpec,
    pub start: Pose,
    pub waypoints: Vec<Waypoint>,
    pub arrival_radius: f64,
    /// `None`: perfect positions.
    pub noise: Option<UwbNoiseModel>,
    pub seed: u64,
    pub control_period: Duration,
    /// Give up after this much simulated time.
    pub timeout: Duration,
    pub filter_window: usize,
    /// Wheel encoders on the simulated robot, and the agent configured to
    /// use them (odometry fusion, closed-loop wheel speed); `None`: UWB only.
    pub encoders: Option<SimEncoderModel>,
    /// The simulated battery's charge (motor gain, 1 = full).
    pub battery: f64,
    /// Time between position fixes (zero: one every control period).
    pub fix_period: Duration,
}

impl Trial {
    /// A mission through `waypoints` from `start`, UWB-like noise, 50 Hz
    /// control, a 9-sample median filter.
    pub fn new(platform: PlatformSpec, start: Pose, waypoints: Vec<Waypoint>, seed: u64) -> Trial {
        Trial {
            platform,
            start,
            waypoints,
            arrival_radius: 0.03,
            noise: Some(UwbNoiseModel::default()),
            seed,
            control_period: Duration::from_millis(20),
            timeout: Duration::from_secs(120),
            filter_window: 9,
            encoders: None,
            battery: 1.0,
            fix_period: Duration::ZERO,
        }
    }

    /// The same trial on a robot with wheel encoders of `model`, the agent
    /// using them (the fusion told the UWB noise's standard deviations, as
    /// a robot's config would be).
    pub fn with_encoders(mut self, model: SimEncoderModel) -> Trial {
        self.encoders = Some(model);
        self
    }

    fn settings(&self) -> AgentSettings {
        let mut settings = AgentSettings::new("trial");
        settings.filter_window = self.filter_window;
        settings.wheels = self.encoders.map(|m| WheelSettings {
            counting: m.counting,
            counts_per_revolution: m.counts_per_revolution,
            wheel_radius: m.wheel_radius,
            speed_loop: Some(PiGains::default()),
            stall: StallSettings::default(),
        });
        let noise = self.noise.unwrap_or(UwbNoiseModel {
            sigma: 0.005,
            heading_sigma: 0.005,
            ..UwbNoiseModel::default()
        });
        settings.fusion = FusionSettings {
            position_sigma: noise.sigma,
            heading_sigma: noise.heading_sigma,
            ..FusionSettings::default()
        };
        settings
    }

    /// Runs the trial.
    pub fn run(&self) -> TrialResult {
        let mut sim = self.robot();
        let mut now = Duration::ZERO;
        self.start(&mut sim, now);
        let mut next_heartbeat = Duration::ZERO;
        let mut finished_at = None;
        let mut pose_errors = Vec::new();
        let mut reported = Reported::default();
        while now < self.timeout {
            now += self.control_period;
            if now >= next_heartbeat {
                sim.handle(from_router("", Body::Heartbeat(Heartbeat::new(0))), now);
                next_heartbeat = now + Duration::from_millis(250);
            }
            sim.tick(now);
            if let Some(e) = sim.agent.estimate() {
                let truth = sim.robot.pose();
                pose_errors.push((e.pose.x - truth.x).hypot(e.pose.y - truth.y));
                reported.record(&sim, now);
            }
            let done = sim.agent.mission("wp/gcs").is_some_and(|m| m.finished());
            match finished_at {
                None if done => finished_at = Some(now),
                // Let the vehicle come to rest before measuring.
                Some(t) if now >= t + Duration::from_secs(1) => break,
                _ => {}
            }
        }
        let mut result = self.outcome(&sim, finished_at, now, &pose_errors);
        reported.fill(&mut result);
        result
    }

    /// The simulated robot: noise, encoders and battery as the trial says.
    fn robot(&self) -> SimAgent {
        let noise = self.noise.map(|m| UwbNoise::new(m, self.seed));
        let mut sim = SimAgent::new(self.settings(), &self.platform, self.start, noise, 0)
            .with_fix_period(self.fix_period);
        if let Some(model) = self.encoders {
            sim = sim.with_encoders(model, self.seed.wrapping_mul(31));
        }
        sim.robot.set_battery(self.battery);
        sim
    }

    /// Registers the robot routed to `wp/gcs` and sends it the mission, as
    /// the router would.
    fn start(&self, sim: &mut SimAgent, now: Duration) {
        sim.tick(now);
        let route = Route {
            robot: "trial".into(),
            channel: "wp/gcs".into(),
            epoch: 1,
        };
        let welcome = Body::Welcome(Welcome {
            robot_id: 1,
            route,
            router_version: "trial".into(),
        });
        sim.handle(from_router("", welcome), now);
        let mission = Mission {
            id: 1,
            waypoints: self.waypoints.clone(),
            looped: false,
            arrival_radius: self.arrival_radius,
            start_index: 0,
        };
        sim.handle(from_router("wp/gcs", Body::Mission(mission)), now);
    }

    /// The result of a run that ended at `now`.
    fn outcome(
        &self,
        sim: &SimAgent,
        finished_at: Option<Duration>,
        now: Duration,
        pose_errors: &[f64],
    ) -> TrialResult {
        let target = self.waypoints.last().copied().unwrap_or(Waypoint {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            time: None,
        });
        let p = sim.robot.pose();
        let dz = if self.platform.build().flies() {
            p.z - target.z
        } else {
            0.0
        };
        let pose_rms = if pose_errors.is_empty() {
            f64::NAN
        } else {
            (pose_errors.iter().map(|e| e * e).sum::<f64>() / pose_errors.len() as f64).sqrt()
        };
        TrialResult {
            final_error: ((p.x - target.x).powi(2) + (p.y - target.y).powi(2) + dz * dz).sqrt(),
            finished: finished_at.is_some(),
            seconds: finished_at.unwrap_or(now).as_secs_f64(),
            pose_rms,
            pose_p95: median_p95(pose_errors).1,
            reported_p99: f64::NAN,
            reported_max: f64::NAN,
            beyond_bound: f64::NAN,
        }
    }
}

/// The reported position's errors against the truth, and how often they
/// were beyond the bound reported with them.
#[derive(Debug, Default)]
struct Reported {
    errors: Vec<f64>,
    beyond: usize,
}

impl Reported {
    fn record(&mut self, sim: &SimAgent, now: Duration) {
        let t = sim.agent.telemetry(now);
        let truth = sim.robot.pose();
        let error = (t.pose.x - truth.x).hypot(t.pose.y - truth.y);
        let bound = t.safety.map_or(0.0, |s| s.position_error);
        if bound >= crate::safety::MAX_POSITION_ERROR {
            // The robot says it does not know where it is (its median
            // window is filling): nothing is claimed.
            return;
        }
        self.errors.push(error);
        self.beyond += usize::from(error > bound);
    }

    fn fill(mut self, result: &mut TrialResult) {
        self.errors.sort_by(f64::total_cmp);
        let n = self.errors.len();
        if n == 0 {
            return;
        }
        result.reported_p99 = self.errors[(n * 99).div_ceil(100).clamp(1, n) - 1];
        result.reported_max = self.errors[n - 1];
        result.beyond_bound = self.beyond as f64 / n as f64;
    }
}

/// A message from the router to the trial's robot on `channel`.
fn from_router(channel: &str, body: Body) -> Envelope {
    Envelope::new(
        Header {
            sender: "router".into(),
            destination: "trial".into(),
            channel: channel.into(),
            ..Header::default()
        },
        body,
    )
}

/// A standard trial `i`: a three-waypoint course across a 3.9 m x 2.8 m
/// arena, start pose and course varied by `i`.
pub fn standard_trial(platform: PlatformSpec, i: u64) -> Trial {
    let f = i as f64;
    let start = Pose {
        x: 0.4 + 0.1 * (f % 5.0),
        y: 0.4 + 0.15 * (f % 4.0),
        z: 0.0,
        heading: 0.7 * f,
    };
    let wp = |x: f64, y: f64| Waypoint {
        x,
        y,
        z: 1.0,
        time: None,
    };
    let waypoints = vec![
        wp(3.2 - 0.1 * (f % 3.0), 0.6 + 0.05 * (f % 4.0)),
        wp(3.0, 2.2 - 0.1 * (f % 4.0)),
        wp(1.0 + 0.2 * (f % 6.0), 1.4 + 0.1 * (f % 5.0)),
    ];
    Trial::new(platform, start, waypoints, 1000 + i)
}

/// Median and 95th percentile of `values` (nearest rank).
pub fn median_p95(values: &[f64]) -> (f64, f64) {
    let mut v = values.to_vec();
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let rank = |q: f64| v[((q * v.len() as f64).ceil() as usize).clamp(1, v.len()) - 1];
    (rank(0.5), rank(0.95))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_by_nearest_rank() {
        let v: Vec<f64> = (1..=20).map(f64::from).collect();
        assert_eq!(median_p95(&v), (10.0, 19.0));
    }

    #[test]
    fn noiseless_trial_finishes_inside_the_radius() {
        let mut t = standard_trial(PlatformSpec::diff_drive(), 0);
        t.noise = None;
        let r = t.run();
        assert!(r.finished, "{r:?}");
        assert!(r.final_error <= t.arrival_radius, "{r:?}");
    }
}
