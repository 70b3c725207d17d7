//! The TUI's plots end to end, at 80x24 and at 200x50: `mech-gcs --demo 2`
//! in tmux; waypoints typed and sent to robot_1 while it is routed to
//! none (the command line's history then offers the route); the offered
//! route run; the fleet table
//! sorted by loss shows its trend; robot_1's detail view draws its charts
//! in braille, the cross-track error of the mission sent included.

use std::process::Command;
use std::time::Duration;

use crate::tmux::Tmux;

#[test]
fn the_detail_view_plots_a_robots_last_minute_at_80x24() {
    plots_at(80, 24);
}

#[test]
fn the_detail_view_plots_a_robots_last_minute_at_200x50() {
    plots_at(200, 50);
}

const TITLES: [&str; 6] = [
    " speed m/s ⠤cmd •pos ",
    " heading ° ",
    " battery % ",
    " loss % ",
    " round trip ms ",
    " cross-track m ",
];

fn is_braille(c: char) -> bool {
    ('\u{2801}'..='\u{28ff}').contains(&c)
}

/// A waypoint in the middle of the demo arena (3.9 m x 2.8 m from the
/// origin), sent to robot_1, which is routed to none; then the route the
/// command line's history offers, run.
fn waypoint_sent_then_routed(tmux: &Tmux) {
    tmux.keys(&["n"]);
    tmux.wait_for("robot_1 selected", Duration::from_secs(5), |s| {
        s.contains("sel 1")
    });
    tmux.keys(&["f", "e"]);
    tmux.literal("2.0,1.4");
    tmux.keys(&["Enter"]);
    tmux.wait_for("the waypoint listed", Duration::from_secs(5), |s| {
        s.contains("⚑1")
    });
    tmux.keys(&["Enter"]);
    tmux.wait_for("the mission acknowledged", Duration::from_secs(10), |s| {
        s.contains("robot_1 acknowledged mission")
    });
    // Out of waypoint mode (Esc alone: Esc and a key at once would read
    // as Alt and the key), then the offered route from the history.
    tmux.keys(&["Escape"]);
    tmux.wait_for("waypoint mode left", Duration::from_secs(5), |s| {
        !s.contains("[placing]")
    });
    tmux.keys(&[":", "Up"]);
    tmux.wait_for("the offered line", Duration::from_secs(5), |s| {
        s.contains(":route robot_1 wp/gcs")
    });
    tmux.keys(&["Enter"]);
}

fn plots_at(w: u16, h: u16) {
    if Command::new("tmux").arg("-V").output().is_err() {
        assert!(std::env::var_os("CI").is_none(), "CI needs tmux");
        println!("skipped: tmux is not installed");
        return;
    }
    let tmux = Tmux::demo(&format!("mech-e2e-plots-{}-{w}", std::process::id()), w, h);
    tmux.wait_for("two connected robots", Duration::from_secs(30), |s| {
        s.contains("robots 2 (2 ok") || s.contains("2/2 ok")
    });

    waypoint_sent_then_routed(&tmux);

    // The table, sorted by loss (two columns back from the name), draws
    // the last minute of loss beside it.
    tmux.keys(&["v", "<", "<"]);
    let spark_in_row = |s: &str| {
        s.lines()
            .find(|l| l.contains("robot_1    "))
            .is_some_and(|row| row.chars().any(|c| ('▁'..='█').contains(&c)))
    };
    tmux.wait_for(
        "the loss trend, once measured",
        Duration::from_secs(20),
        |s| s.contains("sort loss") && s.contains("1 MIN") && spark_in_row(s),
    );

    // robot_1 (the cursor's robot) in detail: six charts, the speed drawn
    // over several columns of time (the chart fills as the minute does),
    // the cross-track error of the mission sent from here drawn.
    tmux.keys(&["Enter"]);
    let screen = tmux.wait_for("robot_1's charts", Duration::from_secs(30), |s| {
        let titled = TITLES.iter().all(|t| s.contains(t));
        titled
            && s.contains("robot_1 #1 │ Enter/Esc back")
            && braille_columns(&chart_body(s, " cross-track m ")) >= 1
            && braille_columns(&chart_body(s, " speed m/s")) >= 3
    });
    assert!(screen.contains("now"), "{screen}");
    assert!(!screen.contains("send waypoints from here"), "{screen}");
    if h >= 36 {
        assert!(
            screen.contains("link, as the router measures it"),
            "{screen}"
        );
    }
    tmux.keys(&["q"]);
}

/// How many columns of a chart's text hold braille (the plot's marks).
fn braille_columns(body: &str) -> usize {
    let mut columns = std::collections::BTreeSet::new();
    for line in body.lines() {
        for (i, c) in line.chars().enumerate() {
            if is_braille(c) {
                columns.insert(i);
            }
        }
    }
    columns.len()
}

/// The text of the chart titled `title` on `screen`: the cells under its
/// title, as wide as the title's border, down to its bottom border.
fn chart_body(screen: &str, title: &str) -> String {
    let lines: Vec<Vec<char>> = screen.lines().map(|l| l.chars().collect()).collect();
    for (row, line) in lines.iter().enumerate() {
        let text: String = line.iter().collect();
        let Some(byte) = text.find(title) else {
            continue;
        };
        let col = text[..byte].chars().count().saturating_sub(1);
        let end = line[col + 1..]
            .iter()
            .position(|c| *c == '┐')
            .map_or(line.len(), |p| col + 1 + p);
        let mut out = String::new();
        for l in lines.iter().skip(row + 1) {
            if l.get(col) == Some(&'└') {
                break;
            }
            out.extend(l.get(col..end.min(l.len())).unwrap_or_default());
            out.push('\n');
        }
        return out;
    }
    String::new()
}
