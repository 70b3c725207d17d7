//! The authenticated control plane end to end: a station that requires
//! keys, a simulated robot registering with its own key, and the Python
//! controller from docs/protocol.md signing its commands. A controller with
//! a key the station does not list moves nothing; the listed one drives the
//! robot.

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::station::{free_port, keygen};

/// Runs the documented Python controller with `key` for `seconds`.
fn python_controller(key: &Path, port: u16, seconds: f64) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/examples/controller.py");
    let status = Command::new("python3")
        .arg(script)
        .arg(key)
        .arg(format!("127.0.0.1:{port}"))
        .arg(seconds.to_string())
        .status()
        .expect("python3 runs (scripts/deps.sh installs msgpack)");
    assert!(status.success(), "the Python controller failed");
}

/// `(x, y)` from a `status` result line (`... at (x, y) heading ...`).
fn position(line: &str) -> (f64, f64) {
    let at = line.find(" at (").expect("a position in the status line") + 5;
    let end = at + line[at..].find(')').expect("closing parenthesis");
    let mut xy = line[at..end]
        .split(',')
        .map(|v| v.trim().parse::<f64>().unwrap());
    (xy.next().unwrap(), xy.next().unwrap())
}

/// Writes `text` to `path`, and gives the path back.
fn write(path: &Path, text: &str) -> std::path::PathBuf {
    std::fs::write(path, text).unwrap();
    path.to_path_buf()
}

/// A simulated kiwi `name`, registering with the router on `port`, with
/// `auth` (an `[auth]` section, or nothing).
fn robot_config(dir: &Path, name: &str, port: u16, auth: &str) -> std::path::PathBuf {
    write(
        &dir.join(format!("{name}.toml")),
        &format!(
            "name = \"{name}\"\n[platform]\nkind = \"kiwi\"\nradius = 0.1\n\
             max_wheel_speed = 0.5\n[position]\nkind = \"sim\"\n\
             [link]\nkind = \"udp\"\nrouter = \"127.0.0.1:{port}\"\n{auth}"
        ),
    )
}

/// The station's script: the robot's position before the controllers, after
/// the intruder's and after the listed one's. The listed controller starts
/// when the test reads `listed` (Python took seconds to start on a loaded
/// machine), so the script waits for the robot to move, not a fixed time.
const SCRIPT: &str = "spawn 1\nwait connected robot_1 10s\nroute robot_1 ext/python\n\
                      wait route robot_1 ext/python 5s\nsleep 500ms\nstatus robot_1\n\
                      log intruder\nsleep 2s\nstatus robot_1\nlog listed\n\
                      wait moved robot_1 0.3 30s\nstatus robot_1\n";

#[test]
fn the_documented_python_controller_signs_and_drives_a_simulated_robot() {
    let dir = tempfile::tempdir().unwrap();
    let (listed, intruder) = (
        dir.path().join("python.key"),
        dir.path().join("intruder.key"),
    );
    keygen("python", &listed);
    keygen("python", &intruder);
    let port = free_port();
    let config = write(
        &dir.path().join("gcs.toml"),
        &format!(
            "[router]\nudp = \"127.0.0.1:{port}\"\ntcp = \"127.0.0.1:0\"\n\
             [auth]\nmode = \"required\"\n\
             [[auth.keys]]\nrole = \"controller\"\nname = \"python\"\nfile = \"python.key\"\n\
             channels = [\"ext/python\"]\n"
        ),
    );
    let args: [&std::ffi::OsStr; 4] = [
        "--config".as_ref(),
        config.as_os_str(),
        "--script".as_ref(),
        "-".as_ref(),
    ];
    let mut gcs = mech_e2e::spawn_mech_gcs(&args, SCRIPT, dir.path());
    let mut lines = BufReader::new(gcs.stdout.take().unwrap()).lines();
    let mut all = Vec::new();
    let mut next_until = |marker: &str, all: &mut Vec<String>| {
        let deadline = Instant::now() + Duration::from_secs(30);
        for line in lines.by_ref() {
            let line = line.unwrap();
            all.push(line.clone());
            if line.contains(marker) {
                return;
            }
            assert!(Instant::now() < deadline, "no {marker:?}: {all:#?}");
        }
        panic!("mech-gcs ended before {marker:?}: {all:#?}");
    };
    next_until("\"summary\":\"intruder\"", &mut all);
    python_controller(&intruder, port, 1.5);
    next_until("\"summary\":\"listed\"", &mut all);
    python_controller(&listed, port, 3.0);
    next_until("\"type\":\"summary\"", &mut all);
    let status = gcs.wait_with_output().unwrap();
    let statuses: Vec<&String> = all
        .iter()
        .filter(|l| l.contains("\"command\":\"status robot_1\""))
        .collect();
    assert_eq!(statuses.len(), 3, "{all:#?}");
    let (start, after_intruder, end) = (
        position(statuses[0]),
        position(statuses[1]),
        position(statuses[2]),
    );
    let moved = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).hypot(a.1 - b.1);
    assert!(
        moved(start, after_intruder) < 0.05,
        "the intruder's key moved the robot {start:?} -> {after_intruder:?}"
    );
    assert!(
        moved(after_intruder, end) > 0.3,
        "the listed controller moved the robot only {after_intruder:?} -> {end:?}"
    );
    let summary = all.last().unwrap();
    assert!(summary.contains("\"authenticated\":true"), "{summary}");
    assert!(
        !summary.contains("\"unknown-key\":0"),
        "the intruder's messages are counted: {summary}"
    );
    assert!(
        status.status.success(),
        "{}",
        String::from_utf8_lossy(&status.stderr)
    );
}

#[test]
fn the_protocol_page_shows_the_tested_controller() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let file = std::fs::read_to_string(root.join("docs/examples/controller.py")).unwrap();
    let block = mech_e2e::doc_block(
        "docs/protocol.md",
        "## Example: a controller in Python",
        "python",
    );
    assert_eq!(block, file, "docs/protocol.md and controller.py differ");
}

#[test]
fn a_robot_with_its_key_registers_and_one_without_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    keygen("rover", &dir.path().join("rover.key"));
    let port = free_port();
    let config = write(
        &dir.path().join("gcs.toml"),
        &format!(
            "[router]\nudp = \"127.0.0.1:{port}\"\ntcp = \"127.0.0.1:0\"\n\
             [[auth.keys]]\nrole = \"robot\"\nname = \"rover\"\nfile = \"rover.key\"\n"
        ),
    );
    let keyed = robot_config(dir.path(), "rover", port, "[auth]\nkey = \"rover.key\"\n");
    let unkeyed = robot_config(dir.path(), "stray", port, "");
    let check = Command::new(mech_e2e::binary("mech-agent"))
        .args(["--check", "--config"])
        .arg(&keyed)
        .output()
        .unwrap();
    assert!(
        check.status.success(),
        "{}",
        String::from_utf8_lossy(&check.stderr)
    );
    let gcs = Command::new(mech_e2e::binary("mech-gcs"))
        .arg("--config")
        .arg(&config)
        .args(["--script", "-"])
        .env("XDG_STATE_HOME", dir.path())
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let agents: Vec<_> = [&keyed, &unkeyed]
        .iter()
        .map(|c| {
            Command::new(mech_e2e::binary("mech-agent"))
                .arg("--config")
                .arg(c)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap()
        })
        .collect();
    let mut gcs = gcs;
    gcs.stdin
        .take()
        .unwrap()
        .write_all(b"wait connected rover 10s\nsleep 1500ms\nstatus\n")
        .unwrap();
    let out = gcs.wait_with_output().unwrap();
    for mut a in agents {
        let _ = a.kill();
        let _ = a.wait();
    }
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let status = text
        .lines()
        .find(|l| l.contains("\"command\":\"status\""))
        .unwrap();
    assert!(
        status.contains("rover #") && !status.contains("stray #"),
        "{status}"
    );
    assert!(
        status.contains("rejected") && status.contains("unsigned"),
        "{status}"
    );
}
