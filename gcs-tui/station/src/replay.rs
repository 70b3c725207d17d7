//! `mech-gcs replay FILE`: a recording read back, with no router and no
//! socket (nothing can reach a robot): as a station a TUI attaches to
//! ([`player`]: pause, play, speed, seek), as the JSON lines of `--script`
//! (`--script`), or as a summary of what the recording holds (`--info`).

pub mod player;

use std::path::Path;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

use anyhow::Context;
use mech_control::playback;
use mech_control::script::Sink;
use mech_core::FleetConfig;
use mech_core::replay::Replay;

/// How `replay` prints a recording.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Show {
    /// The JSON lines of `--script`.
    Script,
    /// What it holds.
    Info,
}

/// Opens `file`, read with the configuration's `[fleet]` section, saying
/// on stderr what is damaged in it.
pub fn open(file: &Path, fleet: FleetConfig) -> anyhow::Result<Replay> {
    let replay = Replay::open_with(file, fleet).context("cannot replay")?;
    if let Some(damage) = replay.damage() {
        eprintln!("mech-gcs: {}: {damage}", file.display());
    }
    Ok(replay)
}

/// Opens `file` and prints it; exit code 0 for a whole file, 1 for a
/// damaged one (what could be read is printed), an error if it is not a
/// recording.
pub fn run(file: &Path, show: Show, fleet: FleetConfig) -> anyhow::Result<ExitCode> {
    let replay = open(file, fleet)?;
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
            r.registration.hello.platform,
            r.telemetry.pose.x,
            r.telemetry.pose.y,
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
