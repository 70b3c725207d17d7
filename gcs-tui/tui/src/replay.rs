//! `mech-gcs replay FILE` in the TUI: the recording played back as a
//! station the TUI attaches to (`mech_station::replay::player`: pause,
//! play, speed, seek), with no router and no socket behind it, so nothing
//! an operator does can reach a robot.

use std::path::Path;
use std::process::ExitCode;

use anyhow::Context;
use mech_core::FleetConfig;
use mech_station::replay::{self, player};

/// Shows `file` in the TUI until the operator quits; exit code 1 for a
/// damaged file (what could be read is shown).
pub async fn run_tui(
    file: &Path,
    fleet: FleetConfig,
    options: crate::ui::RunOptions,
) -> anyhow::Result<ExitCode> {
    let replay = replay::open(file, fleet)?;
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
