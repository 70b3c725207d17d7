//! The rig the DDS tests run in: a network namespace of their own (only
//! `lo`, with multicast on, so DDS discovery stays inside it), the station
//! (`mech-gcs serve --demo N`), the bridge (`mech-ros2`) and a ROS 2 node
//! made of Cyclone DDS's Python binding (`ros2_node.py`), each a process
//! in the namespace. Every part is a guard: processes are killed and the
//! namespace deleted when the test ends, however it ends. The parts
//! (namespace, station, Python nodes, polling) are public for other rigs
//! (`base_rig.rs`: the agent's ROS 2 base).

use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use serde_json::Value;

/// Generous: a loaded 2-core machine runs these.
pub const WAIT: Duration = Duration::from_secs(30);

/// The router's UDP port inside the namespace (outside DDS domain 0's
/// 7400-7649).
pub const ROUTER: &str = "127.0.0.1:17400";

static NEXT: AtomicU32 = AtomicU32::new(0);
const PREFIX: &str = "mechros-";

/// Why this machine cannot run the rig, if it cannot: root, `ip`, and
/// Python's `cyclonedds` are needed.
pub fn unavailable() -> Option<String> {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let root = status
        .lines()
        .find(|l| l.starts_with("Uid:"))
        .is_some_and(|l| l.split_whitespace().nth(1) == Some("0"));
    if !root {
        return Some("not root (network namespaces need it)".into());
    }
    let ok = |p: &str, args: &[&str]| {
        Command::new(p)
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    };
    if !ok("ip", &["-V"]) {
        return Some("`ip` is missing (scripts/deps.sh installs iproute2)".into());
    }
    if !ok("python3", &["-c", "import cyclonedds.domain"]) {
        return Some("Python's cyclonedds is missing (scripts/deps.sh installs it)".into());
    }
    None
}

/// Skips a test this machine cannot run, saying why; under CI (`CI` set)
/// that is a failure instead, since CI must run them.
pub fn skip_unless_available() -> bool {
    skip_if(unavailable(), "the ROS 2 tests")
}

/// Whether to skip `tests` for `why` (if any), saying so; under CI a
/// reason is a failure instead.
pub fn skip_if(why: Option<String>, tests: &str) -> bool {
    let Some(why) = why else {
        return false;
    };
    if std::env::var_os("CI").is_some() {
        panic!("CI must run {tests}: {why}");
    }
    eprintln!("skipped: {why}");
    true
}

/// A binary of the workspace: this package's from Cargo, the others next
/// to it in the target directory (`scripts/test.sh` builds them first).
pub fn binary(name: &str) -> PathBuf {
    if name == "mech-ros2" {
        return PathBuf::from(env!("CARGO_BIN_EXE_mech-ros2"));
    }
    let exe = std::env::current_exe().expect("test executable path");
    exe.parent()
        .and_then(Path::parent)
        .expect("target/<profile>/deps")
        .join(name)
}

fn run(args: &[&str]) {
    let out = Command::new("ip")
        .args(args)
        .stdin(Stdio::null())
        .output()
        .expect("ip runs");
    assert!(
        out.status.success(),
        "ip {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// A network namespace with `lo` up and multicast on, deleted on drop.
#[derive(Debug)]
pub struct Netns {
    pub name: String,
}

impl Netns {
    pub fn create() -> Netns {
        sweep();
        let name = format!(
            "{PREFIX}{}-{}",
            std::process::id(),
            NEXT.fetch_add(1, Ordering::Relaxed)
        );
        run(&["netns", "add", &name]);
        let ns = Netns { name };
        run(&["-n", &ns.name, "link", "set", "lo", "up"]);
        run(&["-n", &ns.name, "link", "set", "lo", "multicast", "on"]);
        ns
    }

    /// `program` run inside the namespace.
    pub fn command(&self, program: impl AsRef<std::ffi::OsStr>) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.name]).arg(program);
        c
    }
}

impl Drop for Netns {
    fn drop(&mut self) {
        let _ = Command::new("ip")
            .args(["netns", "del", &self.name])
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .status();
    }
}

/// Deletes namespaces left by test processes that no longer run.
fn sweep() {
    let Ok(out) = Command::new("ip").args(["netns", "list"]).output() else {
        return;
    };
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let Some(name) = line.split_whitespace().next() else {
            continue;
        };
        let pid = name
            .strip_prefix(PREFIX)
            .and_then(|r| r.split('-').next())
            .and_then(|p| p.parse::<u32>().ok());
        if let Some(pid) = pid
            && !Path::new(&format!("/proc/{pid}")).exists()
        {
            let _ = Command::new("ip").args(["netns", "del", name]).status();
        }
    }
}

/// A child process, killed when dropped.
#[derive(Debug)]
pub struct Proc(pub Child);

impl Drop for Proc {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Everything of one test: namespace, station, bridge, node, and a
/// temporary directory for the station's state and the logs.
#[derive(Debug)]
pub struct Rig {
    pub node: Node,
    pub bridge: Proc,
    _station: Proc,
    pub dir: tempfile::TempDir,
    /// Declared last: dropped after the processes in it.
    _ns: Netns,
}

/// `mech-gcs keygen NAME` for each of `keys`, as `NAME.key` in `dir`.
fn keygen(dir: &Path, keys: &[&str]) {
    for k in keys {
        let out = Command::new(binary("mech-gcs"))
            .args(["keygen", k, "--out"])
            .arg(dir.join(format!("{k}.key")))
            .output()
            .expect("mech-gcs keygen runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

impl Rig {
    /// Starts the station with `robots` simulated robots, the bridge with
    /// `bridge_args`, and the node watching every robot.
    pub fn start(robots: usize, bridge_args: &[&str], stamped: bool) -> Rig {
        Rig::start_with(robots, None, &[], bridge_args, stamped)
    }

    /// [`Rig::start`] for a station configured by `station_toml` (in the
    /// rig's directory, beside the keys `keys` names, made with `mech-gcs
    /// keygen NAME` as `NAME.key`); `@DIR@` in `bridge_args` is that
    /// directory.
    pub fn start_with(
        robots: usize,
        station_toml: Option<&str>,
        keys: &[&str],
        bridge_args: &[&str],
        stamped: bool,
    ) -> Rig {
        let ns = Netns::create();
        let dir = tempfile::tempdir().expect("temp dir");
        keygen(dir.path(), keys);
        let station = start_station(&ns, dir.path(), robots, station_toml);
        let mut bridge = ns.command(binary("mech-ros2"));
        let dir_text = dir.path().display().to_string();
        bridge
            .args(["--router", ROUTER, "--summary-every", "1"])
            .args(bridge_args.iter().map(|a| a.replace("@DIR@", &dir_text)))
            .stdin(Stdio::null())
            .stdout(log_file(dir.path(), "bridge.out"))
            .stderr(log_file(dir.path(), "bridge.log"));
        let bridge = Proc(bridge.spawn().expect("mech-ros2 starts"));
        let mut node = Node::python(&ns, dir.path(), "ros2_node.py", &[], "node.log");
        let names: Vec<String> = (1..=robots).map(|i| format!("robot_{i}")).collect();
        node.ask(serde_json::json!({"op": "watch", "robots": names, "stamped": stamped}));
        Rig {
            node,
            bridge,
            _station: station,
            dir,
            _ns: ns,
        }
    }

    /// Runs a script on the station (`mech-gcs --attach --script`);
    /// panics with its output if a command fails.
    pub fn script(&self, source: &str) -> String {
        let mut child = Command::new(binary("mech-gcs"))
            .arg("--attach")
            .arg(self.dir.path().join("gcs.sock"))
            .args(["--script", "-"])
            .env("XDG_STATE_HOME", self.dir.path())
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("mech-gcs --attach starts");
        child
            .stdin
            .take()
            .expect("stdin")
            .write_all(source.as_bytes())
            .expect("script written");
        let out = child.wait_with_output().expect("script ends");
        let text = String::from_utf8_lossy(&out.stdout).into_owned()
            + &String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "script {source:?} failed:\n{text}");
        text
    }

    /// Stops the bridge with SIGTERM; its last line on stdout is its
    /// counters as JSON.
    pub fn stop_bridge(&mut self) -> Value {
        // `ip netns exec` execs the bridge: the pid is the bridge's.
        let pid = self.bridge.0.id().to_string();
        let _ = Command::new("kill").args(["-TERM", &pid]).status();
        let _ = self.bridge.0.wait();
        let out = std::fs::read_to_string(self.dir.path().join("bridge.out")).unwrap_or_default();
        let line = out.lines().last().unwrap_or("{}");
        serde_json::from_str(line).unwrap_or_else(|e| panic!("{e}: {out:?}"))
    }

    /// The bridge's log, for failure messages.
    pub fn logs(&self) -> String {
        format!(
            "--- bridge.log\n{}\n--- node.log\n{}",
            tail(self.dir.path(), "bridge.log", 30),
            tail(self.dir.path(), "node.log", 30)
        )
    }
}

/// A log file `name` in `dir`, for a process's output.
pub fn log_file(dir: &Path, name: &str) -> std::fs::File {
    std::fs::File::create(dir.join(name)).expect("log file")
}

/// The last `lines` lines of the log `name` in `dir`, for failure
/// messages.
pub fn tail(dir: &Path, name: &str, lines: usize) -> String {
    let text = std::fs::read_to_string(dir.join(name)).unwrap_or_default();
    let all: Vec<&str> = text.lines().collect();
    all[all.len().saturating_sub(lines)..].join("\n")
}

/// Starts the station in `ns` (`mech-gcs serve --demo ROBOTS`, router on
/// [`ROUTER`], control socket `gcs.sock` in `dir`, its log `station.log`),
/// configured by `station_toml` if given; returns once it serves.
pub fn start_station(ns: &Netns, dir: &Path, robots: usize, station_toml: Option<&str>) -> Proc {
    let mut station = ns.command(binary("mech-gcs"));
    station.args(["serve", "--demo", &robots.to_string(), "--udp", ROUTER]);
    if let Some(toml) = station_toml {
        let path = dir.join("gcs.toml");
        std::fs::write(&path, toml).expect("station config");
        station.arg("--config").arg(path);
    }
    station
        .args(["--tcp", "127.0.0.1:17401", "--socket"])
        .arg(dir.join("gcs.sock"))
        .env("XDG_STATE_HOME", dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(log_file(dir, "station.log"));
    let mut station = Proc(station.spawn().expect("mech-gcs serve starts"));
    let out = station.0.stdout.take().expect("stdout");
    let mut lines = BufReader::new(out).lines();
    loop {
        match lines.next() {
            Some(Ok(l)) if l.contains("mech-gcs serving") => break,
            Some(Ok(_)) => continue,
            _ => panic!("the station did not start: see {}", dir.display()),
        }
    }
    std::thread::spawn(move || for _ in lines {});
    station
}

/// The ROS 2 node: one JSON command in, one JSON answer out.
#[derive(Debug)]
pub struct Node {
    _proc: Proc,
    stdin: ChildStdin,
    answers: mpsc::Receiver<String>,
}

impl Node {
    /// Runs the Python node `script` (in this directory) with `args` in
    /// `ns`, Cyclone DDS on `lo` only (its configuration written to
    /// `dir`), its standard error into `log` in `dir`.
    pub fn python(ns: &Netns, dir: &Path, script: &str, args: &[String], log: &str) -> Node {
        let cyclone = dir.join("cyclonedds.xml");
        std::fs::write(
            &cyclone,
            "<CycloneDDS><Domain id=\"any\"><General><Interfaces>\
             <NetworkInterface name=\"lo\" multicast=\"true\"/></Interfaces>\
             <AllowMulticast>true</AllowMulticast></General></Domain></CycloneDDS>\n",
        )
        .expect("cyclone config");
        let mut node = ns.command("python3");
        node.arg(
            Path::new(env!("CARGO_MANIFEST_DIR"))
                .join("tests")
                .join(script),
        )
        .args(args)
        .env("CYCLONEDDS_URI", format!("file://{}", cyclone.display()))
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(log_file(dir, log));
        Node::start(node)
    }

    fn start(mut command: Command) -> Node {
        let mut proc = Proc(command.spawn().expect("python3 runs the node"));
        let stdin = proc.0.stdin.take().expect("stdin");
        let stdout = proc.0.stdout.take().expect("stdout");
        let (tx, answers) = mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let node = Node {
            _proc: proc,
            stdin,
            answers,
        };
        let ready = node
            .answers
            .recv_timeout(WAIT)
            .expect("the node says it is ready");
        assert!(ready.contains("ready"), "{ready}");
        node
    }

    /// Sends one command and returns its answer.
    pub fn ask(&mut self, command: Value) -> Value {
        writeln!(self.stdin, "{command}").expect("command written");
        self.stdin.flush().expect("flushed");
        let line = self
            .answers
            .recv_timeout(WAIT)
            .unwrap_or_else(|e| panic!("no answer to {command}: {e}"));
        serde_json::from_str(&line).unwrap_or_else(|e| panic!("{e}: {line}"))
    }

    /// What the node has received.
    pub fn state(&mut self) -> Value {
        self.ask(serde_json::json!({"op": "state"}))
    }
}

/// Polls `f` every 50 ms until it returns Some, or None after `timeout`.
pub fn poll<T>(timeout: Duration, mut f: impl FnMut() -> Option<T>) -> Option<T> {
    let deadline = Instant::now() + timeout;
    loop {
        if let Some(t) = f() {
            return Some(t);
        }
        if Instant::now() >= deadline {
            return None;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// Polls `check` on the node's state until it returns Some, or panics
/// with `what` and the logs after [`WAIT`].
pub fn eventually<T>(rig: &mut Rig, what: &str, mut check: impl FnMut(&Value) -> Option<T>) -> T {
    let mut last = Value::Null;
    poll(WAIT, || {
        last = rig.node.state();
        check(&last)
    })
    .unwrap_or_else(|| {
        panic!(
            "{what}: not within {WAIT:?}\nlast state: {last:#}\n{}",
            rig.logs()
        )
    })
}
