//! The TUI at fleet scale, end to end: `mech-gcs --demo 100` in a detached
//! tmux session at 120x36 and at 200x50. On the captured map no two labels
//! run into each other; the fleet table (`v`) lists robots in natural order
//! and `/robot_9` keeps exactly robot_9 and robot_90..99; the status bar
//! says the TUI runs its own station (embedded).
//!
//! How a label is read off the captured map (the cells inside the Map
//! panel's border): a *label* is a maximal run, along a row, of label
//! characters (ASCII letters and digits, `_`, `.`, `-`); braille dots,
//! marks (`●` `◉`), box drawing and blanks end it. Every label must be
//! exactly one of: a robot's name (`robot_N`, N in 1..=100), its short form
//! (`rN`), or a metre value at a grid line (a multiple of the step in the
//! title, within 50 m). Two labels that touched or overlapped would read as
//! one run that is none of these (`robot_9robot_10`, `r9r10`, `robot_5-1`,
//! `r1` over `robot_12`). A robot's label must sit where the placer puts
//! it, beside a mark: one cell right or left of it on its row, or starting
//! or ending in its column on the row above or below; and no robot is
//! labelled twice. The labels shown plus the title's count of hidden ones
//! make the whole fleet.

use std::collections::HashSet;
use std::process::Command;
use std::time::Duration;

use crate::tmux::Tmux;

#[test]
fn a_hundred_robots_labelled_apart_and_the_table_sorted_and_filtered() {
    if Command::new("tmux").arg("-V").output().is_err() {
        println!("skipped: tmux is not installed");
        return;
    }
    for (w, h) in [(120u16, 36u16), (200, 50)] {
        let tmux = start(w, h);
        check_screens(&tmux, w, h);
        check_table(&tmux, w, h);
        tmux.keys(&["q"]);
    }
}

/// `mech-gcs --demo 100` at `w` x `h`, once all 100 robots are connected.
fn start(w: u16, h: u16) -> Tmux {
    let id = format!("mech-e2e-scale-{}-{w}", std::process::id());
    let state = std::env::temp_dir().join(&id);
    std::fs::create_dir_all(&state).expect("temp dir");
    let tmux = Tmux {
        socket: id,
        session: "gcs".into(),
        state: state.clone(),
    };
    let cmd = format!(
        "XDG_STATE_HOME={} {} --demo 100 --udp 127.0.0.1:0 --tcp 127.0.0.1:0",
        state.display(),
        mech_e2e::binary("mech-gcs").display()
    );
    let (ws, hs) = (w.to_string(), h.to_string());
    let args = ["new-session", "-d", "-s", "gcs", "-x", &ws, "-y", &hs, &cmd];
    let out = tmux.run(&args);
    assert!(out.status.success(), "tmux new-session: {out:?}");
    // The status bar in full (200 columns) or short (120): either way it
    // says the TUI runs its own station.
    tmux.wait_for("100 connected robots", Duration::from_secs(90), |s| {
        let full = s.contains("robots 100 (100 ok") && s.contains("│ embedded as ");
        let short = s.contains("│ 100/100 ok") && s.contains("@embedded │");
        (full || short) && s.contains("Map")
    });
    tmux
}

/// The map panel of a captured screen.
struct Map {
    /// The panel's top border (its title).
    title: String,
    /// The cells inside its border, row by row.
    rows: Vec<Vec<char>>,
}

/// Checks the labels on five screens a second apart (the simulated
/// robots' noise moves marks across cells, so each frame is laid out
/// anew). A capture taken while the terminal is being redrawn could mix two
/// frames, so a screen that fails is captured again up to twice, 0.2 s
/// apart: a frame that is wrong fails every time.
fn check_screens(tmux: &Tmux, w: u16, h: u16) {
    for _ in 0..5 {
        let mut failure = String::new();
        for _ in 0..3 {
            let screen = tmux.screen();
            match map_panel(&screen).ok_or("no map on the screen".to_string()) {
                Ok(map) => match check_labels(&map) {
                    Ok(n) if n >= 10 => {
                        failure.clear();
                        break;
                    }
                    Ok(n) => failure = format!("{w}x{h}: only {n} robots labelled\n{screen}"),
                    Err(e) => failure = format!("{w}x{h}: {e}\n{screen}"),
                },
                Err(e) => failure = format!("{w}x{h}: {e}\n{screen}"),
            }
            std::thread::sleep(Duration::from_millis(200));
        }
        assert!(failure.is_empty(), "{failure}");
        std::thread::sleep(Duration::from_secs(1));
    }
}

/// Finds the box whose top border holds ` Map ` and cuts out its inside.
fn map_panel(screen: &str) -> Option<Map> {
    let lines: Vec<Vec<char>> = screen.lines().map(|l| l.chars().collect()).collect();
    let top = lines
        .iter()
        .position(|l| l.iter().collect::<String>().contains("┌ Map"))?;
    let left = (0..lines[top].len())
        .find(|&c| lines[top][c] == '┌' && lines[top].get(c + 2) == Some(&'M'))?;
    let right = (left + 1..lines[top].len()).find(|&c| lines[top][c] == '┐')?;
    let bottom = (top + 1..lines.len()).find(|&r| lines[r].get(left) == Some(&'└'))?;
    let rows = lines[top + 1..bottom]
        .iter()
        .map(|l| {
            l.get(left + 1..right)
                .map(<[char]>::to_vec)
                .unwrap_or_default()
        })
        .collect();
    Some(Map {
        title: lines[top][left..right].iter().collect(),
        rows,
    })
}

fn is_label_char(c: char) -> bool {
    c.is_ascii_alphanumeric() || matches!(c, '_' | '.' | '-')
}

/// Each label on the map: its row, first and last column, and text.
fn labels(map: &Map) -> Vec<(usize, usize, usize, String)> {
    let mut out = Vec::new();
    for (r, row) in map.rows.iter().enumerate() {
        let mut c = 0;
        while c < row.len() {
            if !is_label_char(row[c]) {
                c += 1;
                continue;
            }
            let start = c;
            while c < row.len() && is_label_char(row[c]) {
                c += 1;
            }
            out.push((r, start, c - 1, row[start..c].iter().collect()));
        }
    }
    out
}

/// The robot number a label names (`robot_12`, `r12`), if it is one.
fn robot_number(text: &str) -> Option<u32> {
    let n = text
        .strip_prefix("robot_")
        .or_else(|| text.strip_prefix('r'))?;
    let n: u32 = n.parse().ok().filter(|_| !n.starts_with('0'))?;
    (1..=100).contains(&n).then_some(n)
}

/// Metres between grid lines, from the title (`grid 1 m`, `grid 50 cm`).
fn grid_step(title: &str) -> Option<f64> {
    let mut words = title.split("grid ").nth(1)?.split_whitespace();
    let v: f64 = words.next()?.parse().ok()?;
    let unit = match words.next()? {
        "km" => 1000.0,
        "m" => 1.0,
        "cm" => 0.01,
        "mm" => 0.001,
        _ => return None,
    };
    Some(v * unit)
}

/// Whether `text` is a metre value at a grid line `step` apart.
fn is_tick(text: &str, step: f64) -> bool {
    let Ok(v) = text.parse::<f64>() else {
        return false;
    };
    let k = v / step;
    v.abs() <= 50.0 && (k - k.round()).abs() < 1e-6
}

/// Whether a mark (`●`, `◉`) is at `(row, col)` of the map.
fn mark_at(map: &Map, row: Option<usize>, col: Option<usize>) -> bool {
    let (Some(r), Some(c)) = (row, col) else {
        return false;
    };
    map.rows
        .get(r)
        .and_then(|l| l.get(c))
        .is_some_and(|&g| g == '●' || g == '◉')
}

/// A robot label at `row`, columns `a..=b`, beside a mark where the placer
/// puts labels.
fn beside_a_mark(map: &Map, row: usize, a: usize, b: usize) -> bool {
    let (up, down) = (row.checked_sub(1), Some(row + 1));
    mark_at(map, Some(row), a.checked_sub(2))
        || mark_at(map, Some(row), Some(b + 2))
        || [up, down]
            .iter()
            .any(|&r| mark_at(map, r, Some(a)) || mark_at(map, r, Some(b)))
}

/// The rules in the module's documentation; the number of robots
/// labelled.
fn check_labels(map: &Map) -> Result<usize, String> {
    let step = grid_step(&map.title).ok_or(format!("no grid step in {:?}", map.title))?;
    let hidden: usize = match map.title.split(" labels hidden").next() {
        Some(before) if map.title.contains(" labels hidden") => {
            let n = before.rsplit(' ').next().unwrap_or_default();
            n.parse()
                .map_err(|_| format!("hidden count in {:?}", map.title))?
        }
        _ => 0,
    };
    let mut named = HashSet::new();
    for (row, a, b, text) in labels(map) {
        if let Some(n) = robot_number(&text) {
            if !named.insert(n) {
                return Err(format!("robot_{n} labelled twice ({text:?} on row {row})"));
            }
            if !beside_a_mark(map, row, a, b) {
                return Err(format!(
                    "{text:?} (row {row}, cols {a}..{b}) beside no mark"
                ));
            }
        } else if !is_tick(&text, step) {
            return Err(format!(
                "{text:?} (row {row}, cols {a}..{b}) is no label: two ran together"
            ));
        }
    }
    if named.len() + hidden != 100 {
        return Err(format!("{} labelled + {hidden} hidden != 100", named.len()));
    }
    Ok(named.len())
}

/// The first word of each row of the fleet table (the robots' names), once
/// the whole table is on the screen: every row closed by the table's right
/// border and the bottom border under the last. A screen caught mid-draw
/// (the table's top over the cards it replaces) reads as `None`.
fn table_names(screen: &str) -> Option<Vec<String>> {
    let lines: Vec<Vec<char>> = screen.lines().map(|l| l.chars().collect()).collect();
    let top = lines
        .iter()
        .position(|l| l.iter().collect::<String>().contains("┌ Fleet"))?;
    let left = lines[top].iter().position(|&c| c == '┌')?;
    let right = (left + 1..lines[top].len()).find(|&c| lines[top][c] == '┐')?;
    let rows: Vec<&Vec<char>> = lines[top + 1..]
        .iter()
        .take_while(|l| l.get(left) == Some(&'│') && l.get(right) == Some(&'│'))
        .collect();
    let bottom = lines.get(top + 1 + rows.len())?;
    if bottom.get(left) != Some(&'└') || bottom.get(right) != Some(&'┘') {
        return None;
    }
    Some(
        rows.iter()
            .skip(1)
            .filter_map(|l| {
                let inside: String = l.get(left + 1..right)?.iter().collect();
                let word = inside
                    .split_whitespace()
                    .map(|w| w.trim_start_matches(|c: char| !c.is_ascii_alphanumeric()))
                    .find(|w| !w.is_empty())?;
                word.starts_with("robot_").then(|| word.to_string())
            })
            .collect(),
    )
}

/// `v` opens the table in natural name order; `/robot_9` keeps robot_9 and
/// robot_90..99. A screen is read until it shows what is expected (a
/// capture can land mid-draw); one that never does fails with the screen.
fn check_table(tmux: &Tmux, w: u16, h: u16) {
    let natural = |names: &[String]| {
        names.len() >= 12
            && names
                .iter()
                .enumerate()
                .all(|(i, n)| *n == format!("robot_{}", i + 1))
    };
    tmux.keys(&["v"]);
    tmux.wait_for(
        &format!("{w}x{h}: the fleet table in natural order"),
        Duration::from_secs(10),
        |s| s.contains("Fleet 100/100") && table_names(s).is_some_and(|n| natural(&n)),
    );
    tmux.keys(&["/"]);
    tmux.literal("robot_9");
    let mut expect = vec!["robot_9".to_string()];
    expect.extend((90..=99).map(|i| format!("robot_{i}")));
    tmux.wait_for(
        &format!("{w}x{h}: the table filtered by /robot_9 to robot_9 and robot_90..99"),
        Duration::from_secs(10),
        |s| s.contains("Fleet 11/100") && table_names(s).as_ref() == Some(&expect),
    );
    tmux.keys(&["Escape"]);
}

/// The label reader on made-up maps: it accepts labels apart beside their
/// marks and refuses two that ran together, a robot labelled twice, a
/// label away from any mark and a count that does not add up.
#[test]
fn the_label_reader_tells_labels_apart_from_labels_run_together() {
    let map = |title: &str, rows: &[&str]| {
        let mut s = format!("┌{:─<40}┐\n", format!(" Map  grid 1 m │ {title} "));
        for r in rows {
            s.push_str(&format!("│{r:<40}│\n"));
        }
        s.push_str(&format!("└{}┘\n", "─".repeat(40)));
        map_panel(&s).expect("a map panel")
    };
    let good = map("98 labels hidden", &["● robot_1   r2 ●", " 0   1   2"]);
    assert_eq!(check_labels(&good), Ok(2));
    for (title, rows, why) in [
        ("98 labels hidden", ["● robot_1robot_2", ""], "ran together"),
        ("98 labels hidden", ["● r1 ● r1", ""], "twice"),
        (
            "99 labels hidden",
            ["● robot_1  ", "      r2"],
            "beside no mark",
        ),
        ("97 labels hidden", ["● robot_1 ● r2", ""], "!= 100"),
        (
            "98 labels hidden",
            ["● robot_1 ● r2", " 0.5"],
            "ran together",
        ),
    ] {
        let e = check_labels(&map(title, &rows)).expect_err(why);
        assert!(e.contains(why), "{e}");
    }
}
