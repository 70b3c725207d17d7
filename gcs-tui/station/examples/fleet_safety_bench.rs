//! Fleet safety through the real stack on the demo's noisy positions: the
//! agent core on simulated vehicles, each on its own loopback socket, the
//! real station's router and neighbour broadcaster, every robot measuring
//! its position as the demo's do (UWB-like noise and outliers through the
//! median filter). Every figure is measured on the simulator's true
//! poses, which the robots never see.
//!
//! For each scenario and run it prints the smallest gap between two true
//! discs, the time below the margin, the smallest clearance of a true disc
//! to the arena's edges and keep-outs, the largest true speed above a slow
//! zone's cap, the largest error of a reported position, and, for
//! missions, the last arrival against the same run with every layer off
//! (robots then drive through each other: their time alone).
//!
//!   cargo run --release -p mech-station --example fleet_safety_bench [-- RUNS [SCENARIO]]

#![allow(clippy::unwrap_used, clippy::print_stdout)]

#[path = "../tests/support/fleet.rs"]
mod fleet;

use std::time::Duration;

use fleet::{Metrics, Options, Rig};
use mech_agent::PlatformSpec;
use mech_agent::sim::safety_trial::twist;
use mech_core::ArenaConfig;
use mech_proto::Pose;

/// The demo's platforms, cycled as `mech-gcs --demo` does.
fn platforms() -> [PlatformSpec; 4] {
    [
        PlatformSpec::diff_drive(),
        PlatformSpec::kiwi(),
        PlatformSpec::diff_drive(),
        PlatformSpec::quadcopter(),
    ]
}

fn pose(x: f64, y: f64, heading: f64) -> Pose {
    Pose {
        x,
        y,
        z: 0.0,
        heading,
    }
}

/// What one run of a scenario measured.
struct Run {
    metrics: Metrics,
    /// Last arrival with the layer on, and with it off, s.
    arrival: Option<(Option<f64>, f64)>,
}

/// Robots on missions from `starts` to `goals` (started together), with
/// every layer on or off; the last arrival (s since the missions were
/// sent, `None` if not all arrived in 120 s) and the metrics. `freeze`:
/// the station goes quiet for 0.8 s four times during the run.
async fn missions(
    options: &Options,
    layer_on: bool,
    starts: &[Pose],
    goals: &[(f64, f64)],
    freeze: bool,
) -> (Option<f64>, Metrics) {
    let mut rig = Rig::with(layer_on, options.clone()).await;
    let specs = platforms();
    for (i, start) in starts.iter().enumerate() {
        rig.add(&specs[i % 4], *start).await;
    }
    rig.settle().await;
    let start = rig.time();
    for (i, goal) in goals.iter().enumerate() {
        rig.mission(i, *goal).await;
    }
    let mut arrived = false;
    for k in 0..60 {
        if freeze && (1..5).contains(&k) {
            rig.freeze(Duration::from_millis(800));
        }
        if rig.run_until_arrived(2.0).await {
            arrived = true;
            break;
        }
    }
    if !arrived && layer_on {
        println!(
            "not all arrived; the robots at the end:\n{}",
            rig.describe()
        );
    }
    let took = arrived
        .then(|| rig.last_arrival())
        .flatten()
        .map(|t| t.saturating_sub(start).as_secs_f64());
    let m = rig.metrics();
    rig.shutdown().await;
    (took, m)
}

/// Eight robots on a circle round the arena's centre, each to the point
/// opposite.
fn circle() -> (Vec<Pose>, Vec<(f64, f64)>) {
    let (cx, cy, r) = (1.95, 1.4, 1.05);
    let angle = |i: usize| i as f64 / 8.0 * std::f64::consts::TAU;
    let starts = (0..8)
        .map(|i| {
            let a = angle(i);
            pose(cx + r * a.cos(), cy + r * a.sin(), a + std::f64::consts::PI)
        })
        .collect();
    let goals = (0..8)
        .map(|i| (cx - r * angle(i).cos(), cy - r * angle(i).sin()))
        .collect();
    (starts, goals)
}

/// Four robots crossing at right angles, in two pairs: left-right and
/// bottom-top through the centre, each pair head-on.
fn right_angles() -> (Vec<Pose>, Vec<(f64, f64)>) {
    let pi = std::f64::consts::PI;
    let starts = vec![
        pose(0.6, 1.4, 0.0),
        pose(1.95, 0.4, pi / 2.0),
        pose(3.3, 1.4, pi),
        pose(1.95, 2.4, -pi / 2.0),
    ];
    let goals = vec![(3.3, 1.4), (1.95, 2.4), (0.6, 1.4), (1.95, 0.4)];
    (starts, goals)
}

/// A mission scenario: the run with every layer on, then off for the
/// time alone.
async fn mission_run(
    options: &Options,
    (starts, goals): (Vec<Pose>, Vec<(f64, f64)>),
    freeze: bool,
) -> Run {
    let (with, metrics) = missions(options, true, &starts, &goals, freeze).await;
    let (alone, _) = missions(options, false, &starts, &goals, false).await;
    Run {
        metrics,
        arrival: Some((with, alone.unwrap_or(f64::NAN))),
    }
}

/// What a run without missions measured, its station stopped.
async fn stopped(rig: Rig) -> Run {
    let metrics = rig.metrics();
    rig.shutdown().await;
    Run {
        metrics,
        arrival: None,
    }
}

/// Ten robots given a new random twist each second for 30 s.
async fn random_twists(options: &Options, seed: u64) -> Run {
    let mut rig = Rig::with(true, options.clone()).await;
    let arena = mech_agent::sim::Arena::default();
    let specs = platforms();
    for i in 0..10 {
        rig.add(&specs[i % 4], arena.start_pose(i, 10)).await;
    }
    rig.settle().await;
    let mut state = seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) | 1;
    let mut signed = move || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        (state >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
    };
    for _ in 0..30 {
        for (i, spec) in specs.iter().cycle().take(10).enumerate() {
            let p = spec.build();
            let cmd = twist(p.as_ref(), signed(), signed(), signed());
            rig.command(i, cmd);
        }
        rig.run_for(1.0).await;
    }
    stopped(rig).await
}

/// A kiwi driven at full speed for 6 s from (1.6, 1.4) along `heading`,
/// its neighbour a diff-drive pressing it the same way from behind.
async fn driven_at(options: &Options, heading: f64) -> Run {
    let mut rig = Rig::with(true, options.clone()).await;
    let kiwi = PlatformSpec::kiwi();
    let dd = PlatformSpec::diff_drive();
    let a = rig.add(&kiwi, pose(1.6, 1.4, heading)).await;
    let back = (1.6 - 0.6 * heading.cos(), 1.4 - 0.6 * heading.sin());
    let b = rig.add(&dd, pose(back.0, back.1, heading)).await;
    rig.settle().await;
    rig.command(a, twist(kiwi.build().as_ref(), 1.0, 0.0, 0.0));
    rig.command(b, twist(dd.build().as_ref(), 1.0, 0.0, 0.0));
    rig.run_for(6.0).await;
    stopped(rig).await
}

/// The demo arena with a keep-out square and a static disc in the middle
/// of the left half, and a slow zone (0.1 m/s) across the right half.
fn obstacle_arena() -> ArenaConfig {
    let text = r#"
boundary = [[0.0, 0.0], [3.9, 0.0], [3.9, 2.8], [0.0, 2.8]]
keep_out = [[[1.2, 1.1], [1.6, 1.1], [1.6, 1.5], [1.2, 1.5]]]
slow_zones = [{ polygon = [[2.6, 0.0], [3.1, 0.0], [3.1, 2.8], [2.6, 2.8]], max_speed = 0.1 }]
obstacles = [{ x = 1.0, y = 0.5, radius = 0.15 }]
margin = 0.1
"#;
    ArenaConfig::parse_file_text(text, "bench-arena.toml").unwrap()
}

/// Robots driven at full speed for 6 s at the keep-out (a quadcopter, the
/// fastest), past the disc (a diff-drive) and across the slow zone to the
/// wall (a kiwi).
async fn obstacles(options: &Options) -> Run {
    let mut options = options.clone();
    options.arena = obstacle_arena();
    let mut rig = Rig::with(true, options).await;
    let drives = [
        (PlatformSpec::quadcopter(), pose(0.4, 1.3, 0.0)),
        (PlatformSpec::diff_drive(), pose(0.4, 0.55, 0.0)),
        (PlatformSpec::kiwi(), pose(2.0, 2.0, 0.0)),
    ];
    for (spec, start) in &drives {
        rig.add(spec, *start).await;
    }
    rig.settle().await;
    for (i, (spec, _)) in drives.iter().enumerate() {
        rig.command(i, twist(spec.build().as_ref(), 1.0, 0.0, 0.0));
    }
    rig.run_for(6.0).await;
    stopped(rig).await
}

const SCENARIOS: [&str; 9] = [
    "circle-8",
    "circle-8-full-speed",
    "right-angles-4",
    "random-twists-10",
    "pressed-at-the-wall",
    "pressed-into-a-corner",
    "obstacles-full-speed",
    "circle-8-station-frozen",
    "circle-8-exact-poses",
];

async fn scenario(name: &str, seed: u64) -> Run {
    let noisy = Options::noisy(seed);
    let full = Options {
        cruise_fraction: 1.0,
        ..noisy.clone()
    };
    match name {
        "circle-8" => mission_run(&noisy, circle(), false).await,
        "circle-8-full-speed" => mission_run(&full, circle(), false).await,
        "right-angles-4" => mission_run(&full, right_angles(), false).await,
        "random-twists-10" => random_twists(&noisy, seed).await,
        "pressed-at-the-wall" => driven_at(&noisy, 0.0).await,
        "pressed-into-a-corner" => driven_at(&noisy, 0.6).await,
        "obstacles-full-speed" => obstacles(&noisy).await,
        "circle-8-station-frozen" => mission_run(&noisy, circle(), true).await,
        "circle-8-exact-poses" => mission_run(&Options::default(), circle(), false).await,
        _ => unreachable!(),
    }
}

fn print(name: &str, seed: u64, run: &Run) {
    let m = &run.metrics;
    let arrival = match run.arrival {
        Some((Some(with), alone)) => format!("{with:.2} s / {alone:.2} s = {:.2}x", with / alone),
        Some((None, alone)) => format!("NOT ALL ARRIVED in 120 s (alone {alone:.2} s)"),
        None => "-".into(),
    };
    println!(
        "{name:<26} seed {seed:>2}  gap {:>7.1} mm  below margin {:>5.2} s  clearance {:>6.1} mm  \
         zone overspeed {:>5.3} m/s  estimate error {:>5.1} mm  arrival {arrival}",
        m.min_gap * 1e3,
        m.below_margin,
        m.min_clearance * 1e3,
        m.zone_overspeed,
        m.max_estimate_error * 1e3,
    );
}

#[tokio::main(flavor = "multi_thread", worker_threads = 2)]
async fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let runs: u64 = args.first().and_then(|r| r.parse().ok()).unwrap_or(10);
    let only = args.get(1).cloned();
    let margin = mech_core::arena::DEFAULT_MARGIN;
    println!("margin {:.0} mm; figures on true poses", margin * 1e3);
    for name in SCENARIOS {
        if only.as_deref().is_some_and(|o| o != name) {
            continue;
        }
        for seed in 1..=runs {
            let run = scenario(name, seed).await;
            print(name, seed, &run);
        }
    }
}
