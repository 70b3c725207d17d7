//! The binaries built for a Raspberry Pi's processors (`scripts/cross.sh`:
//! the arm64 and armhf agents, the arm64 station), run under qemu-user on
//! this machine against the x86 station, as they would on a robot:
//!
//! - each agent, with the Pi robot's own config (`--sim` for its wheels and
//!   tag), registers routed to none, drives a waypoint mission
//!   to arrival, obeys an e-stop while a controller keeps commanding it,
//!   drives again once released, and stops itself when the station goes
//!   away (its telemetry, still sent to the station's address, reports a
//!   failsafe with its actuators at zero, then it says Hello to find a
//!   station again);
//! - each agent's `--check` of the Pi config names the GPIO pins and the
//!   tag's serial port this machine lacks, and nothing else;
//! - the arm64 station runs a simulated fleet's mission to arrival and an
//!   e-stop.
//!
//! Emulation is slow and its timing uneven: the waits are long and only
//! behaviour is asserted. Without the cross-built binaries (a machine that
//! has not run `scripts/cross.sh`) the test says what it skipped, and fails
//! under CI (`CI` set), where they must run.

use std::io::Write;
use std::net::{SocketAddr, UdpSocket};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use mech_e2e::harness::controller::{Controller, Sample};
use mech_e2e::harness::station::{self, Station};
use mech_e2e::harness::{Killed, poll};
use mech_proto::{Body, FailsafeState};

/// A processor the agents are built for.
#[derive(Debug, Clone, Copy)]
struct Arch {
    /// Debian's name, used in the robot's name.
    debian: &'static str,
    triple: &'static str,
    qemu: &'static str,
}

const ARM64: Arch = Arch {
    debian: "arm64",
    triple: "aarch64-unknown-linux-gnu",
    qemu: "qemu-aarch64",
};
const ARMHF: Arch = Arch {
    debian: "armhf",
    triple: "armv7-unknown-linux-gnueabihf",
    qemu: "qemu-arm",
};

/// Where `scripts/cross.sh` leaves its root (the arm C libraries qemu
/// loads the binaries with) and its builds: `MECH_CROSS_DIR`, by default
/// the workspace's `target/cross`.
fn cross_dir() -> PathBuf {
    std::env::var_os("MECH_CROSS_DIR").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../target/cross"),
        PathBuf::from,
    )
}

/// A line of what the emulated binaries did, for the CI log: printed, and
/// appended to `emulated.log` beside the builds, which `scripts/test.sh`
/// shows after the tests (cargo keeps a passing test's output to itself).
fn report(line: &str) {
    println!("{line}");
    let path = cross_dir().join("emulated.log");
    if let Ok(mut file) = std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
    {
        let _ = writeln!(file, "{line}");
    }
}

/// The peak resident memory of a process (VmHWM), in MiB.
fn peak_rss_mib(pid: u32) -> Option<f64> {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).ok()?;
    let kib: f64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmHWM:"))?
        .trim()
        .trim_end_matches("kB")
        .trim()
        .parse()
        .ok()?;
    Some(kib / 1024.0)
}

/// `qemu-ARCH -L ROOT BINARY` for a cross-built binary, or why it cannot
/// run here.
fn emulated(arch: Arch, binary: &str) -> Result<Command, String> {
    let dir = cross_dir();
    let bin = dir
        .join("build")
        .join(arch.triple)
        .join("dist")
        .join(binary);
    if !bin.is_file() {
        return Err(format!(
            "{} is missing (bash scripts/cross.sh builds it)",
            bin.display()
        ));
    }
    if !mech_e2e::harness::have(arch.qemu, "--version") {
        return Err(format!(
            "{} is missing (apt-get install qemu-user)",
            arch.qemu
        ));
    }
    let mut cmd = Command::new(arch.qemu);
    cmd.arg("-L").arg(dir.join("root")).arg(bin);
    Ok(cmd)
}

/// The Pi robot of `config/agents/`, with its L298 and Pozyx tag.
fn pi_config() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/agents/pi-l298-diff-drive.toml")
}

#[test]
fn pi_binaries_run_under_emulation_against_the_station() {
    let mut failures = Vec::new();
    let mut ran = 0;
    for arch in [ARM64, ARMHF] {
        match emulated(arch, "mech-agent") {
            Ok(_) => {
                check_off_a_pi(arch);
                drive_against_the_x86_station(arch);
                ran += 1;
            }
            Err(why) => failures.push(format!("{} agent: {why}", arch.debian)),
        }
    }
    match emulated(ARM64, "mech-gcs") {
        Ok(cmd) => {
            arm64_station_runs_a_mission(cmd);
            ran += 1;
        }
        Err(why) => failures.push(format!("arm64 station: {why}")),
    }
    for f in &failures {
        println!("SKIPPED {f}");
    }
    // `scripts/test.sh` sets MECH_CROSS_REQUIRED after building them.
    let required = ["CI", "MECH_CROSS_REQUIRED"]
        .iter()
        .any(|v| std::env::var_os(v).is_some());
    assert!(
        !required || failures.is_empty(),
        "the cross-built binaries must run here: {failures:?}"
    );
    report(&format!("cross-built binaries run under qemu: {ran} of 3"));
}

/// `--check` of the Pi config: exit 1, the GPIO pins and the serial port,
/// nothing else on either stream.
fn check_off_a_pi(arch: Arch) {
    let out = emulated(arch, "mech-agent")
        .expect("checked")
        .arg("--config")
        .arg(pi_config())
        .arg("--check")
        .output()
        .expect("qemu runs");
    let stdout = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(out.status.code(), Some(1), "{}: {stdout}", arch.debian);
    assert_eq!(lines.len(), 3, "{}: {stdout}", arch.debian);
    assert!(
        lines[0].ends_with("the config is valid, but this machine cannot open:"),
        "{stdout}"
    );
    // A build with GPIO support: rppal's own reason, not a missing feature.
    assert!(
        lines[1].starts_with("  GPIO 6, 12, 20, 13, 19, 26 (actuators: L298): ")
            && !lines[1].contains("rebuild"),
        "{stdout}"
    );
    assert!(
        lines[2].starts_with("  serial port /dev/ttyACM0 at 115200 baud (position: Pozyx): "),
        "{stdout}"
    );
    assert!(
        out.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    report(&format!(
        "{} agent --check of the Pi config (exit 1):\n{}",
        arch.debian,
        stdout.trim_end()
    ));
}

/// The station's script: the robot registers, runs a mission to arrival,
/// then is routed to the controller's channel.
fn script(robot: &str) -> String {
    format!(
        "wait connected {robot} 120s\nexpect route {robot} none\nwaypoint {robot} 0.6,0.4\n\
         send {robot}\nroute {robot} wp/gcs\nwait route {robot} wp/gcs 60s\n\
         wait arrived {robot} 240s\nexpect near {robot} 0.6,0.4 0.2\nlog arrived\n\
         route {robot} ext/x\nwait route {robot} ext/x 60s\nlog driving\nsleep 600s\n"
    )
}

/// What the station and the agent said, for a failure message.
fn story(arch: Arch, what: &str, station: &Station, log: &Path) -> String {
    format!(
        "{}: {what}\nstation: {:#?}\n{}\nagent log:\n{}",
        arch.debian,
        station.tail(),
        station.stderr_tail(),
        std::fs::read_to_string(log).unwrap_or_default()
    )
}

/// The first sample of `robot` since `since` (µs) that is `want`, waited
/// for; panics with `story` if none comes.
fn await_sample(
    ctl: &Controller,
    robot: &str,
    since: u64,
    want: impl Fn(&Sample) -> bool,
    story: impl FnOnce() -> String,
) -> Sample {
    poll(Duration::from_secs(60), || ctl.first(robot, since, &want))
        .unwrap_or_else(|| panic!("{}", story()))
}

/// The agent under qemu with the Pi config, simulated, registering with
/// the station at `port`, its log in `log`; its process id.
fn start_agent(arch: Arch, robot: &str, port: u16, log: &Path) -> (Killed, u32) {
    let agent = emulated(arch, "mech-agent")
        .expect("checked")
        .arg("--config")
        .arg(pi_config())
        .args(["--sim", "--name", robot, "--router"])
        .arg(format!("127.0.0.1:{port}"))
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(std::fs::File::create(log).expect("agent log"))
        .spawn()
        .expect("qemu starts");
    let pid = agent.id();
    (Killed(Some(agent)), pid)
}

fn drive_against_the_x86_station(arch: Arch) {
    let robot = format!("pi_{}", arch.debian);
    let dir = tempfile::tempdir().expect("temp dir");
    let port = station::free_port();
    let config = station::config(dir.path(), port, "");
    let mut station = Station::start(&config, &script(&robot), dir.path());
    let log = dir.path().join("agent.log");
    let (_agent, pid) = start_agent(arch, &robot, port, &log);
    let started = Instant::now();
    let router: SocketAddr = ([127, 0, 0, 1], port).into();
    let ctl = Controller::start(router, &[&robot], "ext/x", 0.15);
    station.wait_log("arrived", Duration::from_secs(420));
    report(&format!(
        "{}: {robot} registered routed to none, was routed to wp/gcs and \
         arrived at 0.6,0.4 (within 0.2 m) {:.0} s after it started",
        arch.debian,
        started.elapsed().as_secs_f64()
    ));
    let driving = station.wait_log("driving", Duration::from_secs(90));
    ctl.publish(true);
    let tell = |what: &str| story(arch, what, &station, &log);
    await_sample(
        &ctl,
        &robot,
        driving.at_us,
        |s| s.moving,
        || tell("never drove on the controller's channel"),
    );
    let engaged = ctl.estop(true);
    let stopped = await_sample(
        &ctl,
        &robot,
        engaged,
        |s| s.failsafe == FailsafeState::EStopped && !s.moving,
        || tell("did not stop on the e-stop"),
    );
    // Commanded all along, it stays still while the e-stop holds.
    std::thread::sleep(Duration::from_secs(2));
    let released = ctl.estop(false);
    let held: Vec<Sample> = ctl
        .samples()
        .into_iter()
        .filter(|s| s.robot == robot && s.stamp_us >= stopped.stamp_us && s.stamp_us < released)
        .collect();
    assert!(
        held.len() >= 5 && held.iter().all(|s| !s.moving),
        "{}",
        tell(&format!("moved under the e-stop: {held:?}"))
    );
    await_sample(
        &ctl,
        &robot,
        released,
        |s| s.moving,
        || tell("did not drive again once released"),
    );
    report(&format!(
        "{}: drove on ext/x, stopped on the e-stop ({} samples still while \
         commanded), drove again once released",
        arch.debian,
        held.len()
    ));
    let rss = peak_rss_mib(pid);
    station.kill();
    let stopped = fails_safe_without_the_station(port)
        .unwrap_or_else(|why| panic!("{}", story(arch, &why, &station, &log)));
    drop(ctl);
    report(&format!(
        "{}: the station went away; the agent stopped itself ({stopped:?}), \
         actuators at zero, and looked for a station again; peak RSS under \
         qemu (emulator included) {}",
        arch.debian,
        rss.map_or_else(|| "unknown".into(), |m| format!("{m:.1} MiB"))
    ));
}

/// The station at `port` has gone away while the robot drove. What the
/// agent sends to the station's address must show it stopped itself
/// (telemetry of a failsafe, its actuators at zero), then looking for a
/// station again (Hello: it no longer counts itself registered). The
/// failsafe it reported, or what it did instead.
fn fails_safe_without_the_station(port: u16) -> Result<FailsafeState, String> {
    let listener = poll(Duration::from_secs(10), || {
        UdpSocket::bind(("127.0.0.1", port)).ok()
    })
    .ok_or("the station's port stayed taken")?;
    listener
        .set_read_timeout(Some(Duration::from_millis(200)))
        .map_err(|e| e.to_string())?;
    let mut buf = vec![0u8; 65_536];
    let (mut stopped, mut searching) = (None, false);
    poll(Duration::from_secs(60), || {
        if let Ok((n, _)) = listener.recv_from(&mut buf)
            && let Ok(env) = mech_proto::decode(&buf[..n])
        {
            match env.body {
                Body::Telemetry(t)
                    if t.failsafe != FailsafeState::Ok && t.actuators.iter().all(|u| *u == 0.0) =>
                {
                    stopped.get_or_insert(t.failsafe);
                }
                Body::Hello(_) if stopped.is_some() => searching = true,
                _ => {}
            }
        }
        searching.then_some(())
    });
    match stopped {
        Some(failsafe) if searching => Ok(failsafe),
        _ => Err(format!(
            "after the station went away: stopped {stopped:?}, looking for it {searching}"
        )),
    }
}

/// The arm64 station with two simulated robots in its own process: a
/// mission to arrival, then an e-stop every robot acknowledges (a robot
/// acknowledges once its e-stop is latched, its outputs held at zero).
fn arm64_station_runs_a_mission(mut cmd: Command) {
    let dir = tempfile::tempdir().expect("temp dir");
    let port = station::free_port();
    let script = "wait connected robot_1 120s\nwaypoint robot_1 1.5,1.2\nsend robot_1\n\
                  route robot_1 wp/gcs\nwait route robot_1 wp/gcs 60s\n\
                  wait arrived robot_1 240s\nexpect near robot_1 1.5,1.2 0.2\n\
                  estop\nwait estop 60s\nlog done\n";
    let mut child = cmd
        .args(["--demo", "2", "--script", "-", "--udp"])
        .arg(format!("127.0.0.1:{port}"))
        .args(["--tcp", "127.0.0.1:0"])
        .env("XDG_STATE_HOME", dir.path())
        .env("XDG_RUNTIME_DIR", dir.path())
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("qemu starts");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(script.as_bytes())
        .expect("script written");
    let read = |pipe: Option<Box<dyn std::io::Read + Send>>| {
        std::thread::spawn(move || {
            let mut text = Vec::new();
            if let Some(mut p) = pipe {
                let _ = p.read_to_end(&mut text);
            }
            text
        })
    };
    let stdout = read(child.stdout.take().map(|p| Box::new(p) as _));
    let stderr = read(child.stderr.take().map(|p| Box::new(p) as _));
    // Its script's waits bound it; this bounds a station that hangs.
    let mut child = Killed(Some(child));
    let status = poll(Duration::from_secs(900), || {
        child.0.as_mut().and_then(|c| c.try_wait().ok().flatten())
    });
    child.kill();
    let out = std::process::Output {
        status: status.expect("the arm64 station ends within 15 min"),
        stdout: stdout.join().unwrap_or_default(),
        stderr: stderr.join().unwrap_or_default(),
    };
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success() && stdout.contains("\"done\""),
        "arm64 station: {}\n{stdout}\n{}",
        out.status,
        String::from_utf8_lossy(&out.stderr)
    );
    report("arm64 station: a simulated fleet's mission arrived, the e-stop acknowledged");
}
