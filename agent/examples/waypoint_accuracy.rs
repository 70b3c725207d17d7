//! Simulated waypoint accuracy with UWB-like noise (Gaussian jitter plus
//! occasional 100-500 mm outliers) through the agent's median filter and
//! onboard waypoint controller: median and 95th-percentile final error over
//! many runs per platform; and, for the wheeled platforms, the same runs on
//! a robot with wheel encoders (odometry fused with the fixes, closed-loop
//! wheel speed), with the agent's pose error along the way.
//!
//! `cargo run --release -p mech-agent --example waypoint_accuracy [runs]`

use std::time::Duration;

use mech_agent::PlatformSpec;
use mech_agent::sim::SimEncoderModel;
use mech_agent::sim::trial::{Trial, TrialResult, median_p95, standard_trial};

fn main() {
    let runs: u64 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(40);
    println!(
        "{runs} runs per row, 3 waypoints each, arrival radius 30 mm, 50 Hz control, median window 9"
    );
    println!(
        "final error: true distance to the last waypoint at rest; pose error: agent estimate vs truth, every period"
    );
    for (title, fix_period, battery) in [
        (
            "UWB fixes every period (50 Hz), full battery",
            Duration::ZERO,
            1.0,
        ),
        (
            "UWB fixes at 10 Hz, full battery",
            Duration::from_millis(100),
            1.0,
        ),
        (
            "UWB fixes every period (50 Hz), battery at 60%",
            Duration::ZERO,
            0.6,
        ),
    ] {
        println!("\n{title}");
        println!(
            "{:<12} {:<14} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}",
            "platform",
            "position",
            "final med",
            "final p95",
            "final max",
            "pose rms",
            "pose p95",
            "finished"
        );
        for spec in [
            PlatformSpec::diff_drive(),
            PlatformSpec::kiwi(),
            PlatformSpec::quadcopter(),
        ] {
            let wheeled = spec.build().max_wheel_speed().is_some();
            let trial = |i: u64, encoders: bool| {
                let mut t: Trial = standard_trial(spec.clone(), i);
                t.fix_period = fix_period;
                t.battery = battery;
                if encoders {
                    t = t.with_encoders(SimEncoderModel::default());
                }
                t.run()
            };
            let mut rows = vec![("UWB only", false)];
            if wheeled {
                rows.push(("UWB+odometry", true));
            }
            for (label, encoders) in rows {
                let results: Vec<TrialResult> = (0..runs).map(|i| trial(i, encoders)).collect();
                print_row(spec.build().name(), label, &results, runs);
            }
        }
    }
}

fn print_row(platform: &str, label: &str, results: &[TrialResult], runs: u64) {
    let mm = |f: fn(&TrialResult) -> f64| -> Vec<f64> {
        results.iter().map(|r| f(r) * 1000.0).collect()
    };
    let finals = mm(|r| r.final_error);
    let (median, p95) = median_p95(&finals);
    let max = finals.iter().copied().fold(0.0, f64::max);
    let rms = mm(|r| r.pose_rms);
    let (rms_median, _) = median_p95(&rms);
    let (p95_median, _) = median_p95(&mm(|r| r.pose_p95));
    let finished = results.iter().filter(|r| r.finished).count();
    println!(
        "{platform:<12} {label:<14} {median:>9.1} {p95:>9.1} {max:>9.1} {rms_median:>9.1} {p95_median:>9.1} {finished:>6}/{runs}"
    );
}
