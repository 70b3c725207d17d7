//! Gamepads and keyboard teleop through the App: synthetic pad events from a
//! scripted source become commands for exactly the robots routed to the
//! pad's channel.

use std::time::Duration;

use mech_gcs::gamepad::{InputSource, PadAxis, PadButton, PadEvent, PadEventKind, ScriptedSource};
use mech_gcs::ui::fixture;
use mech_gcs::ui::{Action, App, Request, Select};
use mech_proto::{Command, Stop};

fn feed(app: &mut App, src: &mut impl InputSource) {
    while let Some(ev) = src.next_event() {
        app.update(Action::Pad(ev));
    }
}

fn publishes(reqs: &[Request]) -> Vec<(String, Vec<String>, Command)> {
    reqs.iter()
        .filter_map(|r| match r {
            Request::Publish {
                channel,
                robots,
                command,
            } => Some((channel.clone(), robots.clone(), command.clone())),
            _ => None,
        })
        .collect()
}

#[test]
fn pad_drives_only_robots_routed_to_its_channel() {
    // Fixture: robot_2 is routed to joy/0.
    let mut app = fixture::app(4, 80, 24);
    let mut src = ScriptedSource::new([
        PadEvent::new(0, PadEventKind::Connected("synthetic pad".into())),
        PadEvent::new(0, PadEventKind::ButtonPressed(PadButton::LeftBumper)),
        PadEvent::new(0, PadEventKind::AxisChanged(PadAxis::LeftStickY, 0.8)),
    ]);
    feed(&mut app, &mut src);
    let p = publishes(&app.take_requests());
    assert!(!p.is_empty());
    for (channel, robots, _) in &p {
        assert_eq!(channel, "joy/0");
        assert_eq!(robots, &["robot_2"]);
    }
    assert!(matches!(p.last(), Some((_, _, Command::SteeringThrottle(s))) if s.throttle > 0.5));

    // Re-route robot_2 away: the pad keeps publishing, but for nobody.
    app.update(Action::Route {
        robot: "robot_2".into(),
        channel: "wp/gcs".into(),
    });
    app.take_requests();
    let t = app.manual.now + Duration::from_millis(100);
    app.update(Action::Tick(t));
    let p = publishes(&app.take_requests());
    assert!(!p.is_empty(), "steady rate continues while enabled");
    assert!(p.iter().all(|(_, robots, _)| robots.is_empty()));
}

#[test]
fn deadman_release_and_unplug_zero_the_channel() {
    let mut app = fixture::app(4, 80, 24);
    let mut src = ScriptedSource::new([
        PadEvent::new(0, PadEventKind::Connected("pad".into())),
        PadEvent::new(0, PadEventKind::ButtonPressed(PadButton::LeftBumper)),
        PadEvent::new(0, PadEventKind::AxisChanged(PadAxis::LeftStickY, 1.0)),
        PadEvent::new(0, PadEventKind::ButtonReleased(PadButton::LeftBumper)),
    ]);
    feed(&mut app, &mut src);
    let p = publishes(&app.take_requests());
    assert_eq!(p.last().map(|x| &x.2), Some(&Command::Stop(Stop {})));
    app.update(Action::Tick(app.manual.now + Duration::from_secs(1)));
    assert!(
        publishes(&app.take_requests()).is_empty(),
        "silent when released"
    );

    src.push(PadEvent::new(
        0,
        PadEventKind::ButtonPressed(PadButton::LeftBumper),
    ));
    src.push(PadEvent::new(0, PadEventKind::Disconnected));
    feed(&mut app, &mut src);
    let p = publishes(&app.take_requests());
    assert_eq!(p.last().map(|x| &x.2), Some(&Command::Stop(Stop {})));
    assert!(app.pads().is_empty());
    assert!(app.events.iter().any(|l| l.text.contains("unplugged")));
}

#[test]
fn pad_estop_and_cluster_mode() {
    let mut app = fixture::app(4, 80, 24);
    app.update(Action::Select(Select::Only("robot_1".into())));
    app.update(Action::Select(Select::Toggle("robot_3".into())));
    app.update(Action::MakeCluster);
    app.take_requests();
    let mut src = ScriptedSource::new([
        PadEvent::new(0, PadEventKind::Connected("pad".into())),
        // steering-throttle -> velocity-heading -> tank -> twist -> cluster
        PadEvent::new(0, PadEventKind::ButtonPressed(PadButton::Select)),
        PadEvent::new(0, PadEventKind::ButtonPressed(PadButton::Select)),
        PadEvent::new(0, PadEventKind::ButtonPressed(PadButton::Select)),
        PadEvent::new(0, PadEventKind::ButtonPressed(PadButton::Select)),
        PadEvent::new(0, PadEventKind::ButtonPressed(PadButton::LeftBumper)),
        PadEvent::new(0, PadEventKind::AxisChanged(PadAxis::RightStickX, -1.0)),
    ]);
    feed(&mut app, &mut src);
    let reqs = app.take_requests();
    let cluster = reqs.iter().rev().find_map(|r| match r {
        Request::ClusterVelocity { cluster, velocity } => Some((cluster.clone(), *velocity)),
        _ => None,
    });
    let (name, v) = cluster.expect("cluster velocity published");
    assert_eq!(name, "c1");
    let c1 = app
        .fleet
        .clusters
        .iter()
        .find(|c| c.name == "c1")
        .expect("c1");
    assert_eq!(c1.members, ["robot_1", "robot_3"], "the cluster driven");
    assert!(v.wz > 0.0, "stick left rotates counter-clockwise");

    src.push(PadEvent::new(
        0,
        PadEventKind::ButtonPressed(PadButton::Start),
    ));
    feed(&mut app, &mut src);
    assert!(app.fleet.estop);
    assert!(
        app.take_requests()
            .contains(&Request::EStop { engage: true })
    );
}

#[test]
fn keyboard_teleop_publishes_on_key0_and_stops() {
    let mut app = fixture::app(4, 80, 24);
    app.update(Action::Route {
        robot: "robot_4".into(),
        channel: "key/0".into(),
    });
    app.update(Action::ToggleKeyTeleop);
    app.take_requests();
    let keys = mech_gcs::ui::keys::on_key(
        &app,
        &crossterm::event::KeyEvent::new(
            crossterm::event::KeyCode::Char('w'),
            crossterm::event::KeyModifiers::NONE,
        ),
    );
    for a in keys {
        app.update(a);
    }
    let p = publishes(&app.take_requests());
    assert_eq!(p.len(), 1);
    assert_eq!(p[0].0, "key/0");
    assert_eq!(p[0].1, ["robot_4"]);
    assert!(matches!(p[0].2, Command::Twist(t) if t.vx > 0.0));
    app.update(Action::Tick(app.manual.now + Duration::from_secs(2)));
    let p = publishes(&app.take_requests());
    assert_eq!(p.last().map(|x| &x.2), Some(&Command::Stop(Stop {})));
}

#[test]
fn keyboard_teleop_climbs_with_r_and_descends_with_f() {
    let mut app = fixture::app(4, 80, 24);
    app.update(Action::Route {
        robot: "robot_4".into(),
        channel: "key/0".into(),
    });
    app.update(Action::ToggleKeyTeleop);
    app.take_requests();
    let mut vz = Vec::new();
    for key in ['r', 'f'] {
        let event = crossterm::event::KeyEvent::new(
            crossterm::event::KeyCode::Char(key),
            crossterm::event::KeyModifiers::NONE,
        );
        for a in mech_gcs::ui::keys::on_key(&app, &event) {
            app.update(a);
        }
        for (_, _, c) in publishes(&app.take_requests()) {
            if let Command::Twist(t) = c {
                vz.push(t.vz);
            }
        }
    }
    assert_eq!(vz.len(), 2, "{vz:?}");
    assert!(vz[0] > 0.0 && vz[1] < 0.0, "up, then down: {vz:?}");
    assert!(
        !app.waypoints.placing,
        "f is descend while teleop is on, not waypoint mode"
    );
}
