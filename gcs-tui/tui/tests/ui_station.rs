//! The TUI's link to a station, without a terminal: a real station
//! (router, simulated agents) attached in process over the attach
//! protocol, the App fed from what the station sends, and the App's
//! requests carried back as protocol messages.

use std::net::SocketAddr;
use std::time::{Duration, Instant};

use mech_core::{CoreConfig, Gcs};
use mech_gcs::ui::theme::Theme;
use mech_gcs::ui::waypoints::WaypointPanel;
use mech_gcs::ui::{Action, App, LinkState, Select, StationLink};
use mech_proto::Waypoint;
use mech_station::client::{AttachOptions, attach_stream};
use mech_station::wire::{FromStation, Streams};
use mech_station::{Station, StationConfig};
use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::widgets::Widget;
use tokio::sync::mpsc;

/// A station with simulated robots, and a TUI's App attached to it.
struct Rig {
    station: Station,
    link: StationLink,
    from: mpsc::Receiver<FromStation>,
    app: App,
}

impl Rig {
    /// A station on loopback with `n` simulated robots, every one
    /// connected and placed in the App.
    async fn start(n: usize) -> Rig {
        let mut config = CoreConfig::default();
        config.router.udp = SocketAddr::from(([127, 0, 0, 1], 0));
        config.router.tcp = None;
        let gcs = Gcs::start(config).await.expect("router starts");
        let station = Station::start(
            gcs,
            &[],
            Some(mech_station::sim::simulator()),
            &StationConfig::default(),
        );
        let opts = AttachOptions {
            stream: Streams {
                snapshots: true,
                log: true,
                events: false,
            },
            ..AttachOptions::default()
        };
        let attached = attach_stream(station.attach_local(), opts)
            .await
            .expect("attached");
        let mut rig = Rig {
            station,
            link: StationLink::new(attached.to),
            from: attached.from,
            app: App::new(attached.welcome.router, Instant::now()),
        };
        rig.link.exec(format!("spawn {n}"));
        rig.wait_for("connected robots", Duration::from_secs(10), |a| {
            a.fleet.robots.len() == n
                && a.fleet
                    .robots
                    .iter()
                    .all(|r| r.link == LinkState::Connected && r.telemetry.pose.x != 0.0)
        })
        .await;
        rig
    }

    /// What the station sent so far, into the App.
    fn pump(&mut self) {
        while let Ok(m) = self.from.try_recv() {
            self.link.receive(m, &mut self.app);
        }
        self.app.update(Action::Tick(Instant::now()));
    }

    /// The App's requests, to the station.
    fn carry_all(&mut self) {
        for req in self.app.take_requests() {
            self.link.carry(req, &mut self.app);
        }
    }

    /// Pumps until `pred` holds (the simulated agents run in real time);
    /// panics after `timeout`.
    async fn wait_for(&mut self, what: &str, timeout: Duration, pred: impl Fn(&App) -> bool) {
        let start = Instant::now();
        loop {
            self.pump();
            if pred(&self.app) {
                return;
            }
            assert!(start.elapsed() < timeout, "timed out waiting for {what}");
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
    }

    async fn stop(self) {
        self.station.shutdown().await;
    }
}

/// A typed command's result comes after what it logged.
async fn a_typed_result_comes_after_what_it_logged(rig: &mut Rig) {
    rig.link.exec("route robot_2 joy/7".into());
    rig.wait_for("robot_2's route result", Duration::from_secs(5), |a| {
        a.events.iter().any(|l| l.text == "robot_2 routed to joy/7")
    })
    .await;
    let at = |text: &str| rig.app.events.iter().position(|l| l.text == text);
    let (logged, result) = (
        at("robot_2 routed to joy/7 (pending)"),
        at("robot_2 routed to joy/7"),
    );
    assert!(logged.is_some() && logged < result, "{:?}", rig.app.events);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn app_requests_reach_simulated_robots() {
    let mut rig = Rig::start(2).await;
    assert!(
        rig.app.fleet.robots.iter().any(|r| r.platform == "kiwi"),
        "mixed platforms"
    );

    // A waypoint 0.3 m ahead of robot_1, sent and routed from the App.
    let p = rig.app.robot("robot_1").expect("robot_1").telemetry.pose;
    rig.app
        .update(Action::Select(Select::Only("robot_1".into())));
    rig.app.update(Action::AddWaypoint(Waypoint {
        x: p.x + 0.3,
        y: p.y,
        z: 0.0,
        time: None,
    }));
    rig.app.update(Action::SendWaypoints);
    rig.app.update(Action::Route {
        robot: "robot_1".into(),
        channel: "wp/gcs".into(),
    });
    rig.carry_all();
    rig.wait_for(
        "route acknowledged and mission done",
        Duration::from_secs(20),
        |a| {
            let r = a.robot("robot_1").expect("robot_1");
            r.route.channel == "wp/gcs"
                && r.route.acknowledged
                && r.telemetry
                    .mission
                    .is_some_and(|m| m.total == 1 && m.next == 1)
        },
    )
    .await;
    let r = rig.app.robot("robot_1").expect("robot_1");
    assert!(
        (r.telemetry.pose.x - (p.x + 0.3)).abs() < 0.15,
        "arrived near the waypoint: {:?}",
        r.telemetry.pose
    );

    // The map trail is the core's recorded path: it runs from about the
    // start to about where the robot is now (within the arrival radius of
    // the waypoint).
    let trail = &r.trail;
    let passes = |x: f64, y: f64| trail.iter().any(|(a, b)| (a - x).hypot(b - y) < 0.1);
    assert!(
        passes(p.x, p.y) && passes(r.telemetry.pose.x, r.telemetry.pose.y),
        "the trail runs from the start to the robot: {trail:?}"
    );
    // Every command is in the event log under the operator who sent it.
    assert!(
        rig.app
            .events
            .iter()
            .any(|l| l.text.ends_with("> route robot_1 wp/gcs")),
        "{:?}",
        rig.app.events
    );

    a_typed_result_comes_after_what_it_logged(&mut rig).await;

    // E-stop from the App latches every robot.
    rig.app.update(Action::EStop);
    rig.carry_all();
    rig.wait_for("every robot e-stopped", Duration::from_secs(10), |a| {
        a.fleet.estop
            && a.fleet
                .robots
                .iter()
                .all(|r| r.telemetry.failsafe == mech_proto::FailsafeState::EStopped)
    })
    .await;
    rig.stop().await;
}

/// The waypoint panel alone, drawn `w` wide and 12 high, as text.
fn waypoint_panel(app: &App, w: u16) -> String {
    let area = Rect::new(0, 0, w, 12);
    let mut buf = Buffer::empty(area);
    WaypointPanel {
        app,
        theme: Theme::new(true),
    }
    .render(area, &mut buf);
    (0..area.height)
        .map(|y| {
            (0..area.width)
                .map(|x| buf[(x, y)].symbol())
                .collect::<String>()
        })
        .collect::<Vec<_>>()
        .join("\n")
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_mission_sent_to_a_robot_routed_to_none_says_why_it_waits_and_how_to_start_it() {
    let mut rig = Rig::start(1).await;
    let held = "robot_1 holds mission";
    let how = "it starts when routed to wp/gcs (`route robot_1 wp/gcs`)";
    // As an operator would: `e 3.5,2.5`, `s`, the robot routed to none.
    rig.app
        .update(Action::Select(Select::Only("robot_1".into())));
    rig.app.update(Action::AddWaypoint(Waypoint {
        x: 3.5,
        y: 2.5,
        z: 0.0,
        time: None,
    }));
    rig.app.update(Action::SendWaypoints);
    rig.carry_all();
    rig.wait_for(
        "the held mission in the log",
        Duration::from_secs(20),
        |a| {
            a.events
                .iter()
                .any(|l| l.text.starts_with(held) && l.text.ends_with(how))
        },
    )
    .await;
    rig.wait_for(
        "the held mission in the snapshot",
        Duration::from_secs(20),
        |a| a.robot("robot_1").is_some_and(|r| r.mission_held.is_some()),
    )
    .await;
    let panel = waypoint_panel(&rig.app, 40);
    // The panel's words, its borders and line breaks left out.
    let words = panel
        .replace('│', " ")
        .split_whitespace()
        .collect::<Vec<_>>()
        .join(" ");
    assert!(
        words.contains(held) && words.contains(how),
        "the waypoint panel says why:\n{panel}"
    );

    // Routed to the mission's channel, the robot runs it: the panel no
    // longer says it waits.
    rig.app.update(Action::Route {
        robot: "robot_1".into(),
        channel: "wp/gcs".into(),
    });
    rig.carry_all();
    rig.wait_for("the mission running", Duration::from_secs(20), |a| {
        a.robot("robot_1")
            .is_some_and(|r| r.mission_held.is_none() && r.route.channel == "wp/gcs")
    })
    .await;
    let panel = waypoint_panel(&rig.app, 40);
    assert!(!panel.contains("holds"), "{panel}");
    rig.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rerouting_away_from_a_pad_leaves_nothing_driving_the_robot() {
    use mech_gcs::gamepad::{PadAxis, PadButton, PadEvent, PadEventKind};

    let mut rig = Rig::start(1).await;
    rig.app.update(Action::Route {
        robot: "robot_1".into(),
        channel: "joy/0".into(),
    });
    for ev in [
        PadEventKind::Connected("synthetic".into()),
        PadEventKind::ButtonPressed(PadButton::LeftBumper),
        PadEventKind::AxisChanged(PadAxis::LeftStickY, 1.0),
    ] {
        rig.app.update(Action::Pad(PadEvent::new(0, ev)));
    }
    // Keep the pad publishing at its rate while the robot drives.
    let start = Instant::now();
    loop {
        rig.carry_all();
        rig.pump();
        let r = rig.app.robot("robot_1").expect("robot_1");
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
    rig.app.update(Action::Route {
        robot: "robot_1".into(),
        channel: String::new(),
    });
    let start = Instant::now();
    loop {
        rig.carry_all();
        rig.pump();
        let r = rig.app.robot("robot_1").expect("robot_1");
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
        rig.app.pads()[0].enabled,
        "the pad was still driving its channel"
    );
    rig.stop().await;
}

/// Until robot_1 and robot_2 are more than 0.3 m from `start`, carrying
/// the TUI's requests to the station.
async fn members_move(rig: &mut Rig, start: &[mech_proto::Pose]) {
    let t0 = Instant::now();
    loop {
        rig.carry_all();
        rig.pump();
        let moved = ["robot_1", "robot_2"].iter().zip(start).all(|(r, p)| {
            let q = rig.app.robot(r).expect("member").telemetry.pose;
            (q.x - p.x).hypot(q.y - p.y) > 0.3
        });
        if moved {
            return;
        }
        assert!(
            t0.elapsed() < Duration::from_secs(15),
            "members move under the pad: {:?}",
            rig.app.fleet.robots
        );
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Until robot_1 and robot_2 are at rest: with `carry`, the TUI's requests
/// reach the station meanwhile; without, they are dropped.
async fn members_rest(rig: &mut Rig, carry: bool, what: &str) {
    let t0 = Instant::now();
    loop {
        if carry {
            rig.carry_all();
        } else {
            rig.app.take_requests();
        }
        rig.pump();
        if ["robot_1", "robot_2"]
            .iter()
            .all(|r| rig.app.robot(r).expect("member").speed() < 0.02)
        {
            return;
        }
        assert!(t0.elapsed() < Duration::from_secs(10), "{what}");
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

/// Cluster `c1` of robot_1 and robot_2 made in the TUI and both routed to
/// its channel, the requests carried to the station.
fn cluster_c1(rig: &mut Rig) {
    rig.app
        .update(Action::Select(Select::Only("robot_1".into())));
    rig.app
        .update(Action::Select(Select::Toggle("robot_2".into())));
    rig.app.update(Action::MakeCluster);
    for r in ["robot_1", "robot_2"] {
        rig.app.update(Action::Route {
            robot: r.into(),
            channel: "fleet/c1".into(),
        });
    }
    rig.carry_all();
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn pad_in_cluster_mode_moves_the_routed_members_through_the_hub() {
    use mech_gcs::gamepad::{PadAxis, PadButton, PadEvent, PadEventKind};

    let mut rig = Rig::start(3).await;
    cluster_c1(&mut rig);
    let start: Vec<_> = ["robot_1", "robot_2", "robot_3"]
        .iter()
        .map(|r| rig.app.robot(r).expect("robot").telemetry.pose)
        .collect();

    // Pad: steering-throttle -> ... -> cluster (four Selects), dead-man,
    // left stick forward.
    let mut events = vec![PadEventKind::Connected("synthetic".into())];
    events.extend((0..4).map(|_| PadEventKind::ButtonPressed(PadButton::Select)));
    events.push(PadEventKind::ButtonPressed(PadButton::LeftBumper));
    events.push(PadEventKind::AxisChanged(PadAxis::LeftStickY, 1.0));
    for ev in events {
        rig.app.update(Action::Pad(PadEvent::new(0, ev)));
    }
    members_move(&mut rig, &start).await;
    let view = rig
        .station
        .control()
        .cluster_view("c1")
        .expect("the station's hub runs c1");
    assert!(view.status.slots.len() == 2, "{view:?}");
    // The station copies the controller's report into its snapshots, for
    // the map and routes panel.
    rig.wait_for("c1's controller status", Duration::from_secs(5), |a| {
        a.fleet.clusters.iter().any(|c| {
            c.name == "c1"
                && c.control.as_ref().is_some_and(|ctl| {
                    ctl.slots.len() == 2 && ctl.desired.is_some() && ctl.measured.is_some()
                })
        })
    })
    .await;
    let r3 = rig.app.robot("robot_3").expect("robot_3");
    assert!(
        r3.speed() < 0.02,
        "robot_3 is not in the cluster and stays put: {r3:?}"
    );

    // A pad velocity lapses: if the pad's stream stops reaching the hub
    // (dead-man still held, nothing carried), the cluster holds and the
    // members come to rest.
    members_rest(&mut rig, false, "stale pad velocity lapses").await;

    // Releasing the dead-man holds the cluster too.
    rig.app.update(Action::Pad(PadEvent::new(
        0,
        PadEventKind::ButtonReleased(PadButton::LeftBumper),
    )));
    members_rest(&mut rig, true, "members stop").await;

    // The command line's `cluster-move` reaches the very controller the pad
    // drove: every session of the station shares one hub. (The pad's
    // last, zero, velocity may still be the motion until the line runs.)
    rig.link.exec("cluster-move c1 0.1 0 0".into());
    let t0 = Instant::now();
    let moving = |m: &mech_control::ClusterMotion| matches!(m, mech_control::ClusterMotion::Velocity(v) if v.vx > 0.05);
    let motion = loop {
        rig.pump();
        match rig.station.control().cluster_view("c1") {
            Some(v) if moving(&v.motion) => break Some(v.motion),
            Some(v) if t0.elapsed() > Duration::from_secs(10) => break Some(v.motion),
            None if t0.elapsed() > Duration::from_secs(10) => break None,
            _ => tokio::time::sleep(Duration::from_millis(10)).await,
        }
    };
    assert!(
        matches!(motion, Some(mech_control::ClusterMotion::Velocity(v)) if v.vx > 0.05),
        "{motion:?}"
    );
    rig.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn nav_key_switches_the_route_to_offboard_and_back() {
    let mut rig = Rig::start(1).await;
    let p = rig.app.robot("robot_1").expect("robot_1").telemetry.pose;
    rig.app
        .update(Action::Select(Select::Only("robot_1".into())));
    for (dx, dy) in [(0.3, 0.0), (0.3, 0.3), (0.0, 0.3), (0.0, 0.0)] {
        rig.app.update(Action::AddWaypoint(Waypoint {
            x: p.x + dx,
            y: p.y + dy,
            z: 0.0,
            time: None,
        }));
    }
    rig.app.update(Action::SendWaypoints);
    rig.app.update(Action::Route {
        robot: "robot_1".into(),
        channel: "wp/gcs".into(),
    });
    rig.carry_all();
    rig.wait_for("mission running onboard", Duration::from_secs(10), |a| {
        let r = a.robot("robot_1").expect("robot_1");
        r.route.channel == "wp/gcs" && r.route.acknowledged && r.telemetry.mission.is_some()
    })
    .await;

    let keys = mech_gcs::ui::keys::on_key(
        &rig.app,
        &crossterm::event::KeyEvent::new(
            crossterm::event::KeyCode::Char('o'),
            crossterm::event::KeyModifiers::NONE,
        ),
    );
    assert_eq!(keys, [Action::ToggleNav]);
    for a in keys {
        rig.app.update(a);
    }
    rig.carry_all();
    rig.wait_for("route offboard/robot_1", Duration::from_secs(10), |a| {
        let r = a.robot("robot_1").expect("robot_1");
        r.route.channel == "offboard/robot_1"
            && r.route.acknowledged
            && r.telemetry.computation == mech_proto::Computation::Offboard
    })
    .await;
    assert!(rig.station.control().nav_view("robot_1").is_some());

    rig.app.update(Action::ToggleNav);
    rig.carry_all();
    rig.wait_for("route back to wp/gcs", Duration::from_secs(10), |a| {
        let r = a.robot("robot_1").expect("robot_1");
        r.route.channel == "wp/gcs" && r.route.acknowledged
    })
    .await;
    assert!(rig.station.control().nav_view("robot_1").is_none());
    rig.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_typed_estop_acts_at_once_whatever_the_command_queue_is_doing() {
    // A `wait` that cannot finish holds the session's queue of lines:
    // `estop` and `release` must not wait behind it.
    let mut rig = Rig::start(1).await;
    rig.app.update(Action::OpenCommandLine);
    rig.link.exec("wait lost robot_1 60s".into());
    rig.link.exec("estop".into());
    rig.wait_for("the typed estop", Duration::from_secs(5), |a| a.fleet.estop)
        .await;
    rig.link.exec("release".into());
    rig.wait_for("the typed release", Duration::from_secs(5), |a| {
        !a.fleet.estop
    })
    .await;
    let gcs = rig.station.gcs().clone();
    assert!(!gcs.with_fleet(|f| f.estop.engaged));
    rig.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_route_change_by_one_operator_reaches_the_others_snapshot_at_once() {
    let rig = Rig::start(2).await;
    let opts = || AttachOptions {
        stream: Streams {
            snapshots: true,
            log: false,
            events: false,
        },
        ..AttachOptions::default()
    };
    let a = attach_stream(rig.station.attach_local(), opts())
        .await
        .expect("a attached");
    let mut b = attach_stream(rig.station.attach_local(), opts())
        .await
        .expect("b attached");
    let mut latencies = Vec::new();
    for i in 0..40u64 {
        let channel = format!("joy/flip{}", i % 2);
        let sent = Instant::now();
        a.to.send(mech_station::wire::ToStation::Line {
            id: i,
            text: format!("route robot_2 {channel}"),
        })
        .expect("sent");
        loop {
            let m = tokio::time::timeout(Duration::from_secs(5), b.from.recv())
                .await
                .expect("b hears within 5 s")
                .expect("b attached");
            if let FromStation::Snapshot { fleet, .. } = m {
                let r2 = fleet.robots.iter().find(|r| r.name == "robot_2");
                if r2.is_some_and(|r| r.route.channel == channel) {
                    latencies.push(sent.elapsed());
                    break;
                }
            }
        }
    }
    latencies.sort();
    let ms = |d: Duration| d.as_secs_f64() * 1e3;
    println!(
        "route change seen by another client: p50 {:.1} ms, p95 {:.1} ms, max {:.1} ms over {} changes",
        ms(latencies[latencies.len() / 2]),
        ms(latencies[latencies.len() * 95 / 100]),
        ms(latencies[latencies.len() - 1]),
        latencies.len()
    );
    rig.stop().await;
}

#[test]
fn a_radio_robots_card_shows_its_live_links_and_radio_budget() {
    use mech_core::event::{Event, LinkAddr, RobotLinks, Stamped};
    let mut fleet = mech_core::Fleet::new(mech_core::FleetConfig::default());
    let hello = mech_proto::Hello {
        name: "xbee_bot".into(),
        platform: "diff-drive".into(),
        capabilities: vec![],
        motors: 2,
        max_speed: 0.5,
        max_yaw_rate: 2.0,
        agent_version: "t".into(),
    };
    let at = |event| Stamped {
        at: Duration::ZERO,
        event,
    };
    fleet.apply(&at(Event::Registered {
        hello,
        id: 1,
        addr: LinkAddr::Radio("/dev/ttyUSB0".into()),
        known: false,
    }));
    fleet.apply(&at(Event::Links {
        robot: "xbee_bot".into(),
        links: RobotLinks {
            udp: true,
            radio: Some("/dev/ttyUSB0".into()),
            active: "radio",
            radio_budget_hz: Some(14.0),
            down: Vec::new(),
        },
    }));
    let mut app = App::new("127.0.0.1:7400", Instant::now());
    app.update(Action::Fleet(mech_station::snapshot(&fleet, Vec::new())));
    let mut term =
        ratatui::Terminal::new(ratatui::backend::TestBackend::new(120, 36)).expect("terminal");
    term.draw(|f| f.render_widget(&app, f.area()))
        .expect("draws");
    let screen = term.backend().to_string();
    assert!(screen.contains("wifi+radio* 14Hz"), "{screen}");
}

#[test]
fn another_stations_robot_is_marked_remote_on_its_card_and_map() {
    let mut fleet = mech_core::Fleet::new(Default::default());
    let info = mech_proto::Hello {
        name: "robot_9".into(),
        platform: "kiwi".into(),
        capabilities: vec![],
        motors: 3,
        max_speed: 1.0,
        max_yaw_rate: 1.0,
        agent_version: String::new(),
    };
    fleet.remote_info("site-b", "robot_9", 4, &info);
    fleet.remote_link("site-b", "robot_9", LinkState::Connected);
    let snap = mech_station::snapshot(&fleet, vec![]);
    assert_eq!(snap.robots[0].remote.as_deref(), Some("site-b"));
    let mut app = App::new("127.0.0.1:7700", Instant::now());
    app.update(Action::Resize(120, 36));
    app.update(Action::Fleet(snap));
    app.update(Action::FitFleet);
    let mut term = ratatui::Terminal::new(ratatui::backend::TestBackend::new(120, 36)).unwrap();
    term.draw(|f| f.render_widget(&app, f.area())).unwrap();
    let screen = term.backend().to_string();
    assert!(screen.contains("robot_9@site-b"), "{screen}");
    assert!(
        screen.contains("robot_9@site-b remote Connected kiwi"),
        "the card says so: {screen}"
    );
    assert!(screen.contains('○'), "a hollow mark on the map: {screen}");
}
