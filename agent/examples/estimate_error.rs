//! How far the position a robot reports is from the truth, against the
//! error bound it reports with it (`Telemetry.safety.position_error`, the
//! amount its safety layer grows its disc by): UWB-like fixes (Gaussian
//! jitter, 5% outliers of 100-500 mm) every control period through the
//! 9-fix median filter, moved on to now by the robot's own motion, on the
//! standard three-waypoint courses; the raw median's error beside it.
//!
//! `cargo run --release -p mech-agent --example estimate_error [runs]`

use std::time::Duration;

use mech_agent::PlatformSpec;
use mech_agent::sim::trial::{TrialResult, median_p95, standard_trial};

fn main() {
    let runs: u64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(20);
    println!("{runs} runs per row; errors in mm, every control period, truth from the simulator");
    println!(
        "{:<12} {:>7} {:>14} {:>12} {:>12} {:>12} {:>14}",
        "platform",
        "period",
        "raw median p95",
        "reported p99",
        "reported max",
        "bound",
        "beyond bound"
    );
    for spec in [
        PlatformSpec::diff_drive(),
        PlatformSpec::kiwi(),
        PlatformSpec::quadcopter(),
    ] {
        for period in [20, 50] {
            let results: Vec<TrialResult> = (0..runs)
                .map(|i| {
                    let mut t = standard_trial(spec.clone(), i);
                    t.control_period = Duration::from_millis(period);
                    t.run()
                })
                .collect();
            let of = |f: fn(&TrialResult) -> f64| results.iter().map(f).collect::<Vec<_>>();
            let worst = |f: fn(&TrialResult) -> f64| of(f).into_iter().fold(0.0, f64::max);
            let (_, raw_p95) = median_p95(&of(|r| r.pose_p95));
            let beyond = of(|r| r.beyond_bound).iter().sum::<f64>() / runs as f64;
            let settings = mech_agent::safety::SafetyConfig::default();
            let lag = 4.0 * period as f64 / 1000.0;
            let bound = settings.position_error + settings.max_deceleration * lag * lag / 2.0;
            println!(
                "{:<12} {:>5}ms {:>14.1} {:>12.1} {:>12.1} {:>12.1} {:>13.3}%",
                spec.build().name(),
                period,
                raw_p95 * 1e3,
                median_p95(&of(|r| r.reported_p99)).1 * 1e3,
                worst(|r| r.reported_max) * 1e3,
                bound * 1e3,
                beyond * 100.0,
            );
        }
    }
}
