//! Shared by the client tests: a `mech-gcs --script` station on a free
//! loopback port, a plain telemetry subscriber, and running other
//! languages' programs.

use std::io::{BufRead, BufReader, Lines};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdout, Command, Output};
use std::time::{Duration, Instant};

use mech_proto::{Body, Envelope, Header, Subscribe};

pub fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

pub fn free_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

/// `python3` with the client package on its path (as `pip install
/// ./clients/python` would put it).
pub fn python() -> Command {
    let mut c = Command::new("python3");
    c.env("PYTHONPATH", root().join("clients/python"));
    c
}

pub fn run_ok(mut c: Command, what: &str) -> Output {
    let out = c
        .output()
        .unwrap_or_else(|e| panic!("{what} runs (scripts/deps.sh installs it): {e}"));
    assert!(
        out.status.success(),
        "{what} failed:\n{}\n{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// A `mech-gcs --script -` run: the whole script is given at start, and
/// the test reads its JSON lines up to markers the script logs, running
/// the client under test in between.
pub struct Station {
    pub child: Child,
    lines: Lines<BufReader<ChildStdout>>,
    pub all: Vec<String>,
    pub port: u16,
    _dir: tempfile::TempDir,
}

impl Station {
    /// Starts a station on a free loopback port. `keys` lists `(name,
    /// role line)` controller keys to make and require; none runs it
    /// unauthenticated, as `--demo` does.
    pub fn start(script: &str, keys: &[(&str, &str)]) -> Station {
        let dir = tempfile::tempdir().unwrap();
        let port = free_port();
        let mut config = format!("[router]\nudp = \"127.0.0.1:{port}\"\ntcp = \"127.0.0.1:0\"\n");
        if !keys.is_empty() {
            config.push_str("[auth]\nmode = \"required\"\n");
        }
        for (name, extra) in keys {
            keygen(name, &dir.path().join(format!("{name}.key")));
            config.push_str(&format!(
                "[[auth.keys]]\nname = \"{name}\"\nfile = \"{name}.key\"\n{extra}\n"
            ));
        }
        let config_path = dir.path().join("gcs.toml");
        std::fs::write(&config_path, config).unwrap();
        let args: [&std::ffi::OsStr; 4] = [
            "--config".as_ref(),
            config_path.as_os_str(),
            "--script".as_ref(),
            "-".as_ref(),
        ];
        let mut child = mech_e2e::spawn_mech_gcs(&args, script, dir.path());
        let lines = BufReader::new(child.stdout.take().unwrap()).lines();
        Station {
            child,
            lines,
            all: Vec::new(),
            port,
            _dir: dir,
        }
    }

    pub fn key(&self, name: &str) -> PathBuf {
        self._dir.path().join(format!("{name}.key"))
    }

    pub fn router(&self) -> String {
        format!("127.0.0.1:{}", self.port)
    }

    /// Reads output lines until one contains `marker`.
    pub fn until(&mut self, marker: &str) {
        let deadline = Instant::now() + Duration::from_secs(60);
        for line in self.lines.by_ref() {
            let line = line.unwrap();
            self.all.push(line.clone());
            if line.contains(marker) {
                return;
            }
            assert!(Instant::now() < deadline, "no {marker:?}: {:#?}", self.all);
        }
        panic!("mech-gcs ended before {marker:?}: {:#?}", self.all);
    }

    /// Reads to the end; the output lines and whether the script succeeded.
    pub fn finish(mut self) -> (Vec<String>, bool) {
        self.until("\"type\":\"summary\"");
        let status = self.child.wait().unwrap();
        (self.all, status.success())
    }
}

/// A key named `name` in `file`, made by `mech-gcs keygen`.
pub fn keygen(name: &str, file: &Path) {
    let out = Command::new(mech_e2e::binary("mech-gcs"))
        .args(["keygen", name, "--out"])
        .arg(file)
        .output()
        .expect("mech-gcs keygen runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// `(x, y, heading)` from the result line of `status ROBOT`.
pub fn pose_in(lines: &[String], robot: &str, nth: usize) -> (f64, f64, f64) {
    let line = lines
        .iter()
        .filter(|l| l.contains(&format!("\"command\":\"status {robot}\"")))
        .nth(nth)
        .unwrap_or_else(|| panic!("status {robot} #{nth} in {lines:#?}"));
    let at = line.find(" at (").expect("a position") + 5;
    let end = at + line[at..].find(')').expect("closing parenthesis");
    let xy: Vec<f64> = line[at..end]
        .split(',')
        .map(|v| v.trim().parse().expect("a number"))
        .collect();
    let h = line.find("heading ").expect("a heading") + 8;
    let heading: String = line[h..]
        .chars()
        .take_while(|c| c.is_ascii_digit() || *c == '.' || *c == '-')
        .collect();
    let heading: f64 = heading.parse().expect("a heading number");
    (xy[0], xy[1], heading)
}

pub fn header(sender: &str, destination: &str, channel: &str) -> Header {
    Header {
        seq: 9,
        stamp_us: 1_700_000_000_000_000,
        sender: sender.into(),
        destination: destination.into(),
        channel: channel.into(),
    }
}

/// Telemetry poses seen by a plain subscriber (mech-proto over a UDP
/// socket, independent of the client under test), by robot.
pub type Track = std::collections::HashMap<String, Vec<(f64, f64, f64)>>;

/// Subscribes to an unauthenticated router's telemetry until `stop` is set.
pub fn observe(router: String, stop: std::sync::Arc<std::sync::atomic::AtomicBool>) -> Track {
    observe_telemetry(router, stop)
        .into_iter()
        .map(|(robot, ts)| {
            let poses = ts
                .iter()
                .map(|t| (t.pose.x, t.pose.y, t.pose.heading))
                .collect();
            (robot, poses)
        })
        .collect()
}

/// Every telemetry message an unauthenticated router fans out, by robot,
/// until `stop` is set.
pub fn observe_telemetry(
    router: String,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::collections::HashMap<String, Vec<mech_proto::Telemetry>> {
    observe_timed(router, stop)
        .into_iter()
        .map(|(robot, ts)| (robot, ts.into_iter().map(|(_, t)| t).collect()))
        .collect()
}

/// [`observe_telemetry`] with the moment each message arrived: the
/// samples of two robots are compared at one moment by it (their counts
/// differ when the observer was late or a datagram was lost).
pub fn observe_timed(
    router: String,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> std::collections::HashMap<String, Vec<(Instant, mech_proto::Telemetry)>> {
    let socket = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    socket
        .set_read_timeout(Some(Duration::from_millis(100)))
        .unwrap();
    let subscribe = mech_proto::encode(&Envelope::new(
        header("observer", "router", ""),
        Body::Subscribe(Subscribe { telemetry: true }),
    ))
    .unwrap();
    let mut seen =
        std::collections::HashMap::<String, Vec<(Instant, mech_proto::Telemetry)>>::new();
    let mut renewed = Instant::now() - Duration::from_secs(10);
    let mut buf = vec![0; 65_536];
    while !stop.load(std::sync::atomic::Ordering::SeqCst) {
        if renewed.elapsed() > Duration::from_secs(1) {
            socket.send_to(&subscribe, &router).unwrap();
            renewed = Instant::now();
        }
        let Ok(n) = socket.recv(&mut buf) else {
            continue;
        };
        if let Ok(mech_proto::Envelope {
            header,
            body: Body::Telemetry(t),
            ..
        }) = mech_proto::decode(&buf[..n])
        {
            seen.entry(header.sender)
                .or_default()
                .push((Instant::now(), t));
        }
    }
    seen
}
