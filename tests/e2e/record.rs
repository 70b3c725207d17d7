//! Recording and replay end to end: `mech-gcs --script --record` with
//! simulated agents, the file read by Python's `mcap` package (an
//! independent reader) and every message of every channel validated by
//! Python's `jsonschema` against the schema the file embeds, then
//! `mech-gcs replay --script`, which must print the lines the run printed,
//! in the same order, without sending anything anywhere.

use std::net::UdpSocket;
use std::path::Path;
use std::process::{Command, Output, Stdio};

use serde_json::Value;

const RUN: &str = r#"
spawn 2
wait connected robot_1 5s
wait connected robot_2 5s
waypoint robot_1 0.8,0.6
send robot_1
route robot_1 wp/gcs
wait arrived robot_1 30s
route robot_2 cmd/gcs
mode robot_2 twist
drive robot_2 0.2 0 0
mode robot_1 twist
drive robot_1 0.2 0 0
status
record
sleep 1500ms
estop
wait estop 3s
release
wait estop 3s
"#;

fn mech_gcs(args: &[&str], stdin: &str, state: &Path) -> Output {
    mech_e2e::mech_gcs(args, stdin, state)
}

fn json_lines(out: &Output) -> Vec<Value> {
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{e}: {l}")))
        .collect()
}

fn of_type<'a>(lines: &'a [Value], t: &str) -> Vec<&'a Value> {
    lines.iter().filter(|l| l["type"] == t).collect()
}

/// A fresh directory for one test's files, removed when the handle drops
/// (a failed test's included).
fn scratch(name: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("mech-e2e-{name}-"))
        .tempdir()
        .expect("scratch dir")
}

/// What Python's `mcap` package reads in `file`, or `None` if it is not
/// installed (`scripts/deps.sh` installs it).
fn python_reads(file: &Path) -> Option<Value> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/check_recording.py");
    let out = Command::new("python3")
        .arg(script)
        .arg(file)
        .output()
        .ok()?;
    let stderr = String::from_utf8_lossy(&out.stderr);
    if stderr.contains("No module named 'mcap'") {
        return None;
    }
    assert!(out.status.success(), "python reader: {stderr}");
    Some(serde_json::from_slice(&out.stdout).expect("one JSON object"))
}

#[test]
fn a_recorded_script_reads_in_python_and_replays_as_it_ran() {
    let scratch = scratch("record");
    let dir = scratch.path().to_path_buf();
    let file = dir.join("run.mcap");
    let args = [
        "--script",
        "-",
        "--udp",
        "127.0.0.1:0",
        "--tcp",
        "127.0.0.1:0",
        "--record",
        file.to_str().expect("utf-8 path"),
    ];
    let out = mech_gcs(&args, RUN, &dir);
    let run = json_lines(&out);
    assert_eq!(
        out.status.code(),
        Some(0),
        "{run:#?}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let summary = run.last().expect("a summary");
    assert_eq!(summary["recording"]["dropped"], 0, "{summary}");
    let record_result = of_type(&run, "result")
        .into_iter()
        .find(|r| r["command"] == "record")
        .expect("the record verb ran");
    assert!(
        record_result["summary"]
            .as_str()
            .is_some_and(|s| s.starts_with("recording ")),
        "{record_result}"
    );
    match python_reads(&file) {
        Some(read) => check_python_view(&read),
        None => println!("skipped the Python reader: python3 -m pip install mcap"),
    }
    every_message_matches_its_schema(&file);
    replay_prints_the_run(&file, &run, &dir);
}

/// Every message of every JSON channel validates against the JSON Schema
/// the file embeds for it (Python's `jsonschema`, `scripts/deps.sh`
/// installs it; missing only outside CI), link quality and the mech.*
/// channels included.
fn every_message_matches_its_schema(file: &Path) {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/validate_recording.py");
    let out = Command::new("python3")
        .arg(script)
        .arg(file)
        .output()
        .expect("python3 runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    if stderr.contains("No module named") && std::env::var_os("CI").is_none() {
        println!("skipped the schema validation: {stderr} (bash scripts/deps.sh)");
        return;
    }
    assert!(out.status.success(), "validator: {stderr}");
    let read: Value = serde_json::from_slice(&out.stdout).expect("one JSON object");
    assert_eq!(read["errors"], serde_json::json!([]), "{read:#}");
    let validated = &read["validated"];
    for topic in [
        "/mech/events",
        "/mech/snapshot",
        "/mech/decisions",
        "/mech/operator",
        "/mech/log",
        "/mech/scene",
        "/mech/clusters",
        "/robots/robot_1/telemetry",
        "/robots/robot_1/pose",
    ] {
        assert!(
            validated[topic].as_u64().unwrap_or(0) > 0,
            "{topic}: {read}"
        );
    }
    assert_eq!(
        read["unchecked"]
            .as_object()
            .map(|m| m.keys().collect::<Vec<_>>()),
        Some(vec![&"/mech/raw".to_string()]),
        "only the raw copy has no schema: {read}"
    );
    for event in [
        "registered",
        "link_quality",
        "route_acked",
        "mission_sent",
        "estop",
    ] {
        assert!(
            read["events"][event].as_u64().unwrap_or(0) > 0,
            "{event}: {read}"
        );
    }
}

/// Schemas Foxglove and Lichtblick draw, JSON everywhere but the raw copy,
/// and every message the router received recorded once.
fn check_python_view(read: &Value) {
    assert_eq!(read["profile"], "mech");
    let topics = &read["topics"];
    let schema = |t: &str| topics[t]["schema"].as_str().unwrap_or("").to_string();
    assert_eq!(schema("/robots/robot_1/pose"), "foxglove.PoseInFrame");
    assert_eq!(schema("/mech/scene"), "foxglove.SceneUpdate");
    assert_eq!(schema("/mech/log"), "foxglove.Log");
    assert_eq!(schema("/mech/events"), "mech.Event");
    assert_eq!(schema("/robots/robot_2/telemetry"), "mech.Telemetry");
    assert_eq!(schema("/mech/decisions"), "mech.Decision");
    assert_eq!(schema("/mech/operator"), "mech.OperatorCommand");
    let Value::Object(map) = topics else {
        panic!("topics: {topics}")
    };
    for (topic, t) in map {
        let expected = if topic == "/mech/raw" {
            "x-mech-msgpack"
        } else {
            "json"
        };
        assert_eq!(t["encoding"], expected, "{topic}");
        if expected == "json" {
            assert_eq!(t["schema_encoding"], "jsonschema", "{topic}");
        }
    }
    let end = &read["metadata"]["mech.end"];
    let counted = topics["/mech/raw"]["count"].as_u64().expect("raw count");
    assert_eq!(end["router_received"], counted.to_string(), "{end}");
    assert_eq!(end["dropped"], "0");
    let total: u64 = map.values().filter_map(|t| t["count"].as_u64()).sum();
    assert_eq!(read["message_count"], total);
    let pose = &topics["/robots/robot_1/pose"]["first"];
    assert_eq!(pose["frame_id"], "world", "{pose}");
    assert!(pose["pose"]["orientation"]["w"].is_number(), "{pose}");
    assert!(pose["timestamp"]["sec"].as_u64().unwrap_or(0) > 1_600_000_000);
    let scene = &topics["/mech/scene"]["first"];
    assert!(scene["entities"].as_array().is_some(), "{scene}");
    // 19 commands and the script's end.
    assert_eq!(topics["/mech/operator"]["count"], 20);
}

/// `replay --script` prints the lines the run printed, in the same order:
/// the router's binding, every event and every command's result with its
/// details (`status`), up to the script's end (not the goodbyes of the
/// robots as the station stops after it). Only two things may differ
/// (`docs/recording.md`): a result's `t` (the run stamps it when it prints
/// it, the recording when it records it: microseconds apart), with an
/// event that close to the result on its other side, and the summary (the
/// replay's says what it read). No datagram reaches the
/// robots' or the router's recorded addresses while it runs.
fn replay_prints_the_run(file: &Path, run: &[Value], dir: &Path) {
    let listeners = recorded_addresses(run);
    let file = file.to_str().expect("utf-8 path");
    let out = mech_gcs(&["replay", file, "--script"], "", dir);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let replayed = json_lines(&out);
    let (ran_summary, ran) = run.split_last().expect("the run's lines");
    let (summary, again) = replayed.split_last().expect("the replay's lines");
    assert_eq!(ran_summary["type"], "summary");
    assert_eq!(summary["type"], "summary");
    assert_eq!(summary["ok"], true, "{summary}");
    assert!(ran.len() > 20, "{ran:#?}");
    same_lines_in_their_order(ran, again);
    let status = ran
        .iter()
        .find(|l| l["command"] == "status")
        .expect("status ran");
    assert!(
        status["details"].as_array().is_some_and(|d| d.len() == 2),
        "{status}"
    );
    for (what, sock) in &listeners {
        let mut buf = [0u8; 2048];
        assert!(
            sock.recv_from(&mut buf).is_err(),
            "the replay sent a datagram to the recorded {what}"
        );
    }
    if let Some(calls) = network_calls_of_replay(file, dir) {
        assert!(calls.is_empty(), "the replay touched the network: {calls}");
    }
}

/// The run's lines (`ran`, without the summary) and the replay's
/// (`again`) are the same: each kind in its order, a result's `t` and its
/// place among events close to it aside (see [`replay_prints_the_run`]).
fn same_lines_in_their_order(ran: &[Value], again: &[Value]) {
    let without_result_t = |lines: &[Value]| -> Vec<Value> {
        lines
            .iter()
            .map(|l| {
                let mut l = l.clone();
                if l["type"] == "result" {
                    if let Some(m) = l.as_object_mut() {
                        m.remove("t");
                    }
                }
                l
            })
            .collect()
    };
    let (a, b) = (without_result_t(ran), without_result_t(again));
    assert_eq!(
        a.len(),
        b.len(),
        "the replay printed {} lines, the run {}",
        b.len(),
        a.len()
    );
    // Events and results come from two tasks, the event printer and the
    // script runner: each kind comes in its order, and the two interleave
    // as they ran, except that an event close to a result may come on its
    // other side. Close is RESULT_STAMP: the run stamps a result when it
    // prints it, the recording when it records it, microseconds apart on a
    // quiet machine; with a CPU hog per core the runner was preempted in
    // between (an event came before a result in the run, after it in the
    // recording), so the bound is a second.
    const RESULT_STAMP: f64 = 1.0;
    let of_kind = |lines: &[Value], result: bool| -> Vec<Value> {
        lines
            .iter()
            .filter(|l| (l["type"] == "result") == result)
            .cloned()
            .collect()
    };
    let (run_events, replay_events) = (of_kind(&a, false), of_kind(&b, false));
    for (i, (x, y)) in run_events.iter().zip(&replay_events).enumerate() {
        assert_eq!(x, y, "event {i} differs (run, replay)");
    }
    let (run_results, replay_results) = (of_kind(ran, true), of_kind(again, true));
    for (i, (x, y)) in of_kind(&a, true).iter().zip(&of_kind(&b, true)).enumerate() {
        assert_eq!(x, y, "result {i} differs (run, replay)");
    }
    for (x, y) in run_results.iter().zip(&replay_results) {
        let (t0, t1) = (
            x["t"].as_f64().unwrap_or(-1.0),
            y["t"].as_f64().unwrap_or(1e9),
        );
        assert!(
            (t0 - t1).abs() < RESULT_STAMP,
            "result times {t0} {t1}: {x}"
        );
    }
    let (run_before, replay_before) = (events_before(&a), events_before(&b));
    for (k, (&r, &p)) in run_before.iter().zip(&replay_before).enumerate() {
        let t = replay_results[k]["t"].as_f64().unwrap_or(f64::NAN);
        for e in &replay_events[r.min(p)..r.max(p)] {
            let te = e["t"].as_f64().unwrap_or(f64::NAN);
            assert!(
                (te - t).abs() < RESULT_STAMP,
                "event {e} on the other side of result {} (t {t})",
                replay_results[k]
            );
        }
    }
}

/// How many events came before each result of `lines`.
fn events_before(lines: &[Value]) -> Vec<usize> {
    let mut events = 0;
    let mut before = Vec::new();
    for l in lines {
        if l["type"] == "result" {
            before.push(events);
        } else {
            events += 1;
        }
    }
    before
}

/// Sockets bound on the router's and robots' recorded UDP addresses (those
/// still free), non-blocking.
fn recorded_addresses(run: &[Value]) -> Vec<(String, UdpSocket)> {
    let mut addrs = Vec::new();
    for e in of_type(run, "event") {
        let addr = match e["event"].as_str() {
            Some("listening") => e["udp"].as_str(),
            Some("registered") => e["addr"].as_str(),
            _ => None,
        };
        if let Some(a) = addr {
            addrs.push((e["event"].to_string(), a.to_string()));
        }
    }
    assert!(addrs.len() >= 3, "router and two robots: {addrs:?}");
    addrs
        .into_iter()
        .filter_map(|(what, a)| {
            let s = UdpSocket::bind(&a).ok()?;
            s.set_nonblocking(true).ok()?;
            Some((format!("{what} address {a}"), s))
        })
        .collect()
}

/// The network system calls `mech-gcs replay --script` makes, traced with
/// strace (`None` when strace is not installed).
fn network_calls_of_replay(file: &str, dir: &Path) -> Option<String> {
    let trace = dir.join("replay.strace");
    let status = Command::new("strace")
        .args(["-f", "-qq", "-e", "trace=%network", "-o"])
        .arg(&trace)
        .arg(mech_e2e::binary("mech-gcs"))
        .args(["replay", file, "--script"])
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .ok()?;
    if !status.success() {
        println!("strace could not trace the replay here: skipped");
        return None;
    }
    let calls = std::fs::read_to_string(trace).ok()?;
    Some(calls.trim().to_string())
}

/// Where an MCAP file's data section ends (its 13-byte data end record
/// begins): the footer, the record before the closing 8-byte magic, holds
/// where the summary starts (opcode, length, summary start, summary offset
/// start, CRC: 29 bytes). The summary after the data repeats every schema,
/// so a cut at half the file may well leave the data whole.
fn data_section_end(bytes: &[u8]) -> usize {
    let footer = bytes.len() - 8 - 29;
    assert_eq!(bytes[footer], 0x02, "an MCAP footer");
    let start: [u8; 8] = bytes[footer + 9..footer + 17].try_into().expect("8 bytes");
    u64::from_le_bytes(start) as usize - 13
}

#[test]
fn a_damaged_recording_replays_what_it_can_and_says_what_is_wrong() {
    let scratch = scratch("record-damaged");
    let dir = scratch.path().to_path_buf();
    let file = dir.join("run.mcap");
    let script = "spawn 1\nwait connected robot_1 5s\nsleep 2500ms\nlog done\n";
    let args = [
        "--script",
        "-",
        "--udp",
        "127.0.0.1:0",
        "--tcp",
        "127.0.0.1:0",
        "--record",
        file.to_str().expect("utf-8 path"),
    ];
    let out = mech_gcs(&args, script, &dir);
    assert_eq!(out.status.code(), Some(0));
    let bytes = std::fs::read(&file).expect("the recording");
    let cut = dir.join("cut.mcap");
    // Cut into the data's last record: everything before it replays.
    std::fs::write(&cut, &bytes[..data_section_end(&bytes) - 1]).expect("cut written");
    let out = mech_gcs(
        &["replay", cut.to_str().expect("utf-8"), "--script"],
        "",
        &dir,
    );
    assert_eq!(out.status.code(), Some(1), "damaged: exit code 1");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("truncated or corrupt"), "{stderr}");
    let lines = json_lines(&out);
    assert!(
        lines.iter().any(|l| l["event"] == "registered"),
        "{lines:#?}"
    );
    assert_eq!(lines.last().expect("summary")["ok"], false);
    let junk = dir.join("junk.mcap");
    std::fs::write(&junk, b"hello").expect("junk written");
    let out = mech_gcs(&["replay", junk.to_str().expect("utf-8")], "", &dir);
    assert_eq!(out.status.code(), Some(2));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("not a MECH recording"), "{stderr}");
}
