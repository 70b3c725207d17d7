//! `mech-gcs`: the ground-control station binary.

use clap::Parser;

/// MECH ground-control station: robot cards, braille map, waypoints, live
/// controller routing.
#[derive(Debug, Parser)]
#[command(name = "mech-gcs", version)]
struct Cli {
    /// Start a simulated fleet of N robots (default 4).
    #[arg(long, num_args = 0..=1, default_missing_value = "4")]
    demo: Option<usize>,
    /// Run a command script headless ("-" for stdin).
    #[arg(long)]
    script: Option<std::path::PathBuf>,
}

fn main() {
    let _cli = Cli::parse();
}
