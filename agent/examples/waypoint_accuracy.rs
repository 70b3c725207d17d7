//! Simulated waypoint accuracy with UWB-like noise (Gaussian jitter plus
//! occasional 100-500 mm outliers) through the agent's median filter and
//! onboard waypoint controller: median and 95th-percentile final error over
//! many runs per platform.
//!
//! `cargo run --release -p mech-agent --example waypoint_accuracy [runs]`

use mech_agent::PlatformSpec;
use mech_agent::sim::trial::{median_p95, standard_trial};

fn main() {
    let runs: u64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(40);
    println!(
        "{runs} runs per platform, 3 waypoints each, arrival radius 30 mm, 50 Hz control, median window 9"
    );
    println!(
        "{:<12} {:>10} {:>10} {:>10} {:>10}",
        "platform", "median mm", "p95 mm", "max mm", "finished"
    );
    for spec in [
        PlatformSpec::diff_drive(),
        PlatformSpec::kiwi(),
        PlatformSpec::quadcopter(),
    ] {
        let results: Vec<_> = (0..runs)
            .map(|i| standard_trial(spec.clone(), i).run())
            .collect();
        let errors: Vec<f64> = results.iter().map(|r| r.final_error * 1000.0).collect();
        let (median, p95) = median_p95(&errors);
        let max = errors.iter().copied().fold(0.0, f64::max);
        let finished = results.iter().filter(|r| r.finished).count();
        println!(
            "{:<12} {median:>10.1} {p95:>10.1} {max:>10.1} {finished:>7}/{runs}",
            spec.build().name()
        );
    }
}
