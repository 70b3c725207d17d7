//! The TUI end to end: `mech-gcs --demo` inside a detached tmux session.
//! Keys and SGR mouse clicks go in with `send-keys`, the screen comes back
//! with `capture-pane -p`. A waypoint is typed near robot_1, sent to it,
//! robot_1 is routed to the waypoint channel from the command line, and its
//! card must report the mission arrived.

use std::process::Command;
use std::time::Duration;

use crate::tmux::{Tmux, card_position, card_status};

#[test]
fn waypoint_typed_sent_and_routed_arrives_on_the_card() {
    if Command::new("tmux").arg("-V").output().is_err() {
        println!("skipped: tmux is not installed");
        return;
    }
    let tmux = Tmux::demo(&format!("mech-e2e-tui-{}", std::process::id()), 160, 48);

    let screen = tmux.wait_for("two connected robots", Duration::from_secs(20), |s| {
        s.contains("robots 2 (2 ok")
            && card_position(s, "robot_1").is_some_and(|(x, y)| x.abs() + y.abs() > 0.05)
    });
    let (x, y) = card_position(&screen, "robot_1").expect("robot_1 pose on its card");

    // Mouse: an SGR click on robot_2's card (second card: four-line cards
    // under the status bar and the panel's border, 1-based row 7) selects
    // it.
    tmux.literal("\x1b[<0;6;7M\x1b[<0;6;7m");
    tmux.wait_for("robot_2 selected by a click", Duration::from_secs(5), |s| {
        s.contains("▶robot_2") && s.contains("sel 1")
    });

    // Keys: select robot_1, waypoint mode, type a waypoint 0.3 m ahead.
    tmux.keys(&["n"]);
    tmux.wait_for("robot_1 selected", Duration::from_secs(5), |s| {
        s.contains("▶robot_1")
    });
    tmux.keys(&["f", "e"]);
    tmux.literal(&format!("{:.2},{:.2}", x + 0.3, y));
    tmux.keys(&["Enter"]);
    tmux.wait_for("the waypoint listed", Duration::from_secs(5), |s| {
        s.contains("⚑1") && s.contains("Waypoints 1")
    });
    tmux.keys(&["Enter"]);
    tmux.wait_for("the mission acknowledged", Duration::from_secs(10), |s| {
        s.contains("robot_1 acknowledged mission")
    });

    // Route robot_1 to the waypoint channel with the command language.
    tmux.keys(&["Escape", ":"]);
    tmux.literal("route robot_1 wp/gcs");
    tmux.keys(&["Enter"]);
    let screen = tmux.wait_for("robot_1 arrived", Duration::from_secs(30), |s| {
        card_status(s, "robot_1").contains("arrived")
    });
    assert!(
        card_status(&screen, "robot_1").contains("wp/gcs✓"),
        "route acknowledged on the card:\n{screen}"
    );

    // E-stop on one key, banner until released.
    tmux.keys(&["X"]);
    tmux.wait_for("the e-stop banner", Duration::from_secs(5), |s| {
        s.contains("E-STOP ENGAGED")
    });
    tmux.keys(&["C-r"]);
    tmux.wait_for("the e-stop released", Duration::from_secs(5), |s| {
        !s.contains("E-STOP ENGAGED")
    });
    tmux.keys(&["q"]);
}
