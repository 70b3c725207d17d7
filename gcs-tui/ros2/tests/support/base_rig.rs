//! The rig of the agent's ROS 2 base tests: in a network namespace of
//! their own (`rig.rs`), the station (`mech-gcs serve --demo N`), a real
//! `mech-agent` whose config has a `[ros2]` section, and the fake ROS 2
//! mobile base it drives over DDS (`fake_base.py`), with an operator
//! attached to the station (`operator.rs`). The fake's true pose is what
//! the tests measure; the agent knows only its odometry.

use std::process::Stdio;
use std::sync::Arc;
use std::time::Duration;

use serde_json::{Value, json};

use crate::operator::Operator;
use crate::rig::{self, Netns, Node, Proc, ROUTER, WAIT, binary, log_file, tail};

/// The robot's name, and its namespace on the ROS 2 side.
pub const NAME: &str = "tb3_1";

/// Its disc for the safety layer, m (a TurtleBot 3 Burger is 0.105 m
/// from its centre to its farthest point).
pub const RADIUS: f64 = 0.12;

/// Its top speed, m/s: the agent's limit and the fake base's own.
pub const MAX_SPEED: f64 = 0.22;

/// A pose in the plane: x, y (m) and heading (rad, counter-clockwise).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose2 {
    pub x: f64,
    pub y: f64,
    pub heading: f64,
}

impl Pose2 {
    pub const fn new(x: f64, y: f64, heading: f64) -> Pose2 {
        Pose2 { x, y, heading }
    }

    /// `self` composed with `p`: `p` given in the frame `self` places.
    pub fn compose(&self, p: Pose2) -> Pose2 {
        let (s, c) = self.heading.sin_cos();
        Pose2 {
            x: self.x + c * p.x - s * p.y,
            y: self.y + s * p.x + c * p.y,
            heading: wrap(self.heading + p.heading),
        }
    }

    /// Where `self` is in the frame whose origin is `origin`.
    pub fn relative_to(&self, origin: Pose2) -> Pose2 {
        let (s, c) = origin.heading.sin_cos();
        let (dx, dy) = (self.x - origin.x, self.y - origin.y);
        Pose2 {
            x: c * dx + s * dy,
            y: -s * dx + c * dy,
            heading: wrap(self.heading - origin.heading),
        }
    }

    pub fn distance(&self, x: f64, y: f64) -> f64 {
        (self.x - x).hypot(self.y - y)
    }
}

/// An angle in (-pi, pi].
pub fn wrap(a: f64) -> f64 {
    a.sin().atan2(a.cos())
}

/// What a test sets up.
#[derive(Debug, Clone)]
pub struct Setup {
    /// Simulated robots of the station (`--demo N`).
    pub demo: usize,
    /// `[ros2.origin]`: the arena pose of the odometry frame's origin
    /// (of the map's, with `map`).
    pub origin: Pose2,
    /// `map` -> `odom` the base publishes on `/tf` (the agent's
    /// `map_frame = "map"` is then set).
    pub map: Option<Pose2>,
    /// Where the base starts, in arena coordinates (the fake is told it
    /// in its odometry frame).
    pub start: Pose2,
    /// Lines added to the agent's `[ros2]` section.
    pub ros2: String,
    /// Arguments added to the fake base's.
    pub base_args: Vec<String>,
}

impl Setup {
    pub fn new(demo: usize, start: Pose2) -> Setup {
        Setup {
            demo,
            origin: Pose2::new(0.0, 0.0, 0.0),
            map: None,
            start,
            ros2: String::new(),
            base_args: Vec::new(),
        }
    }
}

impl Setup {
    /// The arena pose of the odometry frame's origin: the origin, composed
    /// with `map` -> `odom` if there is one.
    pub fn odom_frame(&self) -> Pose2 {
        self.map.map_or(self.origin, |m| self.origin.compose(m))
    }
}

/// The agent's config: a diff-drive TurtleBot 3 Burger on DDS.
pub fn agent_config(setup: &Setup) -> String {
    let o = setup.origin;
    format!(
        "name = \"{NAME}\"\ncontrol_rate_hz = 20\ntelemetry_rate_hz = 10\n\
         [platform]\nkind = \"diff-drive\"\ntrack_width = 0.16\nmax_wheel_speed = {MAX_SPEED}\n\
         [ros2]\nnamespace = \"/{NAME}\"\nodom_timeout = 2.0\nmap_frame = \"{}\"\n{}\n\
         [ros2.origin]\nx = {}\ny = {}\nheading = {}\n\
         [link]\nkind = \"udp\"\nrouter = \"{ROUTER}\"\n\
         [failsafe]\nchannel_timeout = 0.5\nrouter_timeout = 1.0\n\
         [safety]\nradius = {RADIUS}\n",
        if setup.map.is_some() { "map" } else { "" },
        setup.ros2,
        o.x,
        o.y,
        o.heading
    )
}

/// Why this machine cannot run the base tests, if it cannot: what the
/// DDS rig needs, and a `mech-agent` built with ROS 2 (its feature
/// `ros2`): `mech-agent --check` joins the base's DDS domain (here in a
/// namespace of its own), or says the build has no ROS 2 support. Asked
/// once per test run.
pub fn unavailable() -> Option<String> {
    static WHY: std::sync::OnceLock<Option<String>> = std::sync::OnceLock::new();
    WHY.get_or_init(ask_unavailable).clone()
}

fn ask_unavailable() -> Option<String> {
    if let Some(why) = rig::unavailable() {
        return Some(why);
    }
    let ns = Netns::create();
    let dir = tempfile::tempdir().expect("temp dir");
    let config = dir.path().join("tb3.toml");
    std::fs::write(
        &config,
        agent_config(&Setup::new(0, Pose2::new(0.0, 0.0, 0.0))),
    )
    .expect("agent config");
    let out = ns
        .command(binary("mech-agent"))
        .arg("--config")
        .arg(&config)
        .arg("--check")
        .stdin(Stdio::null())
        .output();
    let out = match out {
        Ok(o) => o,
        Err(e) => {
            return Some(format!(
                "{} does not run ({e}): {BUILD}",
                binary("mech-agent").display()
            ));
        }
    };
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    // "no ROS 2 support" (--check), "no ros2 support" (an agent started).
    let said = text.lines().find(|l| {
        l.to_lowercase()
            .replace("ros 2", "ros2")
            .contains("no ros2 support")
    });
    // Otherwise ready, or failing for another reason (which the test
    // shows).
    said.map(|said| {
        format!(
            "mech-agent was built without ROS 2 ({}): {BUILD}",
            said.trim()
        )
    })
}

/// How to build what the tests run.
const BUILD: &str = "build it with `cargo build --workspace --bins --features mech-agent/ros2`";

/// Skips a test this machine cannot run, saying why; under CI (`CI` set)
/// that is a failure instead.
pub fn skip_unless_available() -> bool {
    rig::skip_if(unavailable(), "the ROS 2 base tests")
}

/// Everything of one test; dropping it kills every process and deletes
/// the namespace.
#[derive(Debug)]
pub struct BaseRig {
    pub op: Arc<Operator>,
    pub base: Node,
    agent: Proc,
    station: Option<Proc>,
    pub setup: Setup,
    pub dir: tempfile::TempDir,
    /// Declared last: dropped after the processes in it.
    _ns: Netns,
}

impl BaseRig {
    /// Starts the station, the fake base and the agent, attaches, and
    /// waits for the robot to register.
    pub fn start(setup: Setup) -> BaseRig {
        let ns = Netns::create();
        let dir = tempfile::tempdir().expect("temp dir");
        let station = rig::start_station(&ns, dir.path(), setup.demo, None);
        let odom_start = setup.start.relative_to(setup.odom_frame());
        let mut args: Vec<String> = vec![
            "--namespace".to_string(),
            format!("/{NAME}"),
            "--max-speed".into(),
            MAX_SPEED.to_string(),
            "--x".into(),
            odom_start.x.to_string(),
            "--y".into(),
            odom_start.y.to_string(),
            "--yaw".into(),
            odom_start.heading.to_string(),
        ];
        if let Some(m) = setup.map {
            args.extend(["--map".into(), format!("{},{},{}", m.x, m.y, m.heading)]);
        }
        args.extend(setup.base_args.iter().cloned());
        let base = Node::python(&ns, dir.path(), "fake_base.py", &args, "base.log");
        let config = dir.path().join("tb3.toml");
        std::fs::write(&config, agent_config(&setup)).expect("agent config");
        let agent = ns
            .command(binary("mech-agent"))
            .arg("--config")
            .arg(&config)
            .stdin(Stdio::null())
            .stdout(log_file(dir.path(), "agent.out"))
            .stderr(log_file(dir.path(), "agent.log"))
            .spawn()
            .expect("mech-agent starts");
        let op = Arc::new(Operator::attach(&dir.path().join("gcs.sock")));
        let mut rig = BaseRig {
            op,
            base,
            agent: Proc(agent),
            station: Some(station),
            setup,
            dir,
            _ns: ns,
        };
        rig.eventually("the robot registered, with the base's odometry", |r| {
            let (_, t) = r.op.robot(NAME)?;
            (t["link"] == "connected" && t["pose"]["x"].is_f64()).then_some(())
        });
        rig
    }

    /// The agent's process id (for its CPU time and memory: the bench).
    #[allow(dead_code)]
    pub fn agent_pid(&self) -> u32 {
        self.agent.0.id()
    }

    /// The fake base's state (true pose, the last cmd_vel...).
    pub fn state(&mut self) -> Value {
        self.base.ask(json!({"op": "state"}))
    }

    /// The base's true pose in the arena.
    pub fn truth(&mut self) -> Pose2 {
        let s = self.state();
        self.setup.odom_frame().compose(pose_of(&s))
    }

    /// cmd_vel samples the base received after `since`: (t, vx, wz, writer).
    pub fn cmds(&mut self, since: f64) -> Vec<(f64, f64, f64, u64)> {
        let a = self.base.ask(json!({"op": "cmds", "since": since}));
        a["cmds"]
            .as_array()
            .map(|v| {
                v.iter()
                    .map(|c| {
                        (
                            num(&c[0]),
                            num(&c[1]),
                            num(&c[2]),
                            c[3].as_u64().unwrap_or(99),
                        )
                    })
                    .collect()
            })
            .unwrap_or_default()
    }

    /// The base's true poses in the arena after `since`, with their times.
    pub fn track(&mut self, since: f64) -> Vec<(f64, Pose2)> {
        let a = self.base.ask(json!({"op": "track", "since": since}));
        let origin = self.setup.odom_frame();
        a["track"]
            .as_array()
            .map(|v| {
                v.iter()
                    .map(|p| {
                        let odom = Pose2::new(num(&p[1]), num(&p[2]), num(&p[3]));
                        (num(&p[0]), origin.compose(odom))
                    })
                    .collect()
            })
            .unwrap_or_default()
    }

    /// The robot as the newest snapshot shows it.
    pub fn robot(&self) -> Value {
        self.op.robot(NAME).map(|(_, r)| r).unwrap_or(Value::Null)
    }

    /// Kills the station (SIGKILL: no Bye to the robots).
    pub fn kill_station(&mut self) {
        self.station = None;
    }

    /// Whether the agent still runs.
    pub fn agent_running(&mut self) -> bool {
        matches!(self.agent.0.try_wait(), Ok(None))
    }

    /// The logs and the station's last events, for failure messages.
    pub fn logs(&self) -> String {
        let d = self.dir.path();
        format!(
            "--- agent.log\n{}\n--- base.log\n{}\n--- station.log\n{}\n--- events\n{}",
            tail(d, "agent.log", 40),
            tail(d, "base.log", 20),
            tail(d, "station.log", 20),
            self.op.tail(30)
        )
    }

    /// Polls `check` until it returns Some, or panics with `what`, the
    /// base's state and the logs after [`WAIT`].
    pub fn eventually<T>(&mut self, what: &str, check: impl FnMut(&mut BaseRig) -> Option<T>) -> T {
        self.eventually_within(WAIT, what, check)
    }

    pub fn eventually_within<T>(
        &mut self,
        timeout: Duration,
        what: &str,
        mut check: impl FnMut(&mut BaseRig) -> Option<T>,
    ) -> T {
        if let Some(t) = rig::poll(timeout, || check(self)) {
            return t;
        }
        let state = self.state();
        panic!(
            "{what}: not within {timeout:?}\nbase: {state}\nrobot: {}\n{}",
            self.robot(),
            self.logs()
        );
    }
}

/// A JSON number (NaN when absent or null).
pub fn num(v: &Value) -> f64 {
    v.as_f64().unwrap_or(f64::NAN)
}

/// The pose in a fake base's state (its odometry frame).
pub fn pose_of(s: &Value) -> Pose2 {
    Pose2::new(num(&s["x"]), num(&s["y"]), num(&s["yaw"]))
}

/// The pose of a robot of a snapshot.
pub fn reported(robot: &Value) -> Pose2 {
    let p = &robot["pose"];
    Pose2::new(num(&p["x"]), num(&p["y"]), num(&p["heading"]))
}

/// The true pose at `t` from a track (linear between samples; the
/// nearest end outside it).
pub fn at(track: &[(f64, Pose2)], t: f64) -> Option<Pose2> {
    let i = track.partition_point(|(ti, _)| *ti <= t);
    match (track.get(i.wrapping_sub(1)), track.get(i)) {
        (Some(&(t0, a)), Some(&(t1, b))) => {
            let k = if t1 > t0 { (t - t0) / (t1 - t0) } else { 0.0 };
            Some(Pose2::new(
                a.x + k * (b.x - a.x),
                a.y + k * (b.y - a.y),
                wrap(a.heading + k * wrap(b.heading - a.heading)),
            ))
        }
        (Some(&(_, a)), None) => Some(a),
        (None, Some(&(_, b))) => Some(b),
        (None, None) => None,
    }
}
