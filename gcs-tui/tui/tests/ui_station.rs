//! The station's link to the core, without a terminal: a real router and
//! simulated agents, the App fed from the fleet model, and the App's
//! requests carried back to the router.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use mech_core::{CoreConfig, Gcs};
use mech_gcs::ui::{Action, App, CoreLink, LinkState, Select, snapshot};
use mech_proto::Waypoint;

async fn refresh(app: &mut App, gcs: &Gcs) {
    // Channels first: the router's tables must not be locked while the
    // fleet model is (the router locks them the other way round).
    let channels = gcs.router().channels();
    let snap = gcs.with_fleet(|f| snapshot(f, channels));
    app.update(Action::Tick(Instant::now()));
    app.update(Action::Fleet(snap));
}

/// Polls the fleet into the App until `pred` holds (the simulated agents
/// run in real time); panics after `timeout`.
async fn wait_for(
    app: &mut App,
    gcs: &Gcs,
    what: &str,
    timeout: Duration,
    pred: impl Fn(&App) -> bool,
) {
    let start = Instant::now();
    loop {
        refresh(app, gcs).await;
        if pred(app) {
            return;
        }
        assert!(start.elapsed() < timeout, "timed out waiting for {what}");
        tokio::time::sleep(Duration::from_millis(50)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn app_requests_reach_simulated_robots() {
    let mut config = CoreConfig::default();
    config.router.udp = SocketAddr::from(([127, 0, 0, 1], 0));
    config.router.tcp = None;
    let gcs = Gcs::start(config).await.expect("router starts");
    let mut spawner = mech_gcs::sim::simulator();
    let names = spawner
        .spawn(2, gcs.router().udp_addr(), gcs.router().clone())
        .await
        .expect("simulated agents start");
    assert_eq!(names, ["robot_1", "robot_2"]);

    let (lines, _rx) = tokio::sync::mpsc::unbounded_channel();
    let control = mech_control::ControlHub::new(gcs.clone());
    let mut link = CoreLink::new(gcs.clone(), lines, control);
    let mut app = App::new(gcs.router().udp_addr().to_string(), Instant::now());
    wait_for(
        &mut app,
        &gcs,
        "two connected robots",
        Duration::from_secs(10),
        |a| {
            a.robots.len() == 2
                && a.robots
                    .iter()
                    .all(|r| r.link == LinkState::Connected && r.pose.x != 0.0)
        },
    )
    .await;
    assert!(
        app.robots.iter().any(|r| r.platform == "kiwi"),
        "mixed platforms"
    );

    // A waypoint 0.3 m ahead of robot_1, sent and routed from the App.
    let p = app.robot("robot_1").expect("robot_1").pose;
    app.update(Action::Select(Select::Only("robot_1".into())));
    app.update(Action::AddWaypoint(Waypoint {
        x: p.x + 0.3,
        y: p.y,
        z: 0.0,
        time: None,
    }));
    app.update(Action::SendWaypoints);
    app.update(Action::Route {
        robot: "robot_1".into(),
        channel: "wp/gcs".into(),
    });
    for req in app.take_requests() {
        link.carry(req, &mut app).await;
    }
    wait_for(
        &mut app,
        &gcs,
        "route acknowledged and mission done",
        Duration::from_secs(20),
        |a| {
            let r = a.robot("robot_1").expect("robot_1");
            r.route.channel == "wp/gcs"
                && r.route.acknowledged
                && r.mission.is_some_and(|m| m.total == 1 && m.next == 1)
        },
    )
    .await;
    let r = app.robot("robot_1").expect("robot_1");
    assert!(
        (r.pose.x - (p.x + 0.3)).abs() < 0.15,
        "arrived near the waypoint: {:?}",
        r.pose
    );

    // The map trail is the core's recorded path: it runs from about the
    // start to about where the robot is now (within the arrival radius of
    // the waypoint).
    let trail = &r.trail;
    let passes = |x: f64, y: f64| trail.iter().any(|(a, b)| (a - x).hypot(b - y) < 0.1);
    assert!(
        passes(p.x, p.y) && passes(r.pose.x, r.pose.y),
        "the trail runs from the start to the robot: {trail:?}"
    );

    // E-stop from the App latches every robot.
    app.update(Action::EStop);
    for req in app.take_requests() {
        link.carry(req, &mut app).await;
    }
    wait_for(
        &mut app,
        &gcs,
        "every robot e-stopped",
        Duration::from_secs(10),
        |a| {
            a.estop
                && a.robots
                    .iter()
                    .all(|r| r.failsafe == mech_proto::FailsafeState::EStopped)
        },
    )
    .await;

    spawner.shutdown().await;
    gcs.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rerouting_away_from_a_pad_leaves_nothing_driving_the_robot() {
    use mech_gcs::gamepad::{PadAxis, PadButton, PadEvent, PadEventKind};

    let mut config = CoreConfig::default();
    config.router.udp = SocketAddr::from(([127, 0, 0, 1], 0));
    config.router.tcp = None;
    let gcs = Gcs::start(config).await.expect("router starts");
    let mut spawner = mech_gcs::sim::simulator();
    spawner
        .spawn(1, gcs.router().udp_addr(), gcs.router().clone())
        .await
        .expect("simulated agent starts");
    let (lines, _rx) = tokio::sync::mpsc::unbounded_channel();
    let control = mech_control::ControlHub::new(gcs.clone());
    let mut link = CoreLink::new(gcs.clone(), lines, control);
    let mut app = App::new("router", Instant::now());
    wait_for(&mut app, &gcs, "robot_1", Duration::from_secs(10), |a| {
        a.robot("robot_1").is_some_and(|r| r.pose.x != 0.0)
    })
    .await;

    app.update(Action::Route {
        robot: "robot_1".into(),
        channel: "joy/0".into(),
    });
    for ev in [
        PadEventKind::Connected("synthetic".into()),
        PadEventKind::ButtonPressed(PadButton::LeftBumper),
        PadEventKind::AxisChanged(PadAxis::LeftStickY, 1.0),
    ] {
        app.update(Action::Pad(PadEvent::new(0, ev)));
    }
    // Keep the pad publishing at its rate while the robot drives.
    let start = Instant::now();
    loop {
        for req in app.take_requests() {
            link.carry(req, &mut app).await;
        }
        refresh(&mut app, &gcs).await;
        let r = app.robot("robot_1").expect("robot_1");
        if r.route.acknowledged && r.speed() > 0.05 {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "pad drives robot_1"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }

    // Re-route away while the dead-man is still held: the pad keeps
    // publishing on joy/0, but robot_1 must come to rest.
    app.update(Action::Route {
        robot: "robot_1".into(),
        channel: String::new(),
    });
    let start = Instant::now();
    loop {
        for req in app.take_requests() {
            link.carry(req, &mut app).await;
        }
        refresh(&mut app, &gcs).await;
        let r = app.robot("robot_1").expect("robot_1");
        if r.route.acknowledged && r.route.channel.is_empty() && r.speed() < 0.01 {
            break;
        }
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "robot_1 stops: {r:?}"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    assert!(
        app.pads()[0].enabled,
        "the pad was still driving its channel"
    );
    spawner.shutdown().await;
    gcs.shutdown().await;
}

/// A real router and `n` simulated agents, the App fed from the fleet
/// model, and a link whose controllers are shared with a command-language
/// executor, as in the station.
async fn station(
    n: usize,
) -> (
    Gcs,
    Box<dyn mech_control::lang::exec::SimSpawner>,
    mech_control::lang::Executor,
    CoreLink,
    App,
) {
    let mut config = CoreConfig::default();
    config.router.udp = SocketAddr::from(([127, 0, 0, 1], 0));
    config.router.tcp = None;
    let gcs = Gcs::start(config).await.expect("router starts");
    let mut spawner = mech_gcs::sim::simulator();
    spawner
        .spawn(n, gcs.router().udp_addr(), gcs.router().clone())
        .await
        .expect("simulated agents start");
    let executor = mech_control::lang::Executor::new(gcs.clone());
    let (lines, _rx) = tokio::sync::mpsc::unbounded_channel();
    let link = CoreLink::new(gcs.clone(), lines, executor.control().clone());
    let mut app = App::new("router", Instant::now());
    wait_for(
        &mut app,
        &gcs,
        "connected robots",
        Duration::from_secs(10),
        |a| a.robots.len() == n && a.robots.iter().all(|r| r.pose.x != 0.0),
    )
    .await;
    (gcs, spawner, executor, link, app)
}

async fn carry_all(app: &mut App, link: &mut CoreLink) {
    for req in app.take_requests() {
        link.carry(req, app).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pad_in_cluster_mode_moves_the_routed_members_through_the_hub() {
    use mech_gcs::gamepad::{PadAxis, PadButton, PadEvent, PadEventKind};

    let (gcs, mut spawner, mut executor, mut link, mut app) = station(3).await;
    app.update(Action::Select(Select::Only("robot_1".into())));
    app.update(Action::Select(Select::Toggle("robot_2".into())));
    app.update(Action::MakeCluster);
    for r in ["robot_1", "robot_2"] {
        app.update(Action::Route {
            robot: r.into(),
            channel: "fleet/c1".into(),
        });
    }
    carry_all(&mut app, &mut link).await;
    let start: Vec<_> = ["robot_1", "robot_2", "robot_3"]
        .iter()
        .map(|r| app.robot(r).expect("robot").pose)
        .collect();

    // Pad: steering-throttle -> ... -> cluster (four Selects), dead-man,
    // left stick forward.
    let mut events = vec![PadEventKind::Connected("synthetic".into())];
    events.extend((0..4).map(|_| PadEventKind::ButtonPressed(PadButton::Select)));
    events.push(PadEventKind::ButtonPressed(PadButton::LeftBumper));
    events.push(PadEventKind::AxisChanged(PadAxis::LeftStickY, 1.0));
    for ev in events {
        app.update(Action::Pad(PadEvent::new(0, ev)));
    }
    let t0 = Instant::now();
    loop {
        carry_all(&mut app, &mut link).await;
        refresh(&mut app, &gcs).await;
        let moved = ["robot_1", "robot_2"].iter().zip(&start).all(|(r, p)| {
            let q = app.robot(r).expect("member").pose;
            (q.x - p.x).hypot(q.y - p.y) > 0.3
        });
        if moved {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(15),
            "members move under the pad: {:?}",
            app.robots
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let view = executor
        .control()
        .cluster_view("c1")
        .expect("the executor's hub runs c1");
    assert!(view.status.slots.len() == 2, "{view:?}");
    // What the station copies into the App for the map and routes panel.
    let channels = gcs.router().channels();
    let mut snap = gcs.with_fleet(|f| snapshot(f, channels));
    mech_gcs::ui::apply_control(&mut snap, &executor.control().snapshot());
    app.update(Action::Fleet(snap));
    let c1 = app.clusters.iter().find(|c| c.name == "c1").expect("c1");
    let ctl = c1.control.as_ref().expect("controller status copied");
    assert_eq!(ctl.slots.len(), 2);
    assert!(ctl.desired.is_some() && ctl.measured.is_some());
    let r3 = app.robot("robot_3").expect("robot_3");
    assert!(
        r3.speed() < 0.02,
        "robot_3 is not in the cluster and stays put: {r3:?}"
    );

    // A pad velocity lapses: if the pad's stream stops reaching the hub
    // (dead-man still held, nothing carried), the cluster holds and the
    // members come to rest.
    let t0 = Instant::now();
    loop {
        app.take_requests();
        refresh(&mut app, &gcs).await;
        if ["robot_1", "robot_2"]
            .iter()
            .all(|r| app.robot(r).expect("member").speed() < 0.02)
        {
            break;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(10),
            "stale pad velocity lapses"
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }

    // Releasing the dead-man holds the cluster too.
    app.update(Action::Pad(PadEvent::new(
        0,
        PadEventKind::ButtonReleased(PadButton::LeftBumper),
    )));
    let t0 = Instant::now();
    loop {
        carry_all(&mut app, &mut link).await;
        refresh(&mut app, &gcs).await;
        if ["robot_1", "robot_2"]
            .iter()
            .all(|r| app.robot(r).expect("member").speed() < 0.02)
        {
            break;
        }
        assert!(t0.elapsed() < Duration::from_secs(10), "members stop");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }

    // The command line's `cluster-move` reaches the very controller the pad
    // drove: the station's link and the executor share one hub.
    executor
        .execute_line("cluster-move c1 0.1 0 0")
        .await
        .expect("cluster-move runs");
    // The status of the next control period is the first to show it.
    let t0 = Instant::now();
    let motion = loop {
        match link.control().cluster_view("c1") {
            Some(v) => break Some(v.motion),
            None if t0.elapsed() > Duration::from_secs(2) => break None,
            None => tokio::time::sleep(Duration::from_millis(10)).await,
        }
    };
    assert!(
        matches!(motion, Some(mech_control::ClusterMotion::Velocity(v)) if v.vx > 0.05),
        "{motion:?}"
    );
    spawner.shutdown().await;
    gcs.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nav_key_switches_the_route_to_offboard_and_back() {
    let (gcs, mut spawner, _executor, mut link, mut app) = station(1).await;
    let p = app.robot("robot_1").expect("robot_1").pose;
    app.update(Action::Select(Select::Only("robot_1".into())));
    for (dx, dy) in [(0.3, 0.0), (0.3, 0.3), (0.0, 0.3), (0.0, 0.0)] {
        app.update(Action::AddWaypoint(Waypoint {
            x: p.x + dx,
            y: p.y + dy,
            z: 0.0,
            time: None,
        }));
    }
    app.update(Action::SendWaypoints);
    app.update(Action::Route {
        robot: "robot_1".into(),
        channel: "wp/gcs".into(),
    });
    carry_all(&mut app, &mut link).await;
    wait_for(
        &mut app,
        &gcs,
        "mission running onboard",
        Duration::from_secs(10),
        |a| {
            let r = a.robot("robot_1").expect("robot_1");
            r.route.channel == "wp/gcs" && r.route.acknowledged && r.mission.is_some()
        },
    )
    .await;

    let keys = mech_gcs::ui::keys::on_key(
        &app,
        &crossterm::event::KeyEvent::new(
            crossterm::event::KeyCode::Char('o'),
            crossterm::event::KeyModifiers::NONE,
        ),
    );
    assert_eq!(keys, [Action::ToggleNav]);
    for a in keys {
        app.update(a);
    }
    carry_all(&mut app, &mut link).await;
    wait_for(
        &mut app,
        &gcs,
        "route offboard/robot_1",
        Duration::from_secs(10),
        |a| {
            let r = a.robot("robot_1").expect("robot_1");
            r.route.channel == "offboard/robot_1"
                && r.route.acknowledged
                && r.computation == mech_proto::Computation::Offboard
        },
    )
    .await;
    assert!(link.control().nav_view("robot_1").is_some());

    app.update(Action::ToggleNav);
    carry_all(&mut app, &mut link).await;
    wait_for(
        &mut app,
        &gcs,
        "route back to wp/gcs",
        Duration::from_secs(10),
        |a| {
            let r = a.robot("robot_1").expect("robot_1");
            r.route.channel == "wp/gcs" && r.route.acknowledged
        },
    )
    .await;
    assert!(link.control().nav_view("robot_1").is_none());
    spawner.shutdown().await;
    gcs.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_typed_estop_acts_at_once_whatever_the_command_queue_is_doing() {
    // The station's queue of typed lines is gone here (as if busy forever
    // with a `wait`): `estop` and `release` must not depend on it.
    let (gcs, mut spawner, _executor, mut link, mut app) = station(1).await;
    link.carry(mech_gcs::ui::Request::Exec("estop".into()), &mut app)
        .await;
    assert!(gcs.with_fleet(|f| f.estop.engaged), "typed estop engages");
    link.carry(mech_gcs::ui::Request::Exec("release".into()), &mut app)
        .await;
    assert!(
        !gcs.with_fleet(|f| f.estop.engaged),
        "typed release releases"
    );
    spawner.shutdown().await;
    gcs.shutdown().await;
}

#[test]
fn another_stations_robot_is_marked_remote_on_its_card_and_map() {
    let mut fleet = mech_core::Fleet::new(Default::default());
    let info = mech_core::fleet::RemoteInfo {
        id: 4,
        platform: "kiwi".into(),
        capabilities: vec![],
        motors: 3,
        max_speed: 1.0,
        max_yaw_rate: 1.0,
    };
    fleet.remote_info("site-b", "robot_9", &info);
    fleet.remote_link("site-b", "robot_9", LinkState::Connected);
    let snap = snapshot(&fleet, vec![]);
    assert_eq!(snap.robots[0].remote.as_deref(), Some("site-b"));
    let mut app = App::new("127.0.0.1:7700", Instant::now());
    app.update(Action::Resize(120, 36));
    app.update(Action::Fleet(snap));
    app.update(Action::FitFleet);
    let mut term = ratatui::Terminal::new(ratatui::backend::TestBackend::new(120, 36)).unwrap();
    term.draw(|f| f.render_widget(&app, f.area())).unwrap();
    let screen = term.backend().to_string();
    assert!(screen.contains("robot_9@site-b"), "{screen}");
    assert!(screen.contains("kiwi remote"), "the card says so: {screen}");
    assert!(screen.contains('○'), "a hollow mark on the map: {screen}");
}
