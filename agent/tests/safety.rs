//! Fleet safety in simulation: robots driven by controllers that ignore
//! each other and the walls, kept apart and inside the arena by their
//! safety layers. Each scenario also runs with the layer switched off and
//! shows the accident it prevents, so none of these can pass vacuously.

use mech_agent::PlatformSpec;
use mech_agent::safety::SafetyConfig;
use mech_agent::sim::safety_trial::{SafetyTrial, demo_arena, twist};
use mech_proto::{Mission, Pose, Waypoint};

fn pose(x: f64, y: f64, heading: f64) -> Pose {
    Pose {
        x,
        y,
        z: 0.0,
        heading,
    }
}

const MARGIN: f64 = 0.1;

/// What a trial may fall short of the margin by and still count as kept:
/// a robot spinning fast while it creeps along a wall follows an arc, not
/// the straight braking path the filter predicts, and can end up to about
/// 0.3 mm inside the margin (see docs/safety.md).
const TOLERANCE: f64 = 1e-3;

fn trial(layer_on: bool) -> SafetyTrial {
    let mut t = SafetyTrial::new(demo_arena(), SafetyConfig::default(), layer_on);
    t.tolerance = TOLERANCE;
    t
}

/// Two robots on one line, facing each other, driven at full speed.
fn head_on(spec: &PlatformSpec, layer_on: bool) -> SafetyTrial {
    let mut t = trial(layer_on);
    let a = t.add(spec, pose(0.6, 1.4, 0.0));
    let b = t.add(spec, pose(3.3, 1.4, std::f64::consts::PI));
    for i in [a, b] {
        let full = twist(spec.build().as_ref(), 1.0, 0.0, 0.0);
        t.command(i, &full);
    }
    t.run_for(10.0);
    t
}

#[test]
fn two_robots_driven_head_on_at_full_speed_keep_their_distance() {
    for spec in [PlatformSpec::diff_drive(), PlatformSpec::kiwi()] {
        let on = head_on(&spec, true).metrics();
        assert!(on.min_gap >= MARGIN - TOLERANCE, "{spec:?}: {on:?}");
        assert_eq!(on.separation_violations, 0, "{spec:?}");
        assert_eq!(on.breaches + on.margin_violations, 0, "{spec:?}: {on:?}");
        let off = head_on(&spec, false).metrics();
        assert!(off.min_gap < 0.0, "without the layer they collide: {off:?}");
    }
}

/// SplitMix64: a tiny deterministic generator so a failure reproduces.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [-1, 1].
    fn signed(&mut self) -> f64 {
        2.0 * self.next() - 1.0
    }
}

/// The demo's platforms, cycled as `mech-gcs --demo` does.
fn platforms() -> [PlatformSpec; 4] {
    [
        PlatformSpec::diff_drive(),
        PlatformSpec::kiwi(),
        PlatformSpec::diff_drive(),
        PlatformSpec::quadcopter(),
    ]
}

/// Ten robots in the demo arena, each given a new random twist (any
/// direction, up to full speed) every second for 60 s.
fn random_twists(layer_on: bool, seed: u64) -> SafetyTrial {
    let mut t = trial(layer_on);
    let arena = mech_agent::sim::Arena::default();
    let specs = platforms();
    for i in 0..10 {
        t.add(&specs[i % specs.len()], arena.start_pose(i, 10));
    }
    let mut rng = Rng(seed);
    for _ in 0..60 {
        for i in 0..10 {
            let p = specs[i % specs.len()].build();
            let cmd = twist(p.as_ref(), rng.signed(), rng.signed(), rng.signed());
            t.command(i, &cmd);
        }
        t.run_for(1.0);
    }
    t
}

#[test]
fn ten_robots_under_random_twists_for_a_minute_never_touch_or_leave() {
    for seed in [1, 2] {
        let on = random_twists(true, seed).metrics();
        assert_eq!(on.separation_violations, 0, "seed {seed}: {on:?}");
        assert_eq!(on.margin_violations, 0, "seed {seed}: {on:?}");
        assert_eq!(on.breaches, 0, "seed {seed}: {on:?}");
        let off = random_twists(false, seed).metrics();
        assert!(
            off.separation_violations > 0 && off.breaches > 0,
            "without the layer they collide and leave: {off:?}"
        );
    }
}

/// Eight robots on a circle around the arena's centre, each sent to the
/// point opposite: every path crosses every other at the centre.
fn crossing(layer_on: bool, config: SafetyConfig) -> SafetyTrial {
    crossing_with(layer_on, config, |_| {})
}

/// The crossing, the trial set up by `setup` first (neighbour rate,
/// latency).
fn crossing_with(
    layer_on: bool,
    config: SafetyConfig,
    setup: impl Fn(&mut SafetyTrial),
) -> SafetyTrial {
    crossing_placed(layer_on, config, setup, 0.0, false)
}

/// Each robot's share of a jitter of the places on the circle (as in the
/// benchmark, `agent/examples/safety_bench.rs`).
const SHIFTS: [f64; 8] = [0.0, 0.5, -0.3, 0.8, -0.6, 0.2, -0.9, 0.4];

/// The crossing with each robot's place moved by `jitter` rad times its
/// share of [`SHIFTS`], and with `stagger`, the missions starting one
/// control period apart.
fn crossing_placed(
    layer_on: bool,
    config: SafetyConfig,
    setup: impl Fn(&mut SafetyTrial),
    jitter: f64,
    stagger: bool,
) -> SafetyTrial {
    let mut t = SafetyTrial::new(demo_arena(), config, layer_on);
    t.tolerance = TOLERANCE;
    setup(&mut t);
    let specs = platforms();
    let (cx, cy, r) = (1.95, 1.4, 1.05);
    for i in 0..8 {
        let a = i as f64 / 8.0 * std::f64::consts::TAU + jitter * SHIFTS[i];
        let start = pose(cx + r * a.cos(), cy + r * a.sin(), a + std::f64::consts::PI);
        let k = t.add(&specs[i % specs.len()], start);
        t.mission(
            k,
            Mission {
                id: 1,
                waypoints: vec![Waypoint {
                    x: cx - r * a.cos(),
                    y: cy - r * a.sin(),
                    z: 0.0,
                    time: None,
                }],
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

/// Every robot of `on` arrived within twice `alone` (s) and no
/// separation, margin or fence was violated; `case` names the run.
fn arrived_apart_within_twice(on: &SafetyTrial, alone: f64, case: &str) {
    let with = on.last_arrival().unwrap_or_else(|| {
        panic!(
            "{case}: deadlock, not all arrived in 120 s: {:?}",
            on.metrics()
        )
    });
    assert!(
        with <= 2.0 * alone,
        "{case}: {with:.1} s with the layer, {alone:.1} s without"
    );
    let m = on.metrics();
    assert_eq!(
        m.separation_violations + m.margin_violations + m.breaches,
        0,
        "{case}: {m:?}"
    );
}

#[test]
fn eight_robots_crossing_on_missions_all_arrive_apart_within_twice_the_time() {
    let off = crossing(false, SafetyConfig::default());
    let alone = off.last_arrival().expect("without the layer all arrive");
    assert!(
        off.metrics().separation_violations > 0,
        "without the layer they drive through each other: {:?}",
        off.metrics()
    );
    let on = crossing(true, SafetyConfig::default());
    arrived_apart_within_twice(&on, alone, "the crossing");
}

/// The crossing with neighbour states as the station's broadcaster sends
/// them by default (20 Hz) and nearly fresh, as on a loopback link, and
/// with the robots looking 2 s ahead instead of 1.5 s: the right-hand rule
/// judges the way each command heads for, recomputed every period, so how
/// far ahead it looks changes little (with timed yields, 2 s ahead and 2 s
/// of yielding jammed the eight in the middle, each turned away from a
/// neighbour that turned away from it).
#[test]
fn eight_robots_crossing_with_states_at_20_hz_all_arrive_within_twice_the_time() {
    let at_20_hz = |t: &mut SafetyTrial| {
        t.neighbour_period = std::time::Duration::from_millis(50);
        t.latency = std::time::Duration::from_millis(25);
    };
    let alone = crossing_with(false, SafetyConfig::default(), at_20_hz)
        .last_arrival()
        .expect("without the layer all arrive");
    let on = crossing_with(true, SafetyConfig::default(), at_20_hz);
    arrived_apart_within_twice(&on, alone, "states at 20 Hz");
    let far = SafetyConfig {
        horizon: 2.0,
        ..SafetyConfig::default()
    };
    let on = crossing_with(true, far, at_20_hz);
    arrived_apart_within_twice(&on, alone, "states at 20 Hz, 2 s ahead");
}

/// Deadlock breaking: the crossing with neighbour states at eight rates
/// and ages: every robot arrives, apart, within twice the time without the
/// layer, and so it does without backing off (`stuck_after = 0`): the
/// right-hand rule, judged from where each command heads
/// (`safety::circulation`), clears the crossing on its own. (Judged from
/// the diff-drives' headings, with timed yields, robots stayed jammed in
/// the middle without backing off in some of these timings.)
#[test]
fn the_right_hand_rule_alone_clears_every_crossing() {
    let timings = [
        (50, 25),
        (50, 50),
        (50, 75),
        (50, 100),
        (100, 20),
        (100, 50),
        (100, 100),
        (100, 150),
    ];
    let never = SafetyConfig {
        stuck_after: 0.0,
        ..SafetyConfig::default()
    };
    for (period, latency) in timings {
        let timing = |t: &mut SafetyTrial| {
            t.neighbour_period = std::time::Duration::from_millis(period);
            t.latency = std::time::Duration::from_millis(latency);
        };
        let alone = crossing_with(false, SafetyConfig::default(), timing)
            .last_arrival()
            .expect("without the layer all arrive");
        let on = crossing_with(true, SafetyConfig::default(), timing);
        let case = format!("states every {period} ms, {latency} ms old");
        arrived_apart_within_twice(&on, alone, &case);
        let rule_alone = crossing_with(true, never, timing);
        arrived_apart_within_twice(&rule_alone, alone, &format!("{case}, never backing off"));
    }
}

/// A diff-drive whose way runs past a robot already standing at its goal
/// by the arena's edge: the right-hand rule turns it right of that robot's
/// disc, which, pressed at exactly the distance it must keep, leads into
/// the edge of its cell; it follows the edge instead (Zhou et al.'s rule,
/// `along_cell_edge`). In these three jittered crossings (places moved by
/// 0.2 rad, missions staggered) a diff-drive turned on the spot there for
/// good without that.
#[test]
fn a_robot_pressed_against_a_standing_one_goes_round_it_along_its_cell() {
    for (period, latency) in [(100, 20), (50, 75), (100, 100)] {
        let timing = |t: &mut SafetyTrial| {
            t.neighbour_period = std::time::Duration::from_millis(period);
            t.latency = std::time::Duration::from_millis(latency);
        };
        let alone = crossing_placed(false, SafetyConfig::default(), timing, 0.2, true)
            .last_arrival()
            .expect("without the layer all arrive");
        let on = crossing_placed(true, SafetyConfig::default(), timing, 0.2, true);
        let case = format!("jittered, staggered, states every {period} ms, {latency} ms old");
        arrived_apart_within_twice(&on, alone, &case);
    }
}

/// One robot driven straight at the wall at full speed for 10 s.
fn at_the_wall(spec: &PlatformSpec, layer_on: bool) -> SafetyTrial {
    let mut t = trial(layer_on);
    let i = t.add(spec, pose(1.0, 1.4, 0.0));
    t.command(i, &twist(spec.build().as_ref(), 1.0, 0.0, 0.0));
    t.run_for(10.0);
    t
}

#[test]
fn a_robot_driven_at_the_wall_stops_at_the_margin() {
    for spec in platforms() {
        let t = at_the_wall(&spec, true);
        let m = t.metrics();
        assert_eq!(m.margin_violations + m.breaches, 0, "{spec:?}: {m:?}");
        // It stops at the margin, not short of it: within 2 cm.
        assert!(m.min_clearance < MARGIN + 0.02, "{spec:?}: {m:?}");
        assert!(t.robots[0].velocity().norm() < 1e-3, "stopped");
        let off = at_the_wall(&spec, false).metrics();
        assert!(off.breaches > 0, "{spec:?} without the layer: {off:?}");
    }
}

/// Every way of commanding a robot at the wall, at full speed: raw
/// actuator outputs, steering-throttle, velocity-heading, twist and an
/// onboard mission to a point beyond the wall.
fn every_mode(spec: &PlatformSpec, layer_on: bool) -> Vec<(&'static str, SafetyTrial)> {
    use mech_proto::{Actuators, Command, SteeringThrottle, VelocityHeading};
    let platform = spec.build();
    let full = platform.mix(&mech_proto::Twist {
        vx: platform.limits().max_speed,
        ..mech_proto::Twist::default()
    });
    let mut commands = vec![
        ("actuators", Command::Actuators(Actuators { outputs: full })),
        (
            "velocity-heading",
            Command::VelocityHeading(VelocityHeading {
                speed: platform.limits().max_speed,
                heading: 0.0,
            }),
        ),
        ("twist", twist(platform.as_ref(), 1.0, 0.0, 0.0)),
    ];
    if platform
        .capabilities()
        .contains(&mech_proto::CommandKind::SteeringThrottle)
    {
        commands.push((
            "steering-throttle",
            Command::SteeringThrottle(SteeringThrottle {
                steering: 0.0,
                throttle: 1.0,
            }),
        ));
    }
    let mut runs: Vec<(&'static str, SafetyTrial)> = commands
        .into_iter()
        .map(|(name, cmd)| {
            let mut t = trial(layer_on);
            let i = t.add(spec, pose(1.0, 1.4, 0.0));
            t.command(i, &cmd);
            t.run_for(10.0);
            (name, t)
        })
        .collect();
    let mut t = trial(layer_on);
    let i = t.add(spec, pose(1.0, 1.4, 0.0));
    let beyond = Waypoint {
        x: 5.0,
        y: 1.4,
        z: 0.0,
        time: None,
    };
    t.mission(
        i,
        Mission {
            id: 1,
            waypoints: vec![beyond],
            looped: false,
            arrival_radius: 0.05,
            start_index: 0,
        },
    );
    t.run_for(15.0);
    runs.push(("mission", t));
    runs
}

#[test]
fn every_command_mode_is_limited_alike() {
    for spec in platforms() {
        for (mode, t) in every_mode(&spec, true) {
            let m = t.metrics();
            assert_eq!(
                m.margin_violations + m.breaches,
                0,
                "{spec:?} {mode}: {m:?}"
            );
            assert!(
                m.min_clearance < MARGIN + 0.05,
                "{spec:?} {mode} got there: {m:?}"
            );
        }
        for (mode, t) in every_mode(&spec, false) {
            assert!(
                t.metrics().breaches > 0,
                "{spec:?} {mode} without the layer"
            );
        }
    }
}

/// The head-on run with the station's neighbour messages lost after the
/// first second.
fn head_on_without_news(layer_on: bool) -> SafetyTrial {
    let spec = PlatformSpec::kiwi();
    let mut t = trial(layer_on);
    t.neighbours_until = Some(std::time::Duration::from_secs(1));
    let a = t.add(&spec, pose(0.6, 1.4, 0.0));
    let b = t.add(&spec, pose(3.3, 1.4, std::f64::consts::PI));
    for i in [a, b] {
        t.command(i, &twist(spec.build().as_ref(), 0.6, 0.0, 0.0));
    }
    t.run_for(15.0);
    t
}

#[test]
fn without_neighbour_messages_robots_crawl_and_still_keep_apart() {
    let t = head_on_without_news(true);
    let m = t.metrics();
    assert_eq!(m.separation_violations + m.margin_violations, 0, "{m:?}");
    // Stale from 1.3 s on: once slowed down, no faster than the crawl.
    assert!(m.max_stale_speed <= 0.05 + 1e-6, "{m:?}");
    for r in &t.robots {
        assert!(r.velocity().norm() <= 0.05 + 1e-6, "crawling at the end");
    }
    let off = head_on_without_news(false).metrics();
    assert!(off.min_gap < 0.0, "without the layer they collide: {off:?}");
}

mod properties {
    //! Property tests of the filter itself: whatever the state and the
    //! command, the stopping point it allows is inside the fence; and two
    //! robots head-on, whatever their speeds and platforms, keep apart.

    use std::time::Duration;

    use mech_agent::PlatformSpec;
    use mech_agent::safety::{Fence, SafetyConfig, SafetyLayer, Vec2};
    use mech_agent::sim::safety_trial::{SafetyTrial, demo_arena};
    use mech_proto::{Arena, Command, Neighbours, Point, Pose, Twist};
    use proptest::prelude::*;

    fn spec(k: usize) -> PlatformSpec {
        [
            PlatformSpec::diff_drive(),
            PlatformSpec::kiwi(),
            PlatformSpec::quadcopter(),
        ][k % 3]
            .clone()
    }

    /// A 4 m x 3 m arena with a keep-out box somewhere inside.
    fn arena(kx: f64, ky: f64, kw: f64, kh: f64) -> Arena {
        let p = |x, y| Point { x, y };
        Arena {
            robot: "robot_1".into(),
            id: 1,
            enabled: true,
            boundary: vec![p(0.0, 0.0), p(4.0, 0.0), p(4.0, 3.0), p(0.0, 3.0)],
            keep_out: vec![vec![
                p(kx, ky),
                p(kx + kw, ky),
                p(kx + kw, ky + kh),
                p(kx, ky + kh),
            ]],
            slow_zones: vec![],
            margin: 0.1,
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig {
            cases: 2000,
            max_global_rejects: 50_000,
            ..ProptestConfig::default()
        })]

        #[test]
        fn the_stopping_point_allowed_is_never_outside_the_fence(
            platform in 0..3usize,
            (x, y, heading) in (0.0..4.0f64, 0.0..3.0f64, -3.2..3.2f64),
            (kx, ky, kw, kh) in (0.5..3.0f64, 0.5..2.0f64, 0.1..1.0f64, 0.1..1.0f64),
            (vx, vy, wz) in (-1.0..1.0f64, -1.0..1.0f64, -1.0..1.0f64),
            (cvx, cvy) in (-1.0..1.0f64, -1.0..1.0f64),
        ) {
            let arena = arena(kx, ky, kw, kh);
            let fence = Fence::from_arena(&arena);
            let config = SafetyConfig::default();
            let p = Vec2::new(x, y);
            prop_assume!(fence.clear(p, config.radius));
            let spec = spec(platform);
            let platform = spec.build();
            let l = platform.limits();
            let twist = Twist {
                vx: vx * l.max_speed,
                vy: if platform.holonomic() { vy * l.max_speed } else { 0.0 },
                vz: 0.0,
                wz: wz * l.max_yaw_rate,
            };
            let outputs = platform.mix(&twist);
            let mut layer = SafetyLayer::new(config);
            layer.apply_arena(&arena);
            layer.apply_neighbours(
                &Neighbours { robot: "robot_1".into(), stamp_us: 1, robots: vec![], obstacles: vec![] },
                Duration::ZERO,
            );
            let pose = Pose { x, y, z: 0.0, heading };
            let now_velocity = Vec2::new(cvx, cvy) * l.max_speed;
            let out = layer.filter(platform.as_ref(), &pose, now_velocity, &outputs, Duration::ZERO);
            let motion = platform.motion(&out.outputs);
            let u = Vec2::new(motion.vx, motion.vy).rotated(heading);
            let length = config.braking().distance(u.norm());
            if let Some(dir) = u.unit() {
                for k in 0..=50 {
                    let q = p + dir * (length * k as f64 / 50.0);
                    prop_assert!(
                        fence.clear(q, config.radius - 1e-9),
                        "stopping path leaves the fence at {q:?} (from {p:?}, u {u:?}, {:?})",
                        out.intervention
                    );
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]

        #[test]
        fn two_robots_head_on_never_come_closer_than_the_bound(
            (a, b) in (0..3usize, 0..3usize),
            (speed_a, speed_b) in (0.3..1.0f64, 0.3..1.0f64),
            gap in 0.5..2.5f64,
            offset in -0.2..0.2f64,
            latency_ms in 0..150u64,
        ) {
            let mut t = SafetyTrial::new(demo_arena(), SafetyConfig::default(), true);
            t.tolerance = 1e-3;
            t.latency = Duration::from_millis(latency_ms);
            let (sa, sb) = (spec(a), spec(b));
            let x0 = 1.95 - gap / 2.0;
            let i = t.add(&sa, Pose { x: x0, y: 1.4, z: 0.0, heading: 0.0 });
            let j = t.add(&sb, Pose { x: x0 + gap, y: 1.4 + offset, z: 0.0, heading: std::f64::consts::PI });
            for (k, s, speed) in [(i, &sa, speed_a), (j, &sb, speed_b)] {
                let max = s.build().limits().max_speed;
                t.command(k, &Command::Twist(Twist { vx: speed * max, ..Twist::default() }));
            }
            t.run_for(6.0);
            let m = t.metrics();
            prop_assert!(m.min_gap >= 0.1 - 1e-3, "{m:?}");
            prop_assert_eq!(m.margin_violations + m.breaches, 0, "{:?}", m);
        }
    }
}

/// A diff-drive driven backwards at full speed towards one standing behind
/// it, on one line.
fn reversing_into_a_neighbour(layer_on: bool) -> SafetyTrial {
    let spec = PlatformSpec::diff_drive();
    let mut t = trial(layer_on);
    let reversing = t.add(&spec, pose(2.6, 1.4, 0.0));
    t.add(&spec, pose(1.4, 1.4, 0.0));
    t.command(reversing, &twist(spec.build().as_ref(), -1.0, 0.0, 0.0));
    t.run_for(4.0);
    t
}

#[test]
fn a_diff_drive_reversing_into_a_neighbour_passes_it_backwards_on_the_right_of_its_travel() {
    let t = reversing_into_a_neighbour(true);
    let on = t.metrics();
    assert!(on.min_gap >= MARGIN - TOLERANCE, "{on:?}");
    assert_eq!(on.separation_violations + on.breaches, 0, "{on:?}");
    // Travelling west, its right is north: it passed the other robot
    // there, still reversing (facing east, give or take its swerve).
    let p = t.robots[0].sim.pose();
    assert!(p.x < 1.4 && p.y > 1.4 + 0.2, "passed on the right: {p:?}");
    assert!(p.heading.cos() > 0.5, "still facing east: {p:?}");
    let off = reversing_into_a_neighbour(false).metrics();
    assert!(off.min_gap < 0.0, "without the layer they collide: {off:?}");
}
