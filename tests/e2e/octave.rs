//! The MATLAB/Octave example: its encoder's golden messages checked
//! against mech-proto (always), and, when GNU Octave is installed (CI
//! installs it), the encoder's own test and the controller driving a
//! simulated robot through a real `mech-gcs --script`.

use std::process::{Command, Stdio};
use std::time::Duration;

use mech_proto::{Body, Command as Cmd, Envelope, Header, Stop, Twist};

use crate::station::{Station, observe, root, run_ok};

/// The hex strings `test_mech_pack.m` expects, by case name.
fn matlab_golden() -> Vec<(String, String)> {
    let text = std::fs::read_to_string(root().join("clients/matlab/test_mech_pack.m")).unwrap();
    let mut cases = Vec::new();
    let mut name = None;
    for line in text.lines().map(str::trim) {
        if let Some(rest) = line.strip_prefix('\'') {
            let quoted = rest.split('\'').next().unwrap_or_default();
            if rest.contains("mech_envelope") {
                name = Some(quoted.to_string());
            } else if let Some(n) = name.take() {
                cases.push((n, quoted.replace(' ', "")));
            }
        }
    }
    cases
}

#[test]
fn the_matlab_golden_messages_are_what_mech_proto_writes() {
    let hex = |env: &Envelope| -> String {
        mech_proto::encode(env)
            .unwrap()
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect()
    };
    let at = |sender: &str, destination: &str, channel: &str, seq: u32, stamp_us: u64| Header {
        seq,
        stamp_us,
        sender: sender.into(),
        destination: destination.into(),
        channel: channel.into(),
    };
    let expected = [
        (
            "twist",
            Envelope::new(
                at("gcs", "robot_1", "joy/0", 7, 1_000_000),
                Body::Command(Cmd::Twist(Twist {
                    vx: 0.5,
                    vy: 0.0,
                    vz: 0.0,
                    wz: -0.25,
                })),
            ),
        ),
        (
            "heartbeat",
            Envelope::new(
                at("robot_1", "router", "", 7, 1_000_000),
                Body::Heartbeat(mech_proto::Heartbeat { uptime_ms: 1500 }),
            ),
        ),
        (
            "route",
            Envelope::new(
                at("gcs", "robot_1", "", 7, 1_000_000),
                Body::Route(mech_proto::Route {
                    robot: "robot_1".into(),
                    channel: "joy/0".into(),
                    epoch: 3,
                }),
            ),
        ),
        (
            "stop",
            Envelope::new(
                at("matlab", "robot_2", "ext/matlab", 300, (1 << 32) + 5),
                Body::Command(Cmd::Stop(Stop {})),
            ),
        ),
    ];
    let golden = matlab_golden();
    assert_eq!(golden.len(), expected.len(), "{golden:?}");
    for ((name, want), (case, env)) in golden.iter().zip(&expected) {
        assert_eq!(name, case);
        assert_eq!(want, &hex(env), "{name}");
    }
}

/// GNU Octave, when installed (scripts/deps.sh installs it; CI must have it).
fn octave() -> Option<Command> {
    let found = Command::new("octave-cli")
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    if !found {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI runs the Octave example: scripts/deps.sh installs octave"
        );
        eprintln!("GNU Octave is not installed: the Octave example is not run");
        return None;
    }
    let mut c = Command::new("octave-cli");
    c.args(["--no-gui", "--quiet", "--no-init-file"])
        .current_dir(root().join("clients/matlab"));
    Some(c)
}

#[test]
fn the_octave_encoder_matches_the_golden_messages() {
    let Some(mut c) = octave() else { return };
    c.args(["--eval", "test_mech_pack"]);
    let out = run_ok(c, "octave-cli test_mech_pack");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(text.contains("7 passed, 0 failed"), "{text}");
}

#[test]
fn the_octave_controller_drives_a_simulated_robot() {
    let Some(mut c) = octave() else { return };
    let script = "spawn 1\nwait connected robot_1 10s\nroute robot_1 ext/matlab\n\
                  wait route robot_1 ext/matlab 5s\nlog go\nsleep 120s\n";
    let mut station = Station::start(script, &[]);
    station.until("\"summary\":\"go\"");
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let observer = {
        let (router, stop) = (station.router(), stop.clone());
        std::thread::spawn(move || observe(router, stop))
    };
    c.args([
        "--eval",
        &format!(
            "mech_controller('robot_1', 'ext/matlab', 4, '127.0.0.1', {})",
            station.port
        ),
    ]);
    let out = run_ok(c, "octave-cli mech_controller");
    std::thread::sleep(Duration::from_millis(300));
    stop.store(true, std::sync::atomic::Ordering::SeqCst);
    let track = observer.join().unwrap();
    station.child.kill().ok();
    station.child.wait().ok();
    let poses = &track["robot_1"];
    let (first, last) = (poses[0], poses[poses.len() - 1]);
    let moved = (last.0 - first.0).hypot(last.1 - first.1);
    let turned = mech_proto::wrap_angle(last.2 - first.2);
    // 4 s at 0.2 m/s and 0.4 rad/s: an arc of 0.8 m turning 1.6 rad left.
    assert!(
        moved > 0.4 && turned > 0.8,
        "moved {moved:.2} m, turned {turned:.2} rad: {}",
        String::from_utf8_lossy(&out.stdout)
    );
}
