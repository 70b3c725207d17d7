//! Simulated waypoint accuracy with UWB-like noise meets the target
//! (median final error <= 50 mm over 20 runs; the 2017 system used a 100 mm
//! threshold). Deterministic seeds; no wall-clock time involved. The
//! `waypoint_accuracy` example prints the full numbers.
#![allow(clippy::unwrap_used)]

use mech_agent::PlatformSpec;
use mech_agent::sim::trial::{median_p95, standard_trial};

#[test]
fn median_final_error_within_50_mm_with_uwb_noise() {
    for spec in [PlatformSpec::diff_drive(), PlatformSpec::kiwi()] {
        let results: Vec<_> = (0..20)
            .map(|i| standard_trial(spec.clone(), i).run())
            .collect();
        assert!(results.iter().all(|r| r.finished), "{spec:?}: {results:?}");
        let errors: Vec<f64> = results.iter().map(|r| r.final_error).collect();
        let (median, p95) = median_p95(&errors);
        println!(
            "{spec:?}: median {:.1} mm, p95 {:.1} mm",
            median * 1000.0,
            p95 * 1000.0
        );
        assert!(median <= 0.050, "{spec:?}: median {median}");
    }
}

#[test]
fn the_median_filter_is_what_makes_it_accurate() {
    // Without filtering, outliers trigger early "arrivals" and steer the
    // robot off: the same trials do measurably worse.
    let spec = PlatformSpec::diff_drive();
    let errors = |window: usize| {
        let e: Vec<f64> = (0..20)
            .map(|i| {
                let mut t = standard_trial(spec.clone(), i);
                t.filter_window = window;
                t.run().final_error
            })
            .collect();
        median_p95(&e)
    };
    let (filtered_median, filtered_p95) = errors(9);
    let (raw_median, raw_p95) = errors(1);
    println!(
        "window 9: {filtered_median:.4}/{filtered_p95:.4} m; window 1: {raw_median:.4}/{raw_p95:.4} m"
    );
    assert!(
        raw_p95 > filtered_p95,
        "unfiltered p95 {raw_p95} vs filtered {filtered_p95}"
    );
}

#[test]
fn odometry_with_uwb_keeps_the_pose_error_below_uwb_alone() {
    // The same runs on the same simulated robots, once positioned by UWB
    // alone (median filter), once with wheel encoders fused with the UWB
    // fixes, at 50 Hz and at 10 Hz fixes.
    use mech_agent::sim::SimEncoderModel;
    use std::time::Duration;
    for spec in [PlatformSpec::diff_drive(), PlatformSpec::kiwi()] {
        for fix_period in [Duration::ZERO, Duration::from_millis(100)] {
            let run = |encoders: bool| {
                let results: Vec<_> = (0..8)
                    .map(|i| {
                        let mut t = standard_trial(spec.clone(), i);
                        t.fix_period = fix_period;
                        if encoders {
                            t = t.with_encoders(SimEncoderModel::default());
                        }
                        t.run()
                    })
                    .collect();
                assert!(results.iter().all(|r| r.finished), "{spec:?}: {results:?}");
                let rms: Vec<f64> = results.iter().map(|r| r.pose_rms).collect();
                let finals: Vec<f64> = results.iter().map(|r| r.final_error).collect();
                (median_p95(&rms).0, median_p95(&finals).0)
            };
            let (uwb, uwb_final) = run(false);
            let (fused, fused_final) = run(true);
            println!(
                "{spec:?} fixes every {fix_period:?}: pose rms {:.1} mm UWB only, {:.1} mm with odometry; final {:.1} / {:.1} mm",
                uwb * 1000.0,
                fused * 1000.0,
                uwb_final * 1000.0,
                fused_final * 1000.0
            );
            assert!(fused < uwb, "{spec:?} {fix_period:?}: {fused} vs {uwb}");
            assert!(
                fused_final <= 0.050,
                "{spec:?} {fix_period:?}: final {fused_final}"
            );
        }
    }
}
