//! `mech-agent`: runs on each robot.

use clap::Parser;

/// MECH robot agent: obeys the routed controller, reports telemetry, stops
/// when the link or the controller goes quiet.
#[derive(Debug, Parser)]
#[command(name = "mech-agent", version)]
struct Cli {
    /// Robot configuration file (TOML).
    #[arg(long)]
    config: Option<std::path::PathBuf>,
    /// Run a simulated robot instead of real hardware.
    #[arg(long)]
    sim: bool,
}

fn main() {
    let _cli = Cli::parse();
}
