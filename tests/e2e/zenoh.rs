//! Two `mech-zenoh` stations end to end, each a real process with its own
//! simulated fleet, meeting over Zenoh on loopback: each sees the other's
//! robots; site-b routes a robot of site-a by asking it; the documented
//! Python reader (`docs/examples/zenoh_telemetry.py`, no MECH code) reads
//! site-a's robots off the network; site-b freezes (SIGSTOP: no goodbye,
//! its connection stays open but silent), and site-a shows its robots lost
//! when the Zenoh lease runs out. Also: `mech-zenoh serve` bridges while an
//! operator attaches with `mech-gcs --attach`; `mech-zenoh` on a terminal
//! shows its station in `mech-gcs`'s TUI, attached on a socket of its own
//! that is gone when the operator quits; and a station name that cannot be
//! a key chunk is refused with the reason.

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

/// A child process, killed when the test ends however it ends.
struct Running(Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// A Zenoh endpoint on loopback with a port nobody holds now.
fn free_endpoint() -> String {
    let l = std::net::TcpListener::bind("127.0.0.1:0").expect("a free port");
    format!("tcp/127.0.0.1:{}", l.local_addr().expect("bound").port())
}

/// Starts `mech-zenoh` as `station` with two simulated robots, running
/// `script`; its stdout lines arrive on the returned channel.
fn start(
    station: &str,
    args: &[&str],
    script: &str,
    logs: &Path,
) -> (Running, mpsc::Receiver<String>) {
    let mut child = Command::new(mech_e2e::binary("mech-zenoh"))
        .args(["--station", station, "--demo", "2", "--script", "-"])
        .args(["--udp", "127.0.0.1:0", "--tcp", "127.0.0.1:0"])
        .args(args)
        .env("XDG_STATE_HOME", logs)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("mech-zenoh starts (scripts/test.sh builds it)");
    let mut stdin = child.stdin.take().expect("stdin");
    stdin.write_all(script.as_bytes()).expect("script written");
    drop(stdin);
    let stdout = child.stdout.take().expect("stdout");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    (Running(child), rx)
}

/// Reads lines until one contains every one of `wanted`; all lines read.
fn read_until(rx: &mpsc::Receiver<String>, wanted: &[&str], what: &str) -> Vec<String> {
    let mut seen = Vec::new();
    loop {
        match rx.recv_timeout(Duration::from_secs(60)) {
            Ok(line) => {
                let done = wanted.iter().all(|w| line.contains(w));
                seen.push(line);
                if done {
                    return seen;
                }
            }
            Err(e) => panic!("{what}: {e} after {seen:#?}"),
        }
    }
}

const SITE_A: &str = "
wait robots 2 20s
wait connected robot_1@site-b 30s
wait connected robot_2@site-b 30s
status
wait route robot_1 ext/b 30s
wait lost robot_2@site-b 30s
expect link robot_1@site-b lost
expect route robot_1 ext/b
";

const SITE_B: &str = "
wait robots 2 20s
wait connected robot_1@site-a 30s
route robot_1@site-a ext/b
wait route robot_1@site-a ext/b 30s
sleep 120s
";

#[test]
fn two_stations_share_their_fleets_and_a_python_program_reads_them() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("site-a.toml");
    std::fs::write(&config, "[zenoh]\nroute_requests = \"unsigned\"\n").unwrap();
    let (a_end, b_end) = (free_endpoint(), free_endpoint());
    let a_args = ["--config", config.to_str().unwrap(), "--listen", &a_end];
    let (mut a, a_out) = start("site-a", &a_args, SITE_A, dir.path());
    let b_args = ["--listen", &b_end, "--connect", &a_end];
    let (b, b_out) = start("site-b", &b_args, SITE_B, dir.path());

    let b_lines = read_until(&b_out, &["\"line\":5,", "\"ok\":true"], "site-b's route");
    let routed = b_lines
        .iter()
        .find(|l| l.contains("\"line\":4,"))
        .expect("the route result");
    assert!(
        routed.contains("\"ok\":true") && routed.contains("of station site-a routed to ext/b"),
        "{routed}"
    );

    let reader = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/examples/zenoh_telemetry.py");
    let out = Command::new("python3")
        .arg(reader)
        .args([a_end.as_str(), "site-a", "10"])
        .output()
        .expect("python3 runs (scripts/deps.sh installs eclipse-zenoh)");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(text.contains("site-a/robot_1 is a "), "{text}");
    assert!(text.contains("mech/site-a/robot_2 appeared"), "{text}");
    let samples = text.lines().filter(|l| l.contains(" x=")).count();
    assert!(samples >= 10, "{text}");
    assert!(
        text.contains("site-a/robot_1 x=") && text.contains("channel=ext/b"),
        "{text}"
    );

    let frozen = Instant::now();
    let stop = Command::new("kill")
        .args(["-STOP", &b.0.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(stop.success());
    let a_lines = read_until(&a_out, &["\"line\":7,"], "site-b lost at site-a");
    let took = frozen.elapsed();
    println!("site-b frozen -> its robots lost at site-a after {took:?} (lease 1 s)");
    // Generous for a loaded 2-core machine; the figure is printed above.
    assert!(took < Duration::from_secs(5), "{took:?}");
    let mut a_lines = a_lines;
    a_lines.extend(read_until(&a_out, &["\"type\":\"zenoh\""], "site-a's end"));
    drop(b);
    let status = a.0.wait().expect("site-a exits");
    let all = a_lines.join("\n");
    assert!(status.success(), "{all}");
    let listing = a_lines
        .iter()
        .find(|l| l.contains("\"command\":\"status\""))
        .expect("the status result");
    assert!(
        listing.contains("robot_2@site-b") && listing.contains("remote site-b (read-only)"),
        "{listing}"
    );
    let zenoh = a_lines.last().unwrap();
    assert!(zenoh.contains("\"route_requests_done\":1"), "{zenoh}");
}

#[test]
fn the_zenoh_page_shows_the_tested_reader() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let file = std::fs::read_to_string(root.join("docs/examples/zenoh_telemetry.py")).unwrap();
    let block = mech_e2e::doc_block("docs/zenoh.md", "## Reading MECH from Python", "python");
    assert_eq!(block, file, "docs/zenoh.md and zenoh_telemetry.py differ");
}

#[test]
fn a_station_name_that_is_not_a_key_chunk_is_refused_with_why() {
    let out = Command::new(mech_e2e::binary("mech-zenoh"))
        .args([
            "--station",
            "site*a",
            "--script",
            "-",
            "--udp",
            "127.0.0.1:0",
        ])
        .stdin(Stdio::null())
        .output()
        .expect("mech-zenoh runs");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("\"site*a\" cannot be a Zenoh key chunk: it contains '*'"),
        "{err}"
    );
}

const SERVED_PEER: &str = "
wait connected robot_1@site-s 30s
route robot_1@site-s ext/t
wait route robot_1@site-s ext/t 30s
sleep 120s
";

const ATTACHED: &str = "
wait route robot_1 ext/t 30s
wait connected robot_2@site-t 30s
status
";

/// Starts `mech-zenoh serve` and waits for its ready line.
fn serve(dir: &Path, socket: &Path, endpoint: &str) -> Running {
    let config = dir.join("site-s.toml");
    std::fs::write(&config, "[zenoh]\nroute_requests = \"unsigned\"\n").unwrap();
    let record = dir.join("site-s.mcap");
    let mut child = Command::new(mech_e2e::binary("mech-zenoh"))
        .args(["serve", "--station", "site-s", "--demo", "1"])
        .arg("--record")
        .arg(&record)
        .args(["--config", config.to_str().unwrap(), "--listen", endpoint])
        .args(["--udp", "127.0.0.1:0", "--tcp", "127.0.0.1:0"])
        .arg("--socket")
        .arg(socket)
        .env("XDG_STATE_HOME", dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("mech-zenoh serve starts");
    let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
    let ready = lines.next().expect("a ready line").expect("utf-8");
    assert!(ready.contains("mech-zenoh serving"), "{ready}");
    assert!(
        ready.contains(&format!("recording to {}", record.display())),
        "{ready}"
    );
    Running(child)
}

#[test]
fn a_served_station_bridges_while_operators_attach() {
    let dir = tempfile::tempdir().unwrap();
    let socket = dir.path().join("gcs.sock");
    let s_end = free_endpoint();
    let mut served = serve(dir.path(), &socket, &s_end);
    let t_args = ["--listen", &free_endpoint(), "--connect", &s_end];
    let (_t, t_out) = start("site-t", &t_args, SERVED_PEER, dir.path());
    let t_lines = read_until(&t_out, &["\"line\":4,", "\"ok\":true"], "site-t's route");
    assert!(
        t_lines
            .iter()
            .any(|l| l.contains("\"line\":3,") && l.contains("of station site-s routed to ext/t")),
        "{t_lines:#?}"
    );

    let attach = [
        "--attach".as_ref(),
        socket.as_os_str(),
        "--script".as_ref(),
        "-".as_ref(),
    ];
    let out = mech_e2e::mech_gcs(&attach, ATTACHED, dir.path());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        text.contains("robot_2@site-t") && text.contains("remote site-t (read-only)"),
        "{text}"
    );

    let term = Command::new("kill")
        .args(["-TERM", &served.0.id().to_string()])
        .status()
        .expect("kill runs");
    assert!(term.success());
    let status = served.0.wait().expect("serve exits");
    assert!(status.success(), "{status:?}");
}

/// `mech-zenoh` with no `serve` or `--script` on a terminal (tmux): its
/// station, bridge and simulated robots run in it, and the TUI is
/// `mech-gcs` attached to a control socket private to it; quitting the TUI
/// stops the station and removes the socket.
#[test]
fn on_a_terminal_the_station_is_shown_in_mech_gcs_attached() {
    use crate::tmux::Tmux;
    if Command::new("tmux").arg("-V").output().is_err() {
        println!("skipped: tmux is not installed");
        return;
    }
    let state = std::env::temp_dir().join(format!("mech-e2e-zenoh-tui-{}", std::process::id()));
    std::fs::create_dir_all(&state).expect("temp dir");
    let tmux = Tmux {
        socket: format!("mech-e2e-zenoh-tui-{}", std::process::id()),
        session: "zenoh".into(),
        state: state.clone(),
    };
    let cmd = format!(
        "XDG_STATE_HOME={dir} XDG_RUNTIME_DIR={dir} {} --station site-t --listen {} --demo 2 \
         --no-mouse --udp 127.0.0.1:0 --tcp 127.0.0.1:0 2>{dir}/zenoh.err; \
         echo exited $? >{dir}/exit",
        mech_e2e::binary("mech-zenoh").display(),
        free_endpoint(),
        dir = state.display(),
    );
    let out = tmux.run(&[
        "new-session",
        "-d",
        "-s",
        "zenoh",
        "-x",
        "160",
        "-y",
        "48",
        &cmd,
    ]);
    assert!(out.status.success(), "tmux new-session: {out:?}");
    let screen = tmux.wait_for("two robots, attached", Duration::from_secs(60), |s| {
        s.contains("Robots 2/2") && s.contains("2/2 ok") && s.contains("@mech-zenoh-")
    });
    assert!(screen.contains("robot_1"), "{screen}");
    let socket = std::fs::read_dir(state.join("mech"))
        .expect("the socket's directory")
        .flatten()
        .map(|e| e.path())
        .find(|p| p.to_string_lossy().ends_with(".sock"))
        .expect("a private control socket");
    use std::os::unix::fs::PermissionsExt;
    let mode = std::fs::metadata(&socket).unwrap().permissions().mode();
    assert_eq!(mode & 0o777, 0o600, "the owner's alone");
    tmux.keys(&["q"]);
    let deadline = Instant::now() + Duration::from_secs(30);
    let exit = loop {
        if let Ok(text) = std::fs::read_to_string(state.join("exit")) {
            break text;
        }
        let err = std::fs::read_to_string(state.join("zenoh.err")).unwrap_or_default();
        assert!(Instant::now() < deadline, "mech-zenoh did not stop: {err}");
        std::thread::sleep(Duration::from_millis(100));
    };
    assert_eq!(exit.trim(), "exited 0");
    assert!(!socket.exists(), "{} is left behind", socket.display());
}
