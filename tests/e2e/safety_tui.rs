//! Fleet safety in the TUI end to end: `mech-gcs --demo 2` in a detached
//! tmux session. The demo's arena is on the map from the start; an arena
//! file with a keep-out and a slow zone, loaded with `arena load`, adds
//! them to the map; robot_2, driven at the wall from the command line, is
//! stopped by its safety layer: its card says what limits it and the
//! events show its notice.

use std::process::Command;
use std::time::{Duration, Instant};

use crate::tmux::{Tmux, card_position, card_status};

/// The demo rectangle with a keep-out above the robots and a slow zone in
/// a corner.
const ARENA: &str = r#"
boundary = [[0, 0], [3.9, 0], [3.9, 2.8], [0, 2.8]]
keep_out = [[[1.5, 2.0], [2.4, 2.0], [2.4, 2.6], [1.5, 2.6]]]
slow_zones = [{ polygon = [[0.2, 0.2], [1.0, 0.2], [1.0, 0.8], [0.2, 0.8]], max_speed = 0.1 }]
margin = 0.1
"#;

/// robot_2's safety notice in the events, when its layer begins to limit
/// it at the wall.
const NOTICE: &str = "robot_2: safety: limited so its stopping point stays inside the arena";

/// Braille cells with at least one dot: only the map draws them.
fn map_dots(screen: &str) -> usize {
    screen
        .chars()
        .filter(|c| ('\u{2801}'..='\u{28ff}').contains(c))
        .count()
}

#[test]
fn the_map_shows_the_arena_and_a_card_the_layer_stopping_a_robot_at_the_wall() {
    if Command::new("tmux").arg("-V").output().is_err() {
        println!("skipped: tmux is not installed");
        return;
    }
    let state = std::env::temp_dir().join(format!("mech-e2e-safety-{}", std::process::id()));
    std::fs::create_dir_all(&state).expect("temp dir");
    // An operator names a file in the station's missions directory
    // (docs/commands.md, *Files a command names*).
    let missions = state.join("mech").join("missions");
    std::fs::create_dir_all(&missions).expect("missions dir");
    std::fs::write(missions.join("arena.toml"), ARENA).expect("arena file");
    let tmux = Tmux {
        socket: format!("mech-e2e-safety-{}", std::process::id()),
        session: "gcs".into(),
        state: state.clone(),
    };
    let gcs = mech_e2e::binary("mech-gcs");
    let cmd = format!(
        "XDG_STATE_HOME={0} XDG_DATA_HOME={0} {1} --demo 2 --udp 127.0.0.1:0 --tcp 127.0.0.1:0",
        state.display(),
        gcs.display()
    );
    let out = tmux.run(&[
        "new-session",
        "-d",
        "-s",
        "gcs",
        "-x",
        "160",
        "-y",
        "48",
        &cmd,
    ]);
    assert!(out.status.success(), "tmux new-session: {out:?}");

    // The simulator's arena from the start: its boundary on the map, and
    // the robots' layers on (no SAFETY OFF anywhere).
    let screen = tmux.wait_for("two connected robots", Duration::from_secs(30), |s| {
        s.contains("robots 2 (2 ok")
            && card_position(s, "robot_2").is_some_and(|(x, y)| x.abs() + y.abs() > 0.05)
    });
    assert!(!screen.contains("SAFETY OFF"), "{screen}");
    let demo = map_dots(&screen);
    assert!(demo > 100, "the boundary is drawn:\n{screen}");

    // The arena file: a keep-out and a slow zone more on the map.
    tmux.keys(&[":"]);
    tmux.literal("arena load arena.toml");
    tmux.keys(&["Enter"]);
    tmux.wait_for("the arena loaded", Duration::from_secs(10), |s| {
        s.contains("1 keep-out, 1 slow zone")
    });
    let loaded = tmux.wait_for("the keep-out drawn", Duration::from_secs(10), |s| {
        map_dots(s) > demo + 20
    });
    println!(
        "map dots: {demo} with the demo arena, {} with the keep-out and slow zone",
        map_dots(&loaded)
    );

    let furthest = drive_robot_2_at_the_wall(&tmux);
    println!("robot_2 held at x {furthest:.2} at most");
    tmux.keys(&["Escape", "q"]);
}

/// robot_2 (a kiwi at x 2.73 facing +x) driven at the east wall, one
/// `drive` after another as an operator holding a course would (a
/// single command lasts until the channel goes silent), until its card
/// has shown the layer limiting it (`fence`), the events its notice, and
/// it got to the wall and was pushed on there. Never further than the margin: its disc
/// (0.15 m) and the margin (0.1 m) from the wall at x 3.9, give or take
/// the position noise on the card (σ 3 cm and outliers, through the
/// agent's median filter): the centre held at 3.65, shown up to 3.85.
/// The furthest x its card showed.
fn drive_robot_2_at_the_wall(tmux: &Tmux) -> f64 {
    for line in ["mode robot_2 twist", "route robot_2 cmd/gcs"] {
        tmux.keys(&["Escape", ":"]);
        tmux.literal(line);
        tmux.keys(&["Enter"]);
    }
    let deadline = Instant::now() + Duration::from_secs(90);
    let (mut limited, mut noticed, mut furthest) = (false, false, f64::NEG_INFINITY);
    // Commands still sent once it got there: it must not move on.
    let mut pushes_at_the_wall = 0;
    while pushes_at_the_wall < 15 {
        tmux.keys(&["Escape", ":"]);
        tmux.literal("drive robot_2 0.3 0 0");
        tmux.keys(&["Enter"]);
        let s = tmux.screen();
        limited |= card_status(&s, "robot_2").contains("fence");
        noticed |= s.contains(NOTICE);
        let x = card_position(&s, "robot_2").map_or(f64::NEG_INFINITY, |p| p.0);
        furthest = furthest.max(x);
        assert!(furthest <= 3.85, "robot_2 at x {furthest:.2}:\n{s}");
        if limited && noticed && x >= 3.6 {
            pushes_at_the_wall += 1;
        }
        assert!(
            Instant::now() < deadline,
            "robot_2 not stopped at the wall (limited {limited}, noticed {noticed}):\n{s}"
        );
        std::thread::sleep(Duration::from_millis(150));
    }
    furthest
}
