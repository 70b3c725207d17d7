//! Fleet safety benchmark: what the safety layer keeps (minimum gap between
//! robots, violations, fence breaches) and what it costs (mission time
//! against the same missions without it; CPU per filter step with 10 and 50
//! neighbours), in the lock-step simulator of `agent/tests/safety.rs`.
//!
//! `cargo run --release -p mech-agent --example safety_bench`

use std::time::{Duration, Instant};

use mech_agent::PlatformSpec;
use mech_agent::safety::{SafetyConfig, SafetyLayer, Vec2};
use mech_agent::sim::Arena as SimArena;
use mech_agent::sim::safety_trial::{SafetyTrial, TrialMetrics, demo_arena, twist};
use mech_proto::{Mission, Neighbour, Neighbours, Pose, Twist, Waypoint};

fn platforms() -> [PlatformSpec; 4] {
    [
        PlatformSpec::diff_drive(),
        PlatformSpec::kiwi(),
        PlatformSpec::diff_drive(),
        PlatformSpec::quadcopter(),
    ]
}

/// The crossing is run with each robot's place on the circle moved by
/// each of these, rad, times its share of [`SHIFTS`]: the same missions,
/// met a little out of step (a symmetric crossing runs the same way
/// whatever its orientation).
const JITTERS: [f64; 5] = [0.0, 0.05, 0.1, 0.15, 0.2];

/// Each robot's share of a jitter.
const SHIFTS: [f64; 8] = [0.0, 0.5, -0.3, 0.8, -0.6, 0.2, -0.9, 0.4];

/// Shortfall below the margin not counted as a violation, m (as in the
/// tests: see docs/safety.md, *What is not guaranteed*).
const TOLERANCE: f64 = 1e-3;

fn trial(layer_on: bool) -> SafetyTrial {
    let mut t = SafetyTrial::new(demo_arena(), SafetyConfig::default(), layer_on);
    t.tolerance = TOLERANCE;
    t
}

/// Eight robots swapping places across the centre of the demo arena.
fn crossing(layer_on: bool) -> SafetyTrial {
    crossing_with(
        layer_on,
        Duration::from_millis(100),
        Duration::from_millis(50),
        false,
        0.0,
    )
}

/// The crossing with neighbour states every `period`, `latency` old when
/// they arrive; with `stagger`, the missions start one control period
/// apart (as a station sending them one by one does); each robot's
/// place moved by `jitter` times its share of [`SHIFTS`].
fn crossing_with(
    layer_on: bool,
    period: Duration,
    latency: Duration,
    stagger: bool,
    jitter: f64,
) -> SafetyTrial {
    let mut t = trial(layer_on);
    t.neighbour_period = period;
    t.latency = latency;
    let specs = platforms();
    let (cx, cy, r) = (1.95, 1.4, 1.05);
    for i in 0..8 {
        let a = i as f64 / 8.0 * std::f64::consts::TAU + jitter * SHIFTS[i];
        let start = Pose {
            x: cx + r * a.cos(),
            y: cy + r * a.sin(),
            z: 0.0,
            heading: a + std::f64::consts::PI,
        };
        let k = t.add(&specs[i % 4], start);
        let waypoints = vec![Waypoint {
            x: cx - r * a.cos(),
            y: cy - r * a.sin(),
            z: 0.0,
            time: None,
        }];
        t.mission(
            k,
            Mission {
                id: 1,
                waypoints,
                looped: false,
                arrival_radius: 0.05,
                start_index: 0,
            },
        );
        if stagger {
            t.step();
        }
    }
    let mut waited = 0.0;
    while !t.all_arrived() && waited < 120.0 {
        t.run_for(0.5);
        waited += 0.5;
    }
    t
}

/// Ten robots, a new random twist each second for 60 s.
fn random_twists(layer_on: bool, seed: u64) -> TrialMetrics {
    let mut t = trial(layer_on);
    let arena = SimArena::default();
    let specs = platforms();
    for i in 0..10 {
        t.add(&specs[i % 4], arena.start_pose(i, 10));
    }
    let mut state = seed;
    let mut next = || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        2.0 * ((state >> 11) as f64 / (1u64 << 53) as f64) - 1.0
    };
    for _ in 0..60 {
        for i in 0..10 {
            let p = specs[i % 4].build();
            let cmd = twist(p.as_ref(), next(), next(), next());
            t.command(i, &cmd);
        }
        t.run_for(1.0);
    }
    t.metrics()
}

fn row(what: &str, m: &TrialMetrics) {
    println!(
        "  {what:<24} min gap {:>8.2} mm  separation violations {:>5}  min clearance {:>8.2} mm  margin violations {:>5}  breaches {:>5}",
        m.min_gap * 1000.0,
        m.separation_violations,
        m.min_clearance * 1000.0,
        m.margin_violations,
        m.breaches
    );
}

/// Time per `filter` call with `n` neighbours around a robot driven
/// towards them (the constraints bind, so the direction search runs).
fn filter_cost(spec: &PlatformSpec, n: usize) -> (f64, f64, f64) {
    let platform = spec.build();
    let mut arena = demo_arena();
    // A larger arena so 50 neighbours fit around the robot.
    arena.boundary = vec![
        mech_proto::Point { x: -5.0, y: -5.0 },
        mech_proto::Point { x: 5.0, y: -5.0 },
        mech_proto::Point { x: 5.0, y: 5.0 },
        mech_proto::Point { x: -5.0, y: 5.0 },
    ];
    let robots: Vec<Neighbour> = (0..n)
        .map(|i| {
            let ring = 0.6 + 0.35 * (i / 12) as f64;
            let a = (i % 12) as f64 / 12.0 * std::f64::consts::TAU + 0.1 * (i / 12) as f64;
            Neighbour {
                id: i as u16 + 2,
                x: ring * a.cos(),
                y: ring * a.sin(),
                z: 0.0,
                vx: -0.1 * a.cos(),
                vy: -0.1 * a.sin(),
                vz: 0.0,
                radius: 0.15,
                age_ms: 50,
                cooperative: true,
            }
        })
        .collect();
    let mut layer = SafetyLayer::new(SafetyConfig::default());
    layer.apply_arena(&arena);
    layer.apply_neighbours(
        &Neighbours {
            robot: "robot_1".into(),
            stamp_us: 1,
            robots,
            obstacles: vec![],
        },
        Duration::ZERO,
    );
    let outputs = platform.mix(&Twist {
        vx: platform.limits().max_speed,
        ..Twist::default()
    });
    let mut samples = Vec::with_capacity(20_000);
    let mut kept = 0.0;
    for i in 0..20_000u32 {
        let heading = f64::from(i % 360).to_radians();
        let pose = Pose {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            heading,
        };
        let velocity = Vec2::from_angle(heading) * 0.1;
        let start = Instant::now();
        let out = layer.filter(
            platform.as_ref(),
            &pose,
            velocity,
            &outputs,
            Duration::from_millis(50),
        );
        samples.push(start.elapsed().as_secs_f64() * 1e6);
        kept += out.outputs[0];
    }
    std::hint::black_box(kept);
    samples.sort_by(f64::total_cmp);
    let at = |q: f64| samples[((samples.len() - 1) as f64 * q) as usize];
    (at(0.5), at(0.99), samples[samples.len() - 1])
}

fn main() {
    println!("fleet safety in the demo arena (3.9 m x 2.8 m, margin 100 mm, radius 150 mm),");
    println!("50 Hz control, neighbour states at 10 Hz and 50 ms old, true poses;");
    println!("violations: control periods with a gap (robot to robot, robot to edge) more than");
    println!("1 mm under the margin; breaches: periods with a robot's disc across an edge\n");

    println!("two robots head-on at full speed, 10 s:");
    for (name, spec) in [
        ("diff-drive", PlatformSpec::diff_drive()),
        ("kiwi", PlatformSpec::kiwi()),
        ("quadcopter", PlatformSpec::quadcopter()),
    ] {
        for on in [true, false] {
            let mut t = trial(on);
            let a = t.add(
                &spec,
                Pose {
                    x: 0.6,
                    y: 1.4,
                    z: 0.0,
                    heading: 0.0,
                },
            );
            let b = t.add(
                &spec,
                Pose {
                    x: 3.3,
                    y: 1.4,
                    z: 0.0,
                    heading: std::f64::consts::PI,
                },
            );
            for i in [a, b] {
                t.command(i, &twist(spec.build().as_ref(), 1.0, 0.0, 0.0));
            }
            t.run_for(10.0);
            row(
                &format!("{name}, layer {}", if on { "on" } else { "off" }),
                &t.metrics(),
            );
        }
    }

    println!("\nten robots (diff-drive, kiwi, diff-drive, quadcopter...), random twists, 60 s:");
    for seed in 1..=5 {
        row(
            &format!("seed {seed}, layer on"),
            &random_twists(true, seed),
        );
        row(
            &format!("seed {seed}, layer off"),
            &random_twists(false, seed),
        );
    }

    println!("\neight robots swapping places across the centre on waypoint missions:");
    let off = crossing(false);
    let on = crossing(true);
    row("layer off", &off.metrics());
    row("layer on", &on.metrics());
    match (off.last_arrival(), on.last_arrival()) {
        (Some(a), Some(b)) => println!(
            "  all arrived: {a:.2} s without the layer, {b:.2} s with it ({:+.0}%)",
            (b / a - 1.0) * 100.0
        ),
        (a, b) => println!("  NOT ALL ARRIVED: without {a:?}, with {b:?}"),
    }

    println!(
        "\nthe crossing under other neighbour rates and latencies, each with places jittered by {JITTERS:?} rad:"
    );
    let mut within = (0, 0);
    let mut arrived = 0;
    let mut worst: f64 = 0.0;
    for (period, latency) in [
        (50, 25),
        (50, 50),
        (50, 75),
        (50, 100),
        (100, 20),
        (100, 50),
        (100, 100),
        (100, 150),
    ] {
        for stagger in [false, true] {
            let (p, l) = (
                Duration::from_millis(period),
                Duration::from_millis(latency),
            );
            let mut times = Vec::new();
            let mut min_gap = f64::INFINITY;
            let mut violations = 0;
            for jitter in JITTERS {
                let on = crossing_with(true, p, l, stagger, jitter);
                let off = crossing_with(false, p, l, stagger, jitter);
                let (alone, with) = (off.last_arrival(), on.last_arrival());
                let ok = matches!((alone, with), (Some(a), Some(b)) if b <= 2.0 * a);
                let m = on.metrics();
                min_gap = min_gap.min(m.min_gap);
                violations += m.separation_violations + m.margin_violations + m.breaches;
                within.1 += 1;
                within.0 += usize::from(ok);
                arrived += usize::from(with.is_some());
                let ratio = match (alone, with) {
                    (Some(a), Some(b)) => b / a,
                    _ => f64::INFINITY,
                };
                worst = worst.max(ratio);
                times.push(ratio);
            }
            println!(
                "  states every {period:>3} ms, {latency:>3} ms old, {:<9} time with / without, per jitter: {}  min gap {:>7.2} mm  violations {violations}",
                if stagger { "staggered" } else { "together" },
                times
                    .iter()
                    .map(|r| if r.is_finite() {
                        format!("{r:>5.2}")
                    } else {
                        "  jam".into()
                    })
                    .collect::<Vec<_>>()
                    .join(" "),
                min_gap * 1000.0,
            );
        }
    }
    println!(
        "  all arrived: {arrived} of {}; within twice the time: {} of {}; worst ratio {worst:.2}",
        within.1, within.0, within.1
    );

    println!("\nCPU per filter step (a robot driven into its neighbours; median / p99 / max, µs):");
    for (name, spec) in [
        ("diff-drive", PlatformSpec::diff_drive()),
        ("kiwi", PlatformSpec::kiwi()),
    ] {
        for n in [0, 10, 50] {
            let (p50, p99, max) = filter_cost(&spec, n);
            println!("  {name:<10} {n:>2} neighbours: {p50:>7.2} / {p99:>7.2} / {max:>7.2}");
        }
    }
}
