//! `mech-gcs replay FILE`: a recording read back, with no router and no
//! socket (nothing can reach a robot): in the TUI ([`player`]: pause,
//! play, speed, seek), as the JSON lines of `--script` (`--script`), or as
//! a summary of what the recording holds (`--info`).

pub mod player;

use std::path::Path;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

use anyhow::Context;
use mech_control::playback;
use mech_control::script::Sink;
use mech_core::FleetConfig;
use mech_core::replay::Replay;

use crate::GcsConfig;

/// How `replay` prints a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Show {
    /// The JSON lines of `--script`.
    Script,
    /// What it holds.
    Info,
}

/// Opens `file`, saying on stderr what is damaged in it.
fn open(file: &Path, config: Option<&Path>) -> anyhow::Result<Replay> {
    let fleet = match config {
        Some(path) => GcsConfig::load(path)?.fleet,
        None => FleetConfig::default(),
    };
    let replay = Replay::open_with(file, fleet).context("cannot replay")?;
    if let Some(damage) = replay.damage() {
        eprintln!("mech-gcs: {}: {damage}", file.display());
    }
    Ok(replay)
}

/// Shows `file` in the TUI until the operator quits; exit code 1 for a
/// damaged file (what could be read is shown).
pub async fn run_tui(
    file: &Path,
    config: Option<&Path>,
    options: crate::ui::RunOptions,
) -> anyhow::Result<ExitCode> {
    let replay = open(file, config)?;
    let whole = replay.damage().is_none();
    crate::ui::run(player::attach(replay), options)
        .await
        .context("terminal error")?;
    Ok(if whole {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// Opens `file` and prints it; exit code 0 for a whole file, 1 for a
/// damaged one (what could be read is printed), an error if it is not a
/// recording.
pub fn run(file: &Path, show: Show, config: Option<&Path>) -> anyhow::Result<ExitCode> {
    let replay = open(file, config)?;
    if show == Show::Script {
        let sink: Sink = Arc::new(Mutex::new(Box::new(std::io::stdout())));
        let whole = playback::print(&replay, &sink);
        return Ok(if whole {
            ExitCode::SUCCESS
        } else {
            ExitCode::from(1)
        });
    }
    print!("{}", describe(&replay));
    Ok(if replay.damage().is_none() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(1)
    })
}

/// What a recording holds: its span, the robots at its end, and the
/// messages on each topic.
pub fn describe(replay: &Replay) -> String {
    let fleet = replay.fleet_at(replay.end());
    let mut out = format!(
        "{}: {:.1} s of router time ({:.1} s to {:.1} s), {} robots\n",
        replay.path().display(),
        replay.duration().as_secs_f64(),
        replay.start().as_secs_f64(),
        replay.end().as_secs_f64(),
        fleet.robots.len()
    );
    for r in fleet.robots.values() {
        out.push_str(&format!(
            "  {} ({}) last at ({:.2}, {:.2}), route {}\n",
            r.name,
            r.platform,
            r.pose.x,
            r.pose.y,
            r.route.requested.as_deref().unwrap_or("none")
        ));
    }
    out.push_str("topics:\n");
    let topics = replay.counts();
    for (topic, n) in topics.iter().filter(|(t, _)| !t.starts_with("/robots/")) {
        out.push_str(&format!("  {topic:<18} {n}\n"));
    }
    let per_robot: u64 = topics
        .iter()
        .filter(|(t, _)| t.starts_with("/robots/"))
        .map(|(_, n)| n)
        .sum();
    out.push_str(&format!("  /robots/*          {per_robot}\n"));
    out
}
