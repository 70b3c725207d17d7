//! A stepped-time test bench for ground-side controllers: real agent cores
//! (`mech_agent::sim::SimAgent`: routes, failsafe, onboard missions, platform
//! kinematics) driven by hand-made router messages, with telemetry collected
//! into the `MemberState`s a controller reads. Agents run their control
//! period every 10 ms; the router's heartbeat goes out every 250 ms.

#![allow(dead_code, clippy::unwrap_used)]

use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

use mech_agent::AgentSettings;
use mech_agent::platform::PlatformSpec;
use mech_agent::sim::SimAgent;
use mech_agent::sim::noise::{UwbNoise, UwbNoiseModel};
use mech_control::{MemberState, PlatformLimits};
use mech_proto::{
    Body, Command, Envelope, FailsafeState, FleetCommand, Header, Heartbeat, Hello, Mission, Pose,
    RobotCommand, Route, Telemetry, Welcome,
};

const AGENT_PERIOD: Duration = Duration::from_millis(10);
const HEARTBEAT_PERIOD: Duration = Duration::from_millis(250);

pub fn pose(x: f64, y: f64, heading: f64) -> Pose {
    Pose {
        x,
        y,
        z: 0.0,
        heading,
    }
}

#[derive(Debug)]
pub struct Bench {
    agents: Vec<SimAgent>,
    hellos: BTreeMap<String, Hello>,
    /// Last telemetry received from each robot, with its arrival time.
    telemetry: BTreeMap<String, (Duration, Telemetry)>,
    epochs: BTreeMap<String, u32>,
    /// Robots whose uplink is broken: their telemetry never arrives.
    silenced: BTreeSet<String>,
    pub now: Duration,
    next_heartbeat: Duration,
    seq: u32,
}

impl Bench {
    /// Registers each robot and routes it to `channel`; positions are exact.
    pub fn new(robots: &[(&str, PlatformSpec, Pose)], channel: &str) -> Bench {
        Bench::with_noise(robots, channel, false)
    }

    /// As [`Bench::new`], with UWB-like position noise (Gaussian jitter and
    /// outliers, through the agent's median filter) when `noise` is set.
    pub fn with_noise(robots: &[(&str, PlatformSpec, Pose)], channel: &str, noise: bool) -> Bench {
        let mut bench = Bench {
            agents: Vec::new(),
            hellos: BTreeMap::new(),
            telemetry: BTreeMap::new(),
            epochs: BTreeMap::new(),
            silenced: BTreeSet::new(),
            now: Duration::ZERO,
            next_heartbeat: Duration::ZERO,
            seq: 0,
        };
        for (i, (name, spec, start)) in robots.iter().enumerate() {
            let uwb = noise.then(|| UwbNoise::new(UwbNoiseModel::default(), 100 + i as u64));
            let mut agent = SimAgent::new(AgentSettings::new(*name), spec, *start, uwb, 0);
            bench.hellos.insert(name.to_string(), agent.agent.hello());
            let welcome = Body::Welcome(Welcome {
                robot_id: i as u16 + 1,
                route: Route {
                    robot: name.to_string(),
                    channel: channel.to_string(),
                    epoch: 1,
                },
                router_version: "bench".into(),
            });
            let env = bench.envelope(name, "", welcome);
            agent.handle(env, Duration::ZERO);
            bench.epochs.insert(name.to_string(), 1);
            bench.agents.push(agent);
        }
        bench.advance(Duration::from_millis(100));
        bench
    }

    fn envelope(&mut self, destination: &str, channel: &str, body: Body) -> Envelope {
        self.seq = self.seq.wrapping_add(1);
        Envelope::new(
            Header {
                seq: self.seq,
                stamp_us: self.now.as_micros() as u64,
                sender: "gcs".into(),
                destination: destination.into(),
                channel: channel.into(),
            },
            body,
        )
    }

    fn agent(&mut self, robot: &str) -> &mut SimAgent {
        self.agents
            .iter_mut()
            .find(|a| a.agent.name() == robot)
            .unwrap()
    }

    fn to(&mut self, robot: &str, channel: &str, body: Body) {
        let env = self.envelope(robot, channel, body);
        let now = self.now;
        self.agent(robot).handle(env, now);
    }

    /// Switches `robot` to `channel` (empty = none), as the router does.
    pub fn route(&mut self, robot: &str, channel: &str) {
        let epoch = self.epochs.get(robot).copied().unwrap_or(0) + 1;
        self.epochs.insert(robot.to_string(), epoch);
        let body = Body::Route(Route {
            robot: robot.into(),
            channel: channel.into(),
            epoch,
        });
        self.to(robot, "", body);
    }

    /// A command published on `channel` for `robot` (the agent drops it
    /// unless routed to `channel`).
    pub fn command(&mut self, robot: &str, channel: &str, command: &Command) {
        self.to(robot, channel, Body::Command(command.clone()));
    }

    /// A fleet command, split per robot as the router does.
    pub fn fleet(&mut self, channel: &str, parts: &[RobotCommand]) {
        for p in parts {
            let body = Body::FleetCommand(FleetCommand {
                parts: vec![p.clone()],
            });
            self.to(&p.robot, channel, body);
        }
    }

    pub fn mission(&mut self, robot: &str, channel: &str, mission: Mission) {
        self.to(robot, channel, Body::Mission(mission));
    }

    /// Breaks (`true`) or repairs the robot's uplink.
    pub fn silence(&mut self, robot: &str, silent: bool) {
        if silent {
            self.silenced.insert(robot.to_string());
        } else {
            self.silenced.remove(robot);
        }
    }

    /// Runs the agents for `span`.
    pub fn advance(&mut self, span: Duration) {
        let end = self.now + span;
        while self.now < end {
            self.now += AGENT_PERIOD;
            let now = self.now;
            if now >= self.next_heartbeat {
                self.next_heartbeat = now + HEARTBEAT_PERIOD;
                let names: Vec<String> = self.hellos.keys().cloned().collect();
                for n in names {
                    self.to(
                        &n,
                        "",
                        Body::Heartbeat(Heartbeat::new(now.as_millis() as u64)),
                    );
                }
            }
            for a in &mut self.agents {
                let name = a.agent.name().to_string();
                for env in a.tick(now) {
                    if let Body::Telemetry(t) = env.body {
                        if !self.silenced.contains(&name) {
                            self.telemetry.insert(name.clone(), (now, t));
                        }
                    }
                }
            }
        }
    }

    /// Telemetry as the GCS holds it: the last report of every robot.
    pub fn states(&self) -> Vec<MemberState> {
        self.telemetry
            .iter()
            .map(|(name, (at, t))| MemberState {
                robot: name.clone(),
                platform: PlatformLimits::from_hello(&self.hellos[name]),
                pose: t.pose,
                velocity: t.velocity,
                stamp: at.as_secs_f64(),
            })
            .collect()
    }

    pub fn state(&self, robot: &str) -> Option<MemberState> {
        self.states().into_iter().find(|s| s.robot == robot)
    }

    pub fn telemetry(&self, robot: &str) -> Option<&Telemetry> {
        self.telemetry.get(robot).map(|(_, t)| t)
    }

    pub fn now_s(&self) -> f64 {
        self.now.as_secs_f64()
    }

    /// True pose of the simulated vehicle.
    pub fn true_pose(&self, robot: &str) -> Pose {
        self.agents
            .iter()
            .find(|a| a.agent.name() == robot)
            .unwrap()
            .robot
            .pose()
    }

    /// True ground speed, m/s.
    pub fn speed(&self, robot: &str) -> f64 {
        let t = self
            .agents
            .iter()
            .find(|a| a.agent.name() == robot)
            .unwrap()
            .robot
            .twist();
        t.vx.hypot(t.vy)
    }

    pub fn failsafe(&self, robot: &str) -> FailsafeState {
        let a = self
            .agents
            .iter()
            .find(|a| a.agent.name() == robot)
            .unwrap();
        a.agent.failsafe_state(self.now)
    }
}
