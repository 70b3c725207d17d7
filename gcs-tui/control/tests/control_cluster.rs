//! Cluster-space control in stepped-time simulation: a mixed cluster of
//! differential-drive and kiwi robots driving a square of cluster waypoints, a
//! formation change while moving, velocity driving with rotation and scaling,
//! and the safety rules (lost telemetry, member routed away).

#![allow(clippy::unwrap_used)]

#[path = "control_support/bench.rs"]
mod bench;

use std::f64::consts::FRAC_PI_2;

use bench::{Bench, pose};
use mech_agent::platform::PlatformSpec;
use mech_control::{
    ClusterConfig, ClusterController, ClusterOutput, ClusterWaypoint, ControlEvent, assign_slots,
    total_distance,
};
use mech_proto::{ClusterVelocity, FailsafeState, Formation, FormationKind};
use std::time::Duration;

const PERIOD: f64 = 0.05;
const CHANNEL: &str = "fleet/c1";

fn mixed_fleet() -> Bench {
    Bench::new(
        &[
            ("robot_1", PlatformSpec::diff_drive(), pose(-0.5, 0.4, 0.3)),
            ("robot_2", PlatformSpec::kiwi(), pose(0.6, 0.5, -1.0)),
            ("robot_3", PlatformSpec::diff_drive(), pose(-0.4, -0.6, 2.0)),
            ("robot_4", PlatformSpec::kiwi(), pose(0.5, -0.3, 0.5)),
        ],
        CHANNEL,
    )
}

fn names() -> Vec<String> {
    (1..=4).map(|i| format!("robot_{i}")).collect()
}

fn formation(kind: FormationKind, spacing: f64) -> Formation {
    Formation {
        kind,
        spacing,
        offsets: vec![],
    }
}

/// One control period: controller step on the received telemetry, commands
/// delivered, robots advanced.
fn tick(world: &mut Bench, cluster: &mut ClusterController) -> ClusterOutput {
    let out = cluster.step(world.now_s(), &world.states());
    world.fleet(CHANNEL, &out.commands);
    world.advance(Duration::from_secs_f64(PERIOD));
    out
}

fn ticks(seconds: f64) -> usize {
    (seconds / PERIOD).round() as usize
}

fn rms(errors: &[f64]) -> f64 {
    (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt()
}

/// Slot tracking errors over one cluster square: (max, RMS) against the
/// reported positions (what the controller sees) and against the true ones.
struct SquareRun {
    reported: (f64, f64),
    truth: (f64, f64),
    per_platform: [(f64, f64); 2],
    samples: usize,
    seconds: f64,
}

/// Four robots of two platforms gathered into a circle; the cluster pose
/// they gathered at.
fn gathered(noise: bool) -> (Bench, ClusterController, mech_proto::ClusterPose) {
    let mut world = Bench::with_noise(
        &[
            ("robot_1", PlatformSpec::diff_drive(), pose(-0.5, 0.4, 0.3)),
            ("robot_2", PlatformSpec::kiwi(), pose(0.6, 0.5, -1.0)),
            ("robot_3", PlatformSpec::diff_drive(), pose(-0.4, -0.6, 2.0)),
            ("robot_4", PlatformSpec::kiwi(), pose(0.5, -0.3, 0.5)),
        ],
        CHANNEL,
        noise,
    );
    let mut cluster = ClusterController::new(
        "c1",
        names(),
        formation(FormationKind::Circle, 0.8),
        ClusterConfig::default(),
    )
    .unwrap();
    for _ in 0..ticks(8.0) {
        tick(&mut world, &mut cluster);
    }
    let start = tick(&mut world, &mut cluster).status.desired.unwrap();
    let gathered = tick(&mut world, &mut cluster).status.max_error();
    assert!(
        gathered < if noise { 0.1 } else { 0.05 },
        "gathered into slots: {gathered:.3} m"
    );
    (world, cluster, start)
}

/// Slot errors sampled along a run.
#[derive(Default)]
struct SlotErrors {
    /// Against the reported positions (what the controller sees).
    reported: Vec<f64>,
    /// Against the true positions.
    truth: Vec<f64>,
    /// Against the true positions, diff-drive then kiwi.
    per_platform: [Vec<f64>; 2],
}

impl SlotErrors {
    /// One period's slots, with the members' true poses when they were
    /// computed.
    fn sample(&mut self, poses: &[(String, mech_proto::Pose)], slots: &[mech_control::SlotTarget]) {
        for s in slots {
            self.reported.push(s.error);
            let p = poses.iter().find(|(n, _)| *n == s.robot).unwrap().1;
            let e = (p.x - s.x).hypot(p.y - s.y);
            self.truth.push(e);
            let diff = s.robot == "robot_1" || s.robot == "robot_3";
            self.per_platform[usize::from(!diff)].push(e);
        }
    }
}

fn drive_square(noise: bool) -> SquareRun {
    let (mut world, mut cluster, start) = gathered(noise);
    let side = 3.0;
    let corners = [
        (start.x + side, start.y, Some(FRAC_PI_2)),
        (start.x + side, start.y + side, Some(FRAC_PI_2 * 2.0)),
        (start.x, start.y + side, Some(-FRAC_PI_2)),
        (start.x, start.y, Some(0.0)),
    ];
    cluster.set_waypoints(
        corners
            .iter()
            .map(|&(x, y, heading)| ClusterWaypoint { x, y, heading })
            .collect(),
        false,
    );
    let mut errors = SlotErrors::default();
    let mut reached = Vec::new();
    let mut finished = false;
    let t0 = world.now_s();
    for _ in 0..ticks(200.0) {
        // True poses at the instant the slots are computed.
        let poses: Vec<_> = names()
            .iter()
            .map(|n| (n.clone(), world.true_pose(n)))
            .collect();
        let out = tick(&mut world, &mut cluster);
        assert_eq!(out.commands.len(), 4, "every member commanded");
        errors.sample(&poses, &out.status.slots);
        for e in &out.events {
            match e {
                ControlEvent::WaypointReached { index } => reached.push(*index),
                ControlEvent::Finished => finished = true,
                _ => {}
            }
        }
        if finished {
            break;
        }
    }
    assert!(finished, "square completed; reached {reached:?}");
    assert_eq!(
        reached,
        vec![0, 1, 2, 3],
        "cluster waypoints in order, none repeated"
    );
    let end = cluster.step(world.now_s(), &world.states()).status;
    let measured = end.measured.unwrap();
    assert!(
        (measured.x - start.x).hypot(measured.y - start.y) < 0.1,
        "back at the start"
    );
    let stats = |e: &[f64]| (e.iter().copied().fold(0.0, f64::max), rms(e));
    SquareRun {
        reported: stats(&errors.reported),
        truth: stats(&errors.truth),
        per_platform: [
            stats(&errors.per_platform[0]),
            stats(&errors.per_platform[1]),
        ],
        samples: errors.reported.len(),
        seconds: world.now_s() - t0,
    }
}

fn print_square(label: &str, r: &SquareRun) {
    println!(
        "{label}: 3 m square in {:.1} s, {} samples; slot error vs reported position max {:.3} m RMS {:.3} m; \
         vs true position max {:.3} m RMS {:.3} m (diff-drive max {:.3} RMS {:.3}; kiwi max {:.3} RMS {:.3})",
        r.seconds,
        r.samples,
        r.reported.0,
        r.reported.1,
        r.truth.0,
        r.truth.1,
        r.per_platform[0].0,
        r.per_platform[0].1,
        r.per_platform[1].0,
        r.per_platform[1].1,
    );
}

#[test]
fn mixed_cluster_drives_a_square_within_tracking_error() {
    let r = drive_square(false);
    print_square("exact positions", &r);
    assert!(
        r.reported.0 <= 0.15,
        "max slot error {:.3} m exceeds 0.15 m",
        r.reported.0
    );
    assert!(
        r.reported.1 <= 0.03,
        "RMS slot error {:.3} m exceeds 0.03 m",
        r.reported.1
    );
    assert!(r.truth.0 <= 0.15 && r.truth.1 <= 0.04);
}

#[test]
fn mixed_cluster_drives_a_square_with_uwb_like_position_noise() {
    let r = drive_square(true);
    print_square("UWB-like noise", &r);
    assert!(
        r.truth.0 <= 0.2,
        "max true slot error {:.3} m exceeds 0.2 m",
        r.truth.0
    );
    assert!(
        r.truth.1 <= 0.05,
        "RMS true slot error {:.3} m exceeds 0.05 m",
        r.truth.1
    );
}

#[test]
fn formation_change_while_moving_converges_without_crossing() {
    let mut world = mixed_fleet();
    let mut cluster = ClusterController::new(
        "c1",
        names(),
        formation(FormationKind::Line, 0.9),
        ClusterConfig::default(),
    )
    .unwrap();
    for _ in 0..ticks(8.0) {
        tick(&mut world, &mut cluster);
    }
    cluster.set_velocity(ClusterVelocity {
        vx: 0.15,
        vy: 0.05,
        wz: 0.0,
        scale_rate: 0.0,
    });
    for _ in 0..ticks(4.0) {
        tick(&mut world, &mut cluster);
    }
    assert!(
        tick(&mut world, &mut cluster).status.max_error() < 0.1,
        "line held while moving"
    );

    let before: Vec<(f64, f64)> = world
        .states()
        .iter()
        .map(|s| (s.pose.x, s.pose.y))
        .collect();
    cluster
        .set_formation(formation(FormationKind::Wedge, 0.9))
        .unwrap();
    let first = tick(&mut world, &mut cluster);
    // Paths from where members were to the new slots they were given.
    let slots: Vec<(f64, f64)> = world
        .states()
        .iter()
        .map(|s| {
            let t = first
                .status
                .slots
                .iter()
                .find(|t| t.robot == s.robot)
                .unwrap();
            (t.x, t.y)
        })
        .collect();
    let given: Vec<usize> = (0..4).collect();
    let optimal = assign_slots(&before, &slots);
    assert!(
        (total_distance(&before, &slots, &given) - total_distance(&before, &slots, &optimal)).abs()
            < 0.05,
        "slots re-assigned to minimise distance travelled"
    );

    let mut converged_at = None;
    for i in 0..ticks(20.0) {
        let out = tick(&mut world, &mut cluster);
        if out.status.max_error() < 0.05 && converged_at.is_none() {
            converged_at = Some(i as f64 * PERIOD);
        }
        if converged_at.is_some() {
            assert!(out.status.max_error() < 0.1, "stays converged");
        }
    }
    let t = converged_at.expect("wedge converged within 20 s");
    println!("line -> wedge while moving: all members within 0.05 m of their slots after {t:.2} s");
}

#[test]
fn velocity_drive_rotates_and_scales_the_cluster() {
    let mut world = mixed_fleet();
    let mut cluster = ClusterController::new(
        "c1",
        names(),
        formation(FormationKind::Circle, 0.8),
        ClusterConfig::default(),
    )
    .unwrap();
    for _ in 0..ticks(8.0) {
        tick(&mut world, &mut cluster);
    }
    let start = tick(&mut world, &mut cluster).status.desired.unwrap();
    cluster.set_velocity(ClusterVelocity {
        vx: 0.1,
        vy: 0.0,
        wz: 0.1,
        scale_rate: 0.03,
    });
    let mut worst = 0.0f64;
    for _ in 0..ticks(10.0) {
        let out = tick(&mut world, &mut cluster);
        worst = worst.max(out.status.max_error());
    }
    cluster.hold();
    for _ in 0..ticks(3.0) {
        tick(&mut world, &mut cluster);
    }
    let status = cluster.step(world.now_s(), &world.states()).status;
    let desired = status.desired.unwrap();
    let measured = status.measured.unwrap();
    println!(
        "velocity drive: worst slot error {worst:.3} m; heading {:.3} rad (desired {:.3}), \
         scale {:.3} (desired {:.3})",
        measured.heading, desired.heading, measured.scale, desired.scale
    );
    assert!(
        (desired.heading - start.heading - 1.0).abs() < 1e-6,
        "turned 0.1 rad/s for 10 s"
    );
    assert!((desired.scale - 1.3).abs() < 1e-6, "grew 0.03/s for 10 s");
    assert!((measured.heading - desired.heading).abs() < 0.05);
    assert!((measured.scale - desired.scale).abs() < 0.05);
    assert!((measured.x - desired.x).hypot(measured.y - desired.y) < 0.05);
    assert!(worst < 0.2, "slot error while moving {worst:.3} m");
}

#[test]
fn member_with_stale_telemetry_is_not_commanded_and_its_failsafe_stops_it() {
    let mut world = mixed_fleet();
    let config = ClusterConfig::default();
    let timeout = config.telemetry_timeout;
    let mut cluster =
        ClusterController::new("c1", names(), formation(FormationKind::Column, 0.8), config)
            .unwrap();
    cluster.set_velocity(ClusterVelocity {
        vx: 0.2,
        vy: 0.0,
        wz: 0.0,
        scale_rate: 0.0,
    });
    for _ in 0..ticks(6.0) {
        tick(&mut world, &mut cluster);
    }
    assert!(
        world.speed("robot_3") > 0.1,
        "robot_3 moving with the cluster"
    );

    world.silence("robot_3", true);
    let silent_since = world.now_s();
    let mut lost_at = None;
    let mut last_command_to_3 = silent_since;
    for _ in 0..ticks(3.0) {
        let now = world.now_s();
        let out = tick(&mut world, &mut cluster);
        if out.commands.iter().any(|c| c.robot == "robot_3") {
            last_command_to_3 = now;
        }
        if out.events.contains(&ControlEvent::MemberLost {
            robot: "robot_3".into(),
        }) {
            lost_at = Some(now);
            assert_eq!(out.status.lost, vec!["robot_3".to_string()]);
            assert!(out.status.slots.iter().all(|s| s.robot != "robot_3"));
        }
        assert!(out.commands.len() >= 3, "the others stay commanded");
    }
    let lost_at = lost_at.expect("robot_3 reported lost");
    assert!(
        lost_at - silent_since <= timeout + PERIOD + 1e-9,
        "lost within timeout + one period"
    );
    assert!(
        last_command_to_3 < lost_at,
        "no command after it was declared lost"
    );
    assert_eq!(world.failsafe("robot_3"), FailsafeState::ChannelSilent);
    assert!(world.speed("robot_3") < 1e-3, "its failsafe stopped it");
    assert!(world.speed("robot_1") > 0.1, "the others keep moving");

    world.silence("robot_3", false);
    let out = tick(&mut world, &mut cluster);
    let out = if out.commands.iter().any(|c| c.robot == "robot_3") {
        out
    } else {
        tick(&mut world, &mut cluster)
    };
    assert!(
        out.commands.iter().any(|c| c.robot == "robot_3"),
        "commanded again once it reports"
    );
}

#[test]
fn member_routed_away_is_dropped_from_outputs_at_once() {
    let mut world = mixed_fleet();
    let mut cluster = ClusterController::new(
        "c1",
        names(),
        formation(FormationKind::Wedge, 0.8),
        ClusterConfig::default(),
    )
    .unwrap();
    cluster.set_velocity(ClusterVelocity {
        vx: 0.1,
        vy: 0.0,
        wz: 0.0,
        scale_rate: 0.0,
    });
    for _ in 0..20 {
        tick(&mut world, &mut cluster);
    }
    // The router no longer routes robot_2 to the cluster's channel: its state is
    // not part of the next step's input.
    let states: Vec<_> = world
        .states()
        .into_iter()
        .filter(|s| s.robot != "robot_2")
        .collect();
    let out = cluster.step(world.now_s(), &states);
    assert_eq!(out.commands.len(), 3);
    assert!(out.commands.iter().all(|c| c.robot != "robot_2"));
    assert_eq!(out.status.absent, vec!["robot_2".to_string()]);
    assert_eq!(
        out.status.slots.len(),
        3,
        "formation re-laid over the members still routed"
    );

    cluster.remove_member("robot_4");
    let out = cluster.step(world.now_s() + PERIOD, &world.states());
    assert!(out.commands.iter().all(|c| c.robot != "robot_4"));
    assert_eq!(out.commands.len(), 3);
    assert_eq!(out.fleet_command().parts.len(), 3);
}

#[test]
fn members_joining_one_by_one_recentre_a_cluster_that_has_not_moved() {
    let mut world = mixed_fleet();
    let mut cluster = ClusterController::new(
        "c1",
        names(),
        formation(FormationKind::Circle, 0.7),
        ClusterConfig::default(),
    )
    .unwrap();
    let states = world.states();
    let first = cluster.step(world.now_s(), &states[..1]);
    let d = first.status.desired.unwrap();
    assert!(
        (d.x - states[0].pose.x).abs() < 1e-9,
        "one member: the cluster is where it is"
    );
    world.advance(Duration::from_secs_f64(PERIOD));
    let states = world.states();
    let all = cluster.step(world.now_s(), &states);
    let d = all.status.desired.unwrap();
    let cx = states.iter().map(|s| s.pose.x).sum::<f64>() / 4.0;
    let cy = states.iter().map(|s| s.pose.y).sum::<f64>() / 4.0;
    assert!(
        (d.x - cx).hypot(d.y - cy) < 1e-9,
        "re-centred on all four members"
    );
    // Once moving, joining members no longer move the cluster pose.
    cluster.set_velocity(ClusterVelocity {
        vx: 0.1,
        vy: 0.0,
        wz: 0.0,
        scale_rate: 0.0,
    });
    let moving = cluster
        .step(world.now_s() + PERIOD, &states[..3])
        .status
        .desired
        .unwrap();
    assert!(
        (moving.x - d.x).hypot(moving.y - d.y) <= 0.1 * PERIOD + 1e-9,
        "not re-centred on the three members left"
    );
}
