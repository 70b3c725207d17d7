//! Fleet control through the real router with simulated agents (the agent
//! core over UDP on loopback): a mixed cluster runs cluster waypoints from the
//! command language, a member routed away is dropped at once, a follower
//! keeps its offset, and a robot switches onboard -> offboard -> onboard
//! mid-mission and finishes it.

#![allow(clippy::unwrap_used)]

use std::time::Duration;

use mech_agent::platform::PlatformSpec;
use mech_agent::sim::{Arena, SimFleet, SimFleetOptions};
use mech_control::ClusterSpec;
use mech_control::lang::Executor;
use mech_core::{CoreConfig, Gcs};

/// These tests run real-time simulated fleets in this process, each with
/// the station's controllers closing their loops over the router; run one
/// at a time. Run at once on a loaded machine (a CPU hog per core), the
/// delayed loops of four fleets kept a cluster from settling within 40 s.
static SERIAL: tokio::sync::Mutex<()> = tokio::sync::Mutex::const_new(());

/// Waits (polling every 20 ms) until `f` gives a value. The limit only
/// bounds a failing test: the simulated fleets run in real time, and a
/// loaded machine may take many periods to show what a quiet one shows in
/// one.
async fn until<T>(what: &str, mut f: impl FnMut() -> Option<T>) -> T {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(60);
    loop {
        if let Some(v) = f() {
            return v;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "gave up waiting: {what}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// The simulated robots on threads of their own, as robots have computers
/// of their own: on the test's two runtime threads, a loaded machine delayed
/// the robots' control periods along with the station's, and a differential
/// drive held its last wheel speeds through the delay and circled its slot.
#[derive(Debug)]
struct Robots {
    runtime: tokio::runtime::Runtime,
    fleet: SimFleet,
}

impl Robots {
    async fn spawn(n: usize, gcs: &Gcs, options: SimFleetOptions) -> Robots {
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .unwrap();
        let router = gcs.router().udp_addr();
        let fleet = runtime
            .spawn(SimFleet::spawn(n, router, Arena::default(), options))
            .await
            .unwrap()
            .unwrap();
        Robots { runtime, fleet }
    }

    /// Stops every robot (each says Bye), then their threads.
    async fn shutdown(self) {
        self.runtime.spawn(self.fleet.shutdown()).await.unwrap();
        self.runtime.shutdown_background();
    }
}

async fn start(n: usize, platforms: Vec<PlatformSpec>) -> (Gcs, Executor, Robots) {
    let mut config = CoreConfig::default();
    config.router.udp = "127.0.0.1:0".parse().unwrap();
    config.router.tcp = None;
    let gcs = Gcs::start(config).await.unwrap();
    let options = SimFleetOptions {
        noise: false,
        platforms,
        ..SimFleetOptions::default()
    };
    let fleet = Robots::spawn(n, &gcs, options).await;
    let mut exec = Executor::new(gcs.clone());
    run(&mut exec, &format!("wait robots {n} 10s")).await;
    (gcs, exec, fleet)
}

async fn run(exec: &mut Executor, line: &str) -> String {
    match exec.execute_line(line).await {
        Ok(o) => o.summary,
        Err(e) => panic!("`{line}` failed: {e}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn cluster_waypoints_through_the_router_and_a_member_routed_away() {
    let _serial = SERIAL.lock().await;
    let (gcs, mut exec, fleet) =
        start(4, vec![PlatformSpec::diff_drive(), PlatformSpec::kiwi()]).await;
    run(&mut exec, "cluster c1 robot_1 robot_2 robot_3 robot_4").await;
    run(&mut exec, "formation c1 circle 0.6").await;
    run(&mut exec, "route c1 fleet/c1").await;
    run(&mut exec, "wait route c1 fleet/c1 5s").await;
    run(&mut exec, "cluster-wait c1 settled 0.08 20s").await;
    let gathered = exec.control().cluster_view("c1").unwrap();
    assert_eq!(gathered.status.slots.len(), 4);
    assert!(
        gathered.status.max_error() < 0.1,
        "gathered: {:?}",
        gathered.status.slots
    );

    run(&mut exec, "cluster-waypoint c1 2.2,1.1 2.2,1.7,90deg").await;
    run(&mut exec, "send c1").await;
    let done = run(&mut exec, "cluster-wait c1 40s").await;
    println!("through the router: {done}");
    // Real time on a shared machine: the precise bounds are checked in
    // stepped time (control_cluster.rs); this checks it works end to end.
    run(&mut exec, "cluster-expect c1 max-error 0.6").await;
    run(&mut exec, "cluster-wait c1 settled 0.05 10s").await;
    let view = exec.control().cluster_view("c1").unwrap();
    let m = view.status.measured.unwrap();
    assert!(
        (m.x - 2.2).hypot(m.y - 1.7) <= 0.1,
        "cluster centroid at the last waypoint: {m:?}"
    );
    assert!(
        (m.heading - std::f64::consts::FRAC_PI_2).abs() < 0.1,
        "cluster heading {m:?}"
    );

    // Routed away: dropped from the cluster's outputs from the next period
    // (waited for here; the period's own timing is checked in stepped time
    // in the hub's unit tests).
    run(&mut exec, "route robot_4 none").await;
    let view = until("robot_4 absent from c1", || {
        let view = exec.control().cluster_view("c1").unwrap();
        (view.status.absent == ["robot_4"]).then_some(view)
    })
    .await;
    let status = exec.execute_line("cluster-status c1").await.unwrap();
    println!("{}\n  {}", status.summary, status.details.join("\n  "));
    assert_eq!(
        status.details.len(),
        4,
        "three slots and robot_4 not routed"
    );
    assert!(status.details[3].contains("robot_4 not routed to fleet/c1"));
    assert!(view.status.slots.iter().all(|s| s.robot != "robot_4"));
    let drops_before = gcs.router().counters().dropped.not_routed;
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert_eq!(
        gcs.router().counters().dropped.not_routed,
        drops_before,
        "the cluster controller no longer publishes for robot_4"
    );
    fleet.shutdown().await;
    gcs.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn follower_holds_offset_while_the_leader_runs_a_mission() {
    let _serial = SERIAL.lock().await;
    let (gcs, mut exec, fleet) =
        start(2, vec![PlatformSpec::diff_drive(), PlatformSpec::kiwi()]).await;
    run(&mut exec, "follow robot_2 robot_1 -0.6,0.4").await;
    run(&mut exec, "route robot_2 follow/robot_1").await;
    // Take up the offset behind the still leader first.
    until("the follower at its offset before the leader moves", || {
        let snap = exec.control().snapshot();
        let t = snap.follows[0].targets.first()?;
        (t.error < 0.05).then_some(())
    })
    .await;
    let start = gcs.with_fleet(|f| f.robot("robot_1").unwrap().telemetry.pose);
    run(
        &mut exec,
        &format!(
            "waypoint robot_1 {},{} {},{}",
            start.x + 1.2,
            start.y,
            start.x + 1.2,
            start.y + 0.8
        ),
    )
    .await;
    run(&mut exec, "send robot_1").await;
    run(&mut exec, "route robot_1 wp/gcs").await;
    let mut worst = 0.0f64;
    until("the leader at the end of its mission", || {
        let snap = exec.control().snapshot();
        if let Some(t) = snap.follows[0].targets.first() {
            worst = worst.max(t.error);
        }
        gcs.with_fleet(|f| {
            f.robot("robot_1")
                .unwrap()
                .telemetry
                .mission
                .is_some_and(|m| m.next == m.total)
        })
        .then_some(())
    })
    .await;
    let error = exec.control().snapshot().follows[0].targets[0].error;
    println!(
        "follower offset error while the leader drove its mission: worst {worst:.3} m, at the end {error:.3} m"
    );
    assert!(worst < 0.4, "worst offset error {worst:.3} m");
    assert!(error < 0.15, "final offset error {error:.3} m");
    fleet.shutdown().await;
    gcs.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mission_switched_onboard_offboard_onboard_finishes_in_order() {
    let _serial = SERIAL.lock().await;
    let (gcs, mut exec, fleet) = start(1, vec![PlatformSpec::diff_drive()]).await;
    let p = gcs.with_fleet(|f| f.robot("robot_1").unwrap().telemetry.pose);
    let pts: Vec<String> = [(0.5, 0.0), (0.5, 0.5), (0.0, 0.5), (0.0, 1.0), (0.5, 1.0)]
        .iter()
        .map(|(dx, dy)| format!("{:.3},{:.3}", p.x + dx, p.y + dy))
        .collect();
    run(&mut exec, &format!("waypoint robot_1 {}", pts.join(" "))).await;
    run(&mut exec, "send robot_1").await;
    run(&mut exec, "route robot_1 wp/gcs").await;
    run(&mut exec, "nav-wait robot_1 2 30s").await;
    let off = run(&mut exec, "nav robot_1 offboard").await;
    println!("{off}");
    assert!(off.contains("from waypoint 2 of 5"), "{off}");
    run(&mut exec, "nav-wait robot_1 4 30s").await;
    let on = run(&mut exec, "nav robot_1 onboard").await;
    println!("{on}");
    assert!(on.contains("resumes at waypoint 4 of 5"), "{on}");
    let reached = run(&mut exec, "nav-wait robot_1 5 30s").await;
    println!("{reached}");
    let end = gcs.with_fleet(|f| f.robot("robot_1").unwrap().telemetry.pose);
    assert!(
        (end.x - p.x - 0.5).hypot(end.y - p.y - 1.0) < 0.15,
        "ended at the last waypoint"
    );
    let log = gcs.with_fleet(|f| f.log.iter().map(|l| l.text.clone()).collect::<Vec<_>>());
    let offboard_reached: Vec<&String> = log
        .iter()
        .filter(|l| l.starts_with("offboard/robot_1: waypoint"))
        .collect();
    assert_eq!(
        offboard_reached,
        vec![
            "offboard/robot_1: waypoint 2 reached",
            "offboard/robot_1: waypoint 3 reached"
        ],
        "the GCS loop flew exactly the middle of the mission"
    );
    fleet.shutdown().await;
    gcs.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn external_program_and_gamepad_drive_a_cluster_from_config() {
    let _serial = SERIAL.lock().await;
    let mut config = CoreConfig::default();
    config.router.udp = "127.0.0.1:0".parse().unwrap();
    config.router.tcp = None;
    let cluster = ClusterSpec {
        name: "c1".into(),
        members: vec!["robot_1".into(), "robot_2".into()],
        formation: "column".into(),
        spacing: 0.5,
        offsets: vec![],
    };
    let gcs = Gcs::start(config).await.unwrap();
    let options = SimFleetOptions {
        noise: false,
        platforms: vec![PlatformSpec::kiwi()],
        ..SimFleetOptions::default()
    };
    let fleet = Robots::spawn(2, &gcs, options).await;
    let mut exec = Executor::new(gcs.clone()).with_clusters(&[cluster]);
    run(&mut exec, "wait robots 2 10s").await;
    assert_eq!(
        gcs.with_fleet(|f| f.clusters["c1"].members.clone()),
        vec!["robot_1", "robot_2"]
    );
    run(&mut exec, "route c1 fleet/c1").await;
    run(&mut exec, "cluster-wait c1 settled 0.05 15s").await;
    let view = exec.control().cluster_view("c1").unwrap();
    assert_eq!(
        view.status.formation.kind,
        mech_proto::FormationKind::Column,
        "formation from the config"
    );

    an_external_cluster_command_sets_formation_and_motion(&gcs, &exec).await;
    a_gamepad_velocity_lapses_and_the_cluster_holds(&exec).await;
    fleet.shutdown().await;
    gcs.shutdown().await;
}

/// An external program publishes a cluster command on the cluster's
/// channel: its formation and velocity goal drive the cluster.
async fn an_external_cluster_command_sets_formation_and_motion(gcs: &Gcs, exec: &Executor) {
    let mut matlab = gcs.router().publisher("matlab", "fleet/c1");
    let command = mech_proto::ClusterCommand {
        cluster: "c1".into(),
        members: vec![],
        goal: mech_proto::ClusterGoal::Velocity(mech_proto::ClusterVelocity {
            vx: 0.1,
            vy: 0.0,
            wz: 0.0,
            scale_rate: 0.0,
        }),
        formation: Some(mech_proto::Formation {
            kind: mech_proto::FormationKind::Line,
            spacing: 0.6,
            offsets: vec![],
        }),
    };
    matlab
        .send_body("router", mech_proto::Body::Cluster(command))
        .await
        .unwrap();
    let view = until("the external command taken", || {
        let view = exec.control().cluster_view("c1").unwrap();
        (view.status.formation.kind == mech_proto::FormationKind::Line).then_some(view)
    })
    .await;
    assert_eq!(
        view.motion,
        mech_control::ClusterMotion::Velocity(mech_proto::ClusterVelocity {
            vx: 0.1,
            vy: 0.0,
            wz: 0.0,
            scale_rate: 0.0
        }),
        "the external velocity goal drives the cluster"
    );
}

/// A gamepad velocity lapses unless refreshed: the cluster holds (the
/// external program's velocity, which does not lapse, is replaced by the
/// gamepad's, so a hold can only be the lapse). It lapses 0.5 s after it
/// was given (the hub's drive_timeout; its timing is checked with stepped
/// time in the hub's unit tests).
async fn a_gamepad_velocity_lapses_and_the_cluster_holds(exec: &Executor) {
    let before = exec
        .control()
        .cluster_view("c1")
        .unwrap()
        .status
        .desired
        .unwrap();
    exec.control()
        .drive_cluster(
            "c1",
            mech_proto::ClusterVelocity {
                vx: 0.0,
                vy: 0.1,
                wz: 0.0,
                scale_rate: 0.0,
            },
        )
        .unwrap();
    let held = until("the gamepad velocity lapsed", || {
        let view = exec.control().cluster_view("c1")?;
        (view.motion == mech_control::ClusterMotion::Hold).then_some(view.status)
    })
    .await;
    assert_eq!(held.velocity.vy, 0.0, "the gamepad velocity lapsed");
    let after = held.desired.unwrap();
    tokio::time::sleep(Duration::from_millis(300)).await;
    let later = exec
        .control()
        .cluster_view("c1")
        .unwrap()
        .status
        .desired
        .unwrap();
    assert_eq!((after.x, after.y), (later.x, later.y), "holding");
    // At 0.1 m/s the pose moves for the 0.5 s until the lapse, and for the
    // interval the first period after the drive integrates over: from the
    // period before it, at most 0.5 s (the controllers' step clock caps an
    // interval there), however late a loaded machine runs that period.
    assert!(
        (after.y - before.y).abs() < 0.1 * (0.5 + 0.5) + 0.02,
        "moved at most until the timeout"
    );
}
