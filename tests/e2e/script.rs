//! `mech-gcs --script` end to end: the real binary, simulated agents over
//! real loopback sockets, JSON lines on stdout and the exit code.

use std::io::Write;
use std::process::{Command, Output, Stdio};

/// Runs `mech-gcs --script -` with `script` on stdin, on ephemeral ports,
/// logging into a fresh directory (removed when the returned handle drops,
/// a failed test's included). Returns the output and the log directory.
fn run_script(script: &str, extra: &[&str]) -> (Output, tempfile::TempDir) {
    let logs = tempfile::Builder::new()
        .prefix("mech-e2e-script-")
        .tempdir()
        .expect("a log directory");
    let mut args = vec![
        "--script",
        "-",
        "--udp",
        "127.0.0.1:0",
        "--tcp",
        "127.0.0.1:0",
    ];
    args.extend_from_slice(extra);
    (mech_e2e::mech_gcs(&args, script, logs.path()), logs)
}

fn lines(out: &Output) -> Vec<String> {
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(str::to_string)
        .collect()
}

/// The result line of script line `n`.
fn result_of(lines: &[String], n: usize) -> &str {
    let key = format!("\"line\":{n},");
    lines
        .iter()
        .find(|l| l.contains("\"type\":\"result\"") && l.contains(&key))
        .unwrap_or_else(|| panic!("no result for line {n} in {lines:#?}"))
}

const MISSION: &str = r#"
# Two simulated robots: a waypoint mission, a route switch, an e-stop.
spawn 2
wait connected robot_1 5s
wait connected robot_2 5s
cluster pair robot_1 robot_2
waypoint robot_1 1.0,1.0
send robot_1
route robot_1 wp/gcs
wait route robot_1 wp/gcs 3s
wait arrived robot_1 30s
expect near robot_1 1.0,1.0 0.25
route robot_2 cmd/gcs
mode robot_2 twist
drive robot_2 0.2 0 0
wait route pair wp/gcs 100ms
"#;

#[test]
fn a_mission_script_runs_headless_against_simulated_agents() {
    // The last line is meant to time out (robot_2 is on cmd/gcs): the script
    // must stop there with exit code 1 after everything before succeeded.
    let (out, logs) = run_script(MISSION, &[]);
    let lines = lines(&out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(1),
        "stdout: {lines:#?}\nstderr: {stderr}"
    );
    for n in [3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15] {
        assert!(
            result_of(&lines, n).contains("\"ok\":true"),
            "line {n}: {}",
            result_of(&lines, n)
        );
    }
    assert!(
        result_of(&lines, 12).contains("within"),
        "{}",
        result_of(&lines, 12)
    );
    assert!(
        result_of(&lines, 15).contains("forwarded"),
        "{}",
        result_of(&lines, 15)
    );
    let last = result_of(&lines, 16);
    assert!(
        last.contains("\"ok\":false")
            && last.contains("timed out")
            && last.contains("line 16, column 1"),
        "{last}"
    );
    assert!(
        lines
            .iter()
            .any(|l| l.contains("\"event\":\"registered\"") && l.contains("robot_2"))
    );
    assert!(
        lines
            .iter()
            .any(|l| l.contains("\"event\":\"mission_acked\"") && l.contains("\"accepted\":true"))
    );
    assert!(
        lines
            .iter()
            .any(|l| l.contains("\"event\":\"route_acked\"") && l.contains("wp/gcs"))
    );
    let summary = lines.last().expect("a summary line");
    assert!(
        summary.contains("\"type\":\"summary\"") && summary.contains("\"ok\":false"),
        "{summary}"
    );
    assert!(stderr.contains("script failed at line 16"), "{stderr}");
    // Every line is one JSON object.
    assert!(lines.iter().all(|l| l.starts_with('{') && l.ends_with('}')));
    // The rolling log file records registrations and route changes.
    let dir = logs.path().join("mech");
    let log: String = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("log dir {}: {e}", dir.display()))
        .filter_map(|e| std::fs::read_to_string(e.ok()?.path()).ok())
        .collect();
    assert!(
        log.contains("robot registered") && log.contains("route changed"),
        "{log}"
    );
    assert!(!log.contains('\u{1b}'), "no colour codes in log files");
}

#[test]
fn estop_and_release_with_demo_agents_exit_zero() {
    let script = "wait robots 3 5s\nestop\nwait estop 3s\nsleep 200ms\nexpect failsafe all estopped\nrelease\nwait estop 3s\nlog \"e-stop checked\"\n";
    let (out, _) = run_script(script, &["--demo", "3"]);
    let lines = lines(&out);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{lines:#?}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let acks = lines
        .iter()
        .filter(|l| l.contains("\"event\":\"estop_acked\"") && l.contains("\"engage\":true"))
        .count();
    assert_eq!(acks, 3, "every robot acknowledged the e-stop");
    let summary = lines.last().expect("a summary line");
    assert!(
        summary.contains("\"ok\":true") && summary.contains("\"commands\":8"),
        "{summary}"
    );
}

#[test]
fn a_bad_script_is_rejected_before_anything_runs() {
    let (out, _) = run_script(
        "spawn 1\nroute robot_1 joy/0\nwait connected robot_1 soon\n",
        &[],
    );
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("line 3, column 24"), "{stderr}");
    let lines = lines(&out);
    assert!(
        lines.iter().all(|l| !l.contains("\"type\":\"result\"")),
        "nothing ran: {lines:#?}"
    );
}

#[test]
fn a_demo_router_listens_on_loopback_only() {
    let state = tempfile::tempdir().expect("a state directory");
    let mut child = Command::new(mech_e2e::binary("mech-gcs"))
        .args(["--demo", "1", "--script", "-", "--tcp", "127.0.0.1:0"])
        .env("XDG_STATE_HOME", state.path())
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mech-gcs starts");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(b"wait robots 1 10s\n")
        .expect("script written");
    let out = child.wait_with_output().expect("mech-gcs finishes");
    let stderr = String::from_utf8_lossy(&out.stderr);
    if stderr.contains("in use") {
        eprintln!("skipped: the default port 7400 is taken on this machine ({stderr})");
        return;
    }
    let lines = lines(&out);
    let listening = lines
        .iter()
        .find(|l| l.contains("\"event\":\"listening\""))
        .unwrap_or_else(|| panic!("no listening event: {lines:#?} {stderr}"));
    assert!(
        listening.contains("\"udp\":\"127.0.0.1:7400\""),
        "demo binds loopback: {listening}"
    );
    assert!(out.status.success(), "{stderr}");
}
