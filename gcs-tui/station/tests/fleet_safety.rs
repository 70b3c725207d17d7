//! Fleet safety through the real agent core and the real station: robots
//! simulated by `SimAgent` (the agent core on a simulated vehicle), each on
//! its own loopback socket; the station's router delivers the arena and
//! the commands of controllers that ignore each other and the walls; its
//! neighbour broadcaster tells each robot where the others are. Each
//! scenario runs again with every robot's layer switched off (the
//! operator's `safety off`) and must then show the accident it prevents,
//! so none can pass vacuously. Simulated time, paced by the wall clock
//! (see `support/fleet.rs`).

#![allow(clippy::unwrap_used)]

#[path = "support/fleet.rs"]
mod fleet;

use std::time::Duration;

use fleet::Rig;
use mech_agent::PlatformSpec;
use mech_agent::safety::SafetyConfig;
use mech_agent::sim::safety_trial::twist;
use mech_proto::Pose;

/// The arena's margin (the demo arena's), also kept between robots.
const MARGIN: f64 = 0.1;

fn pose(x: f64, y: f64, heading: f64) -> Pose {
    Pose {
        x,
        y,
        z: 0.0,
        heading,
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

/// Two robots of `spec` facing each other on one line, each driven at
/// full speed by its own controller on its own channel, for `seconds` (or,
/// with `until_contact`, until their discs touch).
async fn head_on(spec: &PlatformSpec, layer_on: bool, until_contact: bool) -> fleet::Metrics {
    let mut rig = Rig::new(layer_on).await;
    let a = rig.add(spec, pose(0.6, 1.4, 0.0)).await;
    let b = rig.add(spec, pose(3.3, 1.4, std::f64::consts::PI)).await;
    rig.settle().await;
    for i in [a, b] {
        rig.command(i, twist(spec.build().as_ref(), 1.0, 0.0, 0.0));
    }
    if until_contact {
        rig.until(|r| r.metrics().collisions > 0, "contact").await;
    } else {
        rig.run_for(6.0).await;
    }
    let m = rig.metrics();
    rig.shutdown().await;
    m
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_robots_driven_head_on_at_full_speed_on_two_channels_keep_their_distance() {
    for spec in [PlatformSpec::diff_drive(), PlatformSpec::kiwi()] {
        let on = head_on(&spec, true, false).await;
        println!("head-on {}: {on:?}", spec.build().name());
        assert!(on.min_gap >= MARGIN - 1e-3, "{spec:?}: {on:?}");
        assert_eq!(on.separation_violations, 0, "{spec:?}: {on:?}");
        assert_eq!(on.breaches + on.margin_violations, 0, "{spec:?}: {on:?}");
        let off = head_on(&spec, false, true).await;
        assert!(off.min_gap < 0.0, "without the layer they collide: {off:?}");
    }
}

/// SplitMix64, so a failure reproduces.
struct Rng(u64);

impl Rng {
    fn signed(&mut self) -> f64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        2.0 * (((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64) - 1.0
    }
}

/// Ten robots spread over the demo arena, each given a new random twist
/// (any direction, up to full speed) every second, for 60 s; with
/// `until_accidents`, only until both a collision and a breach happened.
async fn random_twists(layer_on: bool, until_accidents: bool) -> fleet::Metrics {
    let mut rig = Rig::new(layer_on).await;
    let arena = mech_agent::sim::Arena::default();
    let specs = platforms();
    for i in 0..10 {
        rig.add(&specs[i % 4], arena.start_pose(i, 10)).await;
    }
    rig.settle().await;
    let mut rng = Rng(1);
    for _ in 0..60 {
        for (i, spec) in specs.iter().cycle().take(10).enumerate() {
            let p = spec.build();
            let cmd = twist(p.as_ref(), rng.signed(), rng.signed(), rng.signed());
            rig.command(i, cmd);
        }
        rig.run_for(1.0).await;
        let m = rig.metrics();
        if until_accidents && m.collisions > 0 && m.breaches > 0 {
            break;
        }
    }
    let m = rig.metrics();
    rig.shutdown().await;
    m
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn ten_robots_under_random_twists_for_a_minute_never_touch_or_leave() {
    let on = random_twists(true, false).await;
    println!("random twists: {on:?}");
    assert_eq!(on.separation_violations, 0, "{on:?}");
    assert_eq!(on.margin_violations + on.breaches, 0, "{on:?}");
    let off = random_twists(false, true).await;
    assert!(
        off.collisions > 0 && off.breaches > 0,
        "without the layer they collide and leave: {off:?}"
    );
}

/// Eight robots on a circle around the arena's centre, each sent on a
/// mission to the point opposite: every path crosses every other. The
/// simulated time until the last arrived.
async fn crossing(layer_on: bool) -> (Option<f64>, fleet::Metrics) {
    crossing_with(layer_on, fleet::Options::default()).await
}

/// [`crossing`] with the robots sensing and moving as `options` say.
async fn crossing_with(layer_on: bool, options: fleet::Options) -> (Option<f64>, fleet::Metrics) {
    let mut rig = Rig::with(layer_on, options).await;
    let specs = platforms();
    let (cx, cy, r) = (1.95, 1.4, 1.05);
    let angle = |i: usize| i as f64 / 8.0 * std::f64::consts::TAU;
    for i in 0..8 {
        let a = angle(i);
        let start = pose(cx + r * a.cos(), cy + r * a.sin(), a + std::f64::consts::PI);
        rig.add(&specs[i % 4], start).await;
    }
    rig.settle().await;
    let start = rig.time();
    for i in 0..8 {
        let a = angle(i);
        rig.mission(i, (cx - r * a.cos(), cy - r * a.sin())).await;
    }
    for k in 0..60 {
        if rig.run_until_arrived(2.0).await {
            break;
        }
        if layer_on && (6..12).contains(&k) {
            println!("at {:?}:\n{}", rig.time() - start, rig.describe());
        }
    }
    let took = rig
        .last_arrival()
        .map(|t| t.saturating_sub(start).as_secs_f64());
    if layer_on {
        println!("the robots at the end:\n{}", rig.describe());
    }
    let m = rig.metrics();
    rig.shutdown().await;
    (took, m)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn eight_robots_crossing_on_missions_all_arrive_within_twice_the_time_and_apart() {
    let (alone, off) = crossing(false).await;
    let alone = alone.expect("without the layer every robot arrives");
    assert!(
        off.separation_violations > 0,
        "without the layer they drive through each other: {off:?}"
    );
    let (with, on) = crossing(true).await;
    println!("crossing: {with:?} s with the layer, {alone:.2} s without; {on:?}");
    let with = with.unwrap_or_else(|| panic!("not all arrived in 120 s: {on:?}"));
    assert!(
        with <= 2.0 * alone,
        "{with:.1} s with the layer, {alone:.1} s without"
    );
    assert_eq!(
        on.separation_violations + on.margin_violations + on.breaches,
        0,
        "{on:?}"
    );
}

/// The crossing on the demo's noisy positions (UWB-like fixes through the
/// median filter): each robot grows its disc by how far its estimate may
/// be off, so the margin holds between the true discs, which the robots
/// never see.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn eight_robots_crossing_on_noisy_positions_keep_the_margin_between_true_discs() {
    let (alone, off) = crossing_with(false, fleet::Options::noisy(1)).await;
    let alone = alone.expect("without the layer every robot arrives");
    assert!(off.separation_violations > 0, "{off:?}");
    let (with, on) = crossing_with(true, fleet::Options::noisy(1)).await;
    println!("noisy crossing: {with:?} s with the layer, {alone:.2} s without; {on:?}");
    assert!(
        on.max_estimate_error > 0.01,
        "the estimates were noisy: {on:?}"
    );
    let with = with.unwrap_or_else(|| panic!("not all arrived in 120 s: {on:?}"));
    assert!(on.min_gap >= MARGIN - 1e-3, "true discs: {on:?}");
    assert_eq!(
        on.separation_violations + on.margin_violations + on.breaches,
        0,
        "{on:?}"
    );
    assert!(
        with <= 2.5 * alone,
        "{with:.1} s with the layer, {alone:.1} s without"
    );
}

/// One robot driven straight at the wall at full speed.
async fn at_the_wall(spec: &PlatformSpec, layer_on: bool) -> (fleet::Metrics, f64, usize) {
    let mut rig = Rig::new(layer_on).await;
    let i = rig.add(spec, pose(1.0, 1.4, 0.0)).await;
    rig.settle().await;
    rig.command(i, twist(spec.build().as_ref(), 1.0, 0.0, 0.0));
    if layer_on {
        // Limited, then standing at the wall for a second (the slowest
        // platform takes about 6 s to get there).
        let stopped = move |r: &Rig| r.report(i).counts.total() > 0 && r.speed(i) < 1e-3;
        rig.until_steady(stopped, Duration::from_secs(1), "stopped at the wall")
            .await;
    } else {
        rig.until(|r| r.metrics().breaches > 0, "a breach").await;
    }
    let (m, speed) = (rig.metrics(), rig.speed(i));
    let notices = rig.safety_notices();
    rig.shutdown().await;
    (m, speed, notices)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_robot_driven_at_the_wall_stops_at_the_margin() {
    for spec in platforms()
        .into_iter()
        .take(2)
        .chain([PlatformSpec::quadcopter()])
    {
        let (m, speed, notices) = at_the_wall(&spec, true).await;
        println!("wall {}: {m:?}", spec.build().name());
        assert_eq!(m.margin_violations + m.breaches, 0, "{spec:?}: {m:?}");
        assert!(
            m.min_clearance < MARGIN + 0.02,
            "stops at the margin: {m:?}"
        );
        assert!(speed < 1e-3, "{spec:?} stopped: {speed}");
        assert!(notices >= 1, "the station was told");
        let (off, _, _) = at_the_wall(&spec, false).await;
        assert!(off.breaches > 0, "{spec:?} without the layer: {off:?}");
    }
}

/// The head-on pair (kiwis at 0.6 of full speed) with every neighbour list
/// to both lost after the first second.
async fn head_on_without_news(layer_on: bool) -> (fleet::Metrics, Vec<f64>) {
    let spec = PlatformSpec::kiwi();
    let mut rig = Rig::new(layer_on).await;
    let a = rig.add(&spec, pose(0.6, 1.4, 0.0)).await;
    let b = rig.add(&spec, pose(3.3, 1.4, std::f64::consts::PI)).await;
    rig.settle().await;
    for i in [a, b] {
        rig.command(i, twist(spec.build().as_ref(), 0.6, 0.0, 0.0));
    }
    rig.run_for(1.0).await;
    rig.drop_neighbours(a);
    rig.drop_neighbours(b);
    if layer_on {
        rig.run_for(10.0).await;
    } else {
        rig.until(|r| r.metrics().collisions > 0, "contact").await;
    }
    let speeds = vec![rig.speed(a), rig.speed(b)];
    let m = rig.metrics();
    rig.shutdown().await;
    (m, speeds)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn without_neighbour_messages_robots_slow_down_and_keep_apart() {
    let (m, speeds) = head_on_without_news(true).await;
    println!("no news: {m:?}");
    assert_eq!(m.separation_violations + m.margin_violations, 0, "{m:?}");
    assert!(m.max_stale_speed <= 0.05 + 1e-4, "crawling at most: {m:?}");
    assert!(speeds.iter().all(|s| *s <= 0.05 + 1e-4), "{speeds:?}");
    let (off, _) = head_on_without_news(false).await;
    assert!(off.min_gap < 0.0, "without the layer they collide: {off:?}");
}

/// The issue's reproduction, as a new user runs it: `mech-gcs --demo 2
/// --script` (the station core, the demo's simulated robots with their
/// position noise and the simulator's arena, the script language), robot_1
/// sent to (3.0, 0.85) and robot_2 to (0.3, 0.85), both routed to
/// `wp/gcs`; with `safety_off`, the operator switches both layers off
/// first. The script's JSON lines, and the closest the two robots' reported
/// centres came (every telemetry message of either, against the other's
/// latest), m.
async fn demo_two(safety_off: bool) -> (String, f64) {
    use std::sync::{Arc, Mutex};

    use mech_control::lang::Executor;
    use mech_control::script::{self, ScriptOutcome, Sink};
    use mech_core::event::Event;

    let mut config = mech_core::CoreConfig::default();
    config.router.udp = "127.0.0.1:0".parse().unwrap();
    config.router.tcp = None;
    let gcs = mech_core::Gcs::start(config).await.unwrap();
    let mut events = gcs.router().subscribe(4096, true);
    let closest = tokio::spawn(async move {
        let (mut one, mut two) = (None::<Pose>, None::<Pose>);
        let mut closest = f64::INFINITY;
        while let Some(e) = events.recv().await {
            if let Event::Telemetry { robot, telemetry } = &e.event {
                match robot.as_str() {
                    "robot_1" => one = Some(telemetry.pose),
                    "robot_2" => two = Some(telemetry.pose),
                    _ => {}
                }
                if let (Some(a), Some(b)) = (one, two) {
                    closest = closest.min((a.x - b.x).hypot(a.y - b.y));
                }
            }
        }
        closest
    });
    let mut executor = Executor::new(gcs.clone())
        .with_spawner(mech_station::sim::simulator())
        .with_source("script");
    executor.execute_line("spawn 2").await.unwrap();
    let off = if safety_off {
        "wait connected robot_1 10s\nwait connected robot_2 10s\n\
         safety off robot_1\nsafety off robot_2\n\
         wait safety robot_1 off 10s\nwait safety robot_2 off 10s\n"
    } else {
        ""
    };
    let source = format!(
        "wait connected robot_1 10s\nwait connected robot_2 10s\n{off}\
         waypoint robot_1 3.0,0.85\nsend robot_1\nroute robot_1 wp/gcs\n\
         waypoint robot_2 0.3,0.85\nsend robot_2\nroute robot_2 wp/gcs\n\
         wait arrived robot_1 120s\nwait arrived robot_2 120s\n"
    );
    let out = Arc::new(Mutex::new(Vec::<u8>::new()));
    let sink: Sink = Arc::new(Mutex::new(Box::new(SharedBuf(out.clone()))));
    let outcome = script::run(&gcs, &mut executor, &source, sink).await;
    executor.shutdown().await;
    gcs.shutdown().await;
    let closest = closest.await.unwrap();
    let printed = String::from_utf8(out.lock().unwrap().clone()).unwrap();
    assert!(
        matches!(outcome, ScriptOutcome::Passed { .. }),
        "{outcome:?}\n{printed}"
    );
    (printed, closest)
}

/// A writer into a buffer the test reads afterwards.
struct SharedBuf(std::sync::Arc<std::sync::Mutex<Vec<u8>>>);

impl std::io::Write for SharedBuf {
    fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(b);
        Ok(b.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_issues_reproduction_both_arrive_never_closer_than_the_bound() {
    // Two discs of the default radius and the arena's margin; the reported
    // centres are the agents' filtered estimates, each up to one
    // telemetry period older than the other's: a few centimetres of that
    // are the measurement, not the robots.
    let bound = 2.0 * SafetyConfig::default().radius + MARGIN;
    let (printed, closest) = demo_two(false).await;
    println!("demo 2 reproduction: closest {closest:.3} m, bound {bound:.3} m");
    assert!(closest >= bound - 0.05, "{closest:.3} m\n{printed}");
    assert!(
        printed.contains("\"arena\""),
        "the script shows the arena: {printed}"
    );
    let (_, off) = demo_two(true).await;
    println!("demo 2 reproduction, safety off: closest {off:.3} m");
    assert!(off < bound - 0.1, "without the layer they meet: {off:.3} m");
}
