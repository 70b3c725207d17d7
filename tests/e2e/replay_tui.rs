//! A recording replayed in the TUI: `mech-gcs --script --record` drives a
//! simulated robot to a waypoint, then `mech-gcs replay FILE` runs in tmux
//! (under strace when it is installed). The replayed robot must move on its
//! card from where the run started it to where the run left it, obey
//! pause, seek and speed typed at the prompt, refuse anything meant for a
//! robot, and open no network socket.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use crate::tmux::{Tmux, card_position};

const RUN: &str = "spawn 1\nwait connected robot_1 5s\nwaypoint robot_1 0.7,1.4\nsend robot_1\n\
                   route robot_1 wp/gcs\nwait arrived robot_1 30s\nsleep 1s\n";

/// Records RUN into `file`.
fn record(file: &Path, state: &Path) {
    let file = file.to_str().expect("utf-8 path");
    let args = [
        "--script",
        "-",
        "--udp",
        "127.0.0.1:0",
        "--tcp",
        "127.0.0.1:0",
        "--record",
        file,
    ];
    let out = mech_e2e::mech_gcs(&args, RUN, state);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Where `replay --info` says robot_1 ended.
fn last_position(file: &Path) -> (f64, f64) {
    let out = Command::new(mech_e2e::binary("mech-gcs"))
        .arg("replay")
        .arg(file)
        .arg("--info")
        .output()
        .expect("replay --info runs");
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .find(|l| l.contains("robot_1"))
        .unwrap_or_else(|| panic!("robot_1 in {text}"));
    let inner = line
        .split("last at (")
        .nth(1)
        .and_then(|r| r.split(')').next())
        .unwrap_or_else(|| panic!("a position in {line}"));
    let mut xy = inner.split(", ").map(|v| v.parse::<f64>().expect("number"));
    (xy.next().expect("x"), xy.next().expect("y"))
}

/// Types a command line. Escape goes alone: an Escape closely followed by
/// `:` reads as Alt-`:`.
fn prompt(tmux: &Tmux, line: &str) {
    tmux.keys(&["Escape"]);
    std::thread::sleep(Duration::from_millis(150));
    tmux.keys(&[":"]);
    tmux.literal(line);
    tmux.keys(&["Enter"]);
    std::thread::sleep(Duration::from_millis(150));
}

/// `mech-gcs replay FILE` in a tmux session, under strace (its network
/// calls written to the returned file) when strace is installed.
fn replay_in_tmux(file: &Path, state: &Path) -> (Tmux, Option<PathBuf>) {
    let trace = state.join("replay.strace");
    let strace = Command::new("strace").arg("-V").output().is_ok();
    let replay = format!(
        "{} replay {}",
        mech_e2e::binary("mech-gcs").display(),
        file.display()
    );
    let cmd = if strace {
        format!(
            "strace -f -qq -e trace=%network -o {} {replay}",
            trace.display()
        )
    } else {
        replay
    };
    let cmd = format!("XDG_STATE_HOME={} {cmd}", state.display());
    let tmux = Tmux {
        socket: format!("mech-e2e-replay-{}", std::process::id()),
        session: "replay".into(),
        state: state.to_path_buf(),
    };
    let out = tmux.run(&[
        "new-session",
        "-d",
        "-s",
        "replay",
        "-x",
        "160",
        "-y",
        "48",
        &cmd,
    ]);
    assert!(out.status.success(), "tmux new-session: {out:?}");
    (tmux, strace.then_some(trace))
}

#[test]
fn a_replay_in_the_tui_moves_the_robot_as_it_ran_and_sends_nothing() {
    if Command::new("tmux").arg("-V").output().is_err() {
        println!("skipped: tmux is not installed");
        return;
    }
    let state = std::env::temp_dir().join(format!("mech-e2e-replay-tui-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&state);
    std::fs::create_dir_all(&state).expect("temp dir");
    let file = state.join("run.mcap");
    record(&file, &state);
    let (end_x, _) = last_position(&file);

    let (tmux, trace) = replay_in_tmux(&file, &state);

    // From the start at a tenth of the speed: robot_1 where the run
    // spawned it, as soon as it registered.
    let wait = Duration::from_secs(30);
    tmux.wait_for("the replay", wait, |s| s.contains("replay "));
    let x0 = registered_at(&tmux);
    // The map fitted the robot where it first reported: zoom out so its
    // whole run stays in view.
    tmux.keys(&["Escape"]);
    for _ in 0..4 {
        tmux.keys(&["-"]);
    }
    std::thread::sleep(Duration::from_millis(300));
    let start = tmux.screen();
    let on_map_at_start = map_label(&start).expect("robot_1 labelled on the map");
    assert!(
        x0 - end_x > 0.5,
        "the run drove robot_1 in -x, from {x0} to {end_x}"
    );

    // Refused: a command for a robot.
    prompt(&tmux, "route robot_1 joy/0");
    tmux.wait_for("the refusal", wait, |s| {
        s.contains("sends nothing to robots")
    });

    // Played at 4x to the end: robot_1 ends where the run left it.
    prompt(&tmux, "speed 4");
    prompt(&tmux, "play");
    tmux.wait_for("robot_1 moving", wait, |s| {
        card_position(s, "robot_1").is_some_and(|(x, _)| x < x0 - 0.1)
    });
    let end = tmux.wait_for("the end of the recording", Duration::from_secs(60), |s| {
        s.contains("paused")
            && card_position(s, "robot_1").is_some_and(|(x, _)| (x - end_x).abs() < 0.02)
    });
    assert!(end.contains("x4"), "{end}");
    // On the map too: the run drove robot_1 in -x, so its label moved left.
    let on_map_at_end = map_label(&end).expect("robot_1 labelled on the map");
    assert!(
        on_map_at_end.1 + 2 < on_map_at_start.1,
        "robot_1's map label from {on_map_at_start:?} to {on_map_at_end:?}\n{start}\n{end}"
    );

    // Seeking back shows the start again.
    let again = registered_at(&tmux);
    assert!((again - x0).abs() < 0.05, "{again} vs {x0}");

    tmux.keys(&["Escape", "q"]);
    if let Some(trace) = trace {
        let calls = wait_for_file(&trace);
        let inet: Vec<&str> = calls.lines().filter(|l| l.contains("AF_INET")).collect();
        assert!(inet.is_empty(), "the replay used the network: {inet:#?}");
    }
}

/// Plays from the start (the recording began before the robot registered)
/// at 0.1x until robot_1's card shows its first position, pauses, and
/// reads its x.
fn registered_at(tmux: &Tmux) -> f64 {
    prompt(tmux, "pause");
    prompt(tmux, "seek 0");
    tmux.wait_for("the start, before robot_1", Duration::from_secs(30), |s| {
        s.contains("replay 0.0/") && s.contains("paused") && !s.contains("robot_1 #")
    });
    prompt(tmux, "speed 0.1");
    prompt(tmux, "play");
    // Its first telemetry (before it, the card's pose is 0, 0).
    let reported =
        |s: &str| card_position(s, "robot_1").is_some_and(|(x, y)| x.abs() + y.abs() > 0.01);
    tmux.wait_for("robot_1 reporting", Duration::from_secs(30), reported);
    prompt(tmux, "pause");
    let screen = tmux.wait_for("paused", Duration::from_secs(30), |s| {
        s.contains("paused") && reported(s)
    });
    card_position(&screen, "robot_1")
        .expect("robot_1 on its card")
        .0
}

/// Row and column (in characters) of robot_1's label on the map: the
/// middle panel at 160 columns (the cards take the first 40, the waypoints
/// and routes the last 40).
fn map_label(screen: &str) -> Option<(usize, usize)> {
    let map_rows = screen
        .lines()
        .take_while(|l| !l.contains("┌ Events"))
        .count();
    screen
        .lines()
        .take(map_rows)
        .enumerate()
        .find_map(|(row, line)| {
            let chars: Vec<char> = line.chars().collect();
            let text: String = chars.iter().skip(40).take(80).collect();
            text.find("robot_1")
                .filter(|&i| !text[i + 7..].starts_with(|c: char| c.is_ascii_digit()))
                .map(|i| (row, 40 + text[..i].chars().count()))
        })
}

/// The trace, once strace has finished writing it.
fn wait_for_file(path: &Path) -> String {
    let until = std::time::Instant::now() + Duration::from_secs(10);
    let mut last = String::new();
    while std::time::Instant::now() < until {
        std::thread::sleep(Duration::from_millis(300));
        let now = std::fs::read_to_string(path).unwrap_or_default();
        if !now.is_empty() && now == last {
            return now;
        }
        last = now;
    }
    last
}
