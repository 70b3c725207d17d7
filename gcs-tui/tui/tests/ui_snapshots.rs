//! Screen snapshots of the main screen with a fixed fleet.

use mech_gcs::ui::fixture;
use mech_gcs::ui::{Action, Select};
use mech_proto::Waypoint;
use ratatui::Terminal;
use ratatui::backend::TestBackend;

fn screen(app: &mech_gcs::ui::App, w: u16, h: u16) -> String {
    let mut term = Terminal::new(TestBackend::new(w, h)).expect("test terminal");
    term.draw(|f| f.render_widget(app, f.area()))
        .expect("draws");
    term.backend().to_string()
}

fn populated(w: u16, h: u16) -> mech_gcs::ui::App {
    let mut app = fixture::app(6, w, h);
    app.update(Action::Select(Select::Only("robot_1".into())));
    app.update(Action::Select(Select::Toggle("robot_2".into())));
    app.update(Action::MakeCluster);
    app.update(Action::Select(Select::Only("robot_1".into())));
    app.update(Action::AddWaypoint(Waypoint {
        x: 1.0,
        y: 1.0,
        z: 0.0,
        time: None,
    }));
    app.update(Action::AddWaypoint(Waypoint {
        x: -1.0,
        y: 0.5,
        z: 0.0,
        time: Some(12.0),
    }));
    app
}

#[test]
fn main_screen_80x24() {
    let app = populated(80, 24);
    insta::assert_snapshot!(screen(&app, 80, 24));
}

#[test]
fn main_screen_160x48() {
    let app = populated(160, 48);
    insta::assert_snapshot!(screen(&app, 160, 48));
}

#[test]
fn routes_panel_80x24() {
    let mut app = populated(80, 24);
    app.update(Action::FocusPrev);
    insta::assert_snapshot!(screen(&app, 80, 24));
}

#[test]
fn estop_banner_and_help_80x24() {
    let mut app = populated(80, 24);
    app.update(Action::EStop);
    insta::assert_snapshot!("estop", screen(&app, 80, 24));
    app.update(Action::ToggleHelp);
    insta::assert_snapshot!("help", screen(&app, 80, 24));
    app.update(Action::HelpScroll(100));
    insta::assert_snapshot!("help_scrolled", screen(&app, 80, 24));
}

#[test]
fn help_lists_every_key_across_its_pages() {
    let mut app = populated(80, 24);
    app.update(Action::ToggleHelp);
    let mut seen = String::new();
    for _ in 0..mech_gcs::ui::help::KEYS.len() {
        seen.push_str(&screen(&app, 80, 24));
        app.update(Action::HelpScroll(1));
    }
    for (k, d) in mech_gcs::ui::help::KEYS {
        assert!(seen.contains(k), "key {k} shown");
        assert!(seen.contains(d), "description of {k} shown whole");
    }
}

#[test]
fn monochrome_screen_keeps_the_text() {
    let mut app = populated(80, 24);
    let colour = screen(&app, 80, 24);
    app.session.monochrome = true;
    assert_eq!(colour, screen(&app, 80, 24), "same glyphs without colour");
}

#[test]
fn tiny_and_odd_terminal_sizes_render_without_panicking() {
    for (w, h) in [
        (1, 1),
        (5, 3),
        (20, 6),
        (40, 10),
        (79, 23),
        (119, 35),
        (300, 90),
    ] {
        let mut app = populated(w, h);
        app.update(Action::EStop);
        app.update(Action::ToggleHelp);
        app.update(Action::CommandResult(Err(mech_gcs::ui::PromptError {
            line: "route x".into(),
            message: "bad".into(),
            column: Some(99),
        })));
        let s = screen(&app, w, h);
        assert_eq!(s.lines().count(), usize::from(h), "{w}x{h}");
    }
}

#[test]
fn routes_panel_lists_pads_and_keyboard_teleop() {
    use mech_gcs::gamepad::{PadButton, PadEvent, PadEventKind};
    let mut app = populated(80, 24);
    app.update(Action::Pad(PadEvent::new(
        1,
        PadEventKind::Connected("Synthetic Pad".into()),
    )));
    app.update(Action::Pad(PadEvent::new(
        1,
        PadEventKind::ButtonPressed(PadButton::LeftBumper),
    )));
    app.update(Action::ToggleKeyTeleop);
    app.update(Action::FocusPrev);
    insta::assert_snapshot!(screen(&app, 80, 24));
}

/// A cluster under its controller: slot targets (◇) joined to the members,
/// the desired cluster pose (⊕) and heading, the measured pose (✚c1), and
/// per-member tracking errors in the routes panel.
#[test]
fn cluster_slots_and_tracking_errors_160x48() {
    use mech_gcs::ui::{ClusterControlView, ClusterOnScreen, SlotView};

    let mut app = populated(160, 48);
    let mut snap = fixture::fleet(6);
    let p1 = app.robot("robot_1").expect("robot_1").telemetry.pose;
    let p2 = app.robot("robot_2").expect("robot_2").telemetry.pose;
    let (cx, cy) = ((p1.x + p2.x) / 2.0, (p1.y + p2.y) / 2.0);
    snap.clusters = Some(vec![ClusterOnScreen {
        name: "c1".into(),
        members: vec!["robot_1".into(), "robot_2".into(), "robot_3".into()],
        control: Some(ClusterControlView {
            desired: Some((cx + 0.6, cy + 0.3, 0.0)),
            measured: Some((cx, cy, 0.0)),
            slots: vec![
                SlotView {
                    robot: "robot_1".into(),
                    x: p1.x + 0.6,
                    y: p1.y + 0.3,
                    error: 0.67,
                },
                SlotView {
                    robot: "robot_2".into(),
                    x: p2.x + 0.6,
                    y: p2.y + 0.3,
                    error: 0.04,
                },
            ],
            lost: vec![],
            absent: vec!["robot_3".into()],
        }),
    }]);
    app.update(Action::Fleet(snap));
    let text = screen(&app, 160, 48);
    assert!(text.contains("robot_1 67cm"), "{text}");
    assert!(text.contains("robot_2 4cm"), "{text}");
    assert!(text.contains('◇') && text.contains('⊕'), "{text}");
    insta::assert_snapshot!(text);
}

/// The fleet table in place of the cards and the map: every column at
/// 200x50, sorted by loss (worst first), robot_3 under the cursor.
#[test]
fn fleet_table_200x50() {
    let mut app = fixture::app(30, 200, 50);
    app.update(Action::ToggleTable);
    app.update(Action::SortBy(mech_gcs::ui::Column::Loss));
    app.update(Action::SortReverse);
    app.update(Action::Select(Select::Only("robot_3".into())));
    insta::assert_snapshot!(screen(&app, 200, 50));
}

/// At 120x36 the columns that matter most stay; filtered by `/robot_1`.
#[test]
fn fleet_table_filtered_120x36() {
    let mut app = fixture::app(30, 120, 36);
    app.update(Action::OpenFilter);
    for ch in "robot_1".chars() {
        app.update(Action::PromptChar(ch));
    }
    insta::assert_snapshot!(screen(&app, 120, 36));
}

/// One robot in detail at 120x36: its card and its charts (one sample: the
/// fixture has no past); the link's counters and its events need 30 rows.
#[test]
fn robot_detail_120x36() {
    let mut app = fixture::app(6, 120, 36);
    app.update(Action::Log(
        mech_gcs::ui::LogLevel::Warn,
        "robot_4 link lost".into(),
    ));
    app.update(Action::ToggleTable);
    app.update(Action::Select(Select::Only("robot_4".into())));
    app.update(Action::ToggleDetail);
    insta::assert_snapshot!(screen(&app, 120, 36));
}

#[test]
fn fleet_table_80x24() {
    let mut app = fixture::app(30, 80, 24);
    app.update(Action::ToggleTable);
    insta::assert_snapshot!(screen(&app, 80, 24));
}

/// Fleet safety on the screen: the station's arena on the map (boundary,
/// a keep-out crossed, a slow zone dotted, an obstacle disc), robot_1
/// limited at the fence (on its card), robot_2 with its layer switched off
/// (an alarm on its card and in the status bar).
#[test]
fn arena_intervention_and_safety_alarm_120x36() {
    use mech_gcs::ui::{ArenaShape, SafetyView};
    use mech_proto::{Disc, Intervention, Point, SafetyState, SlowZone};

    let p = |x, y| Point { x, y };
    let mut app = populated(120, 36);
    let mut snap = fixture::fleet(6);
    snap.arena = Some(ArenaShape {
        boundary: vec![p(-3.0, -3.0), p(3.0, -3.0), p(3.0, 3.0), p(-3.0, 3.0)],
        keep_out: vec![vec![p(-0.5, -0.5), p(0.5, -0.5), p(0.5, 0.5), p(-0.5, 0.5)]],
        slow_zones: vec![SlowZone {
            polygon: vec![p(1.0, -3.0), p(3.0, -3.0), p(3.0, -1.0), p(1.0, -1.0)],
            max_speed: 0.1,
        }],
        obstacles: vec![Disc {
            x: -2.0,
            y: -2.0,
            radius: 0.3,
        }],
        margin: 0.1,
    });
    snap.robots[0].safety = Some(SafetyView {
        state: SafetyState::On,
        intervention: Intervention::Fence,
        interventions: 3,
        alarm: false,
        footprint: 0.35,
        position_error: 0.05,
    });
    snap.robots[1].safety = Some(SafetyView {
        state: SafetyState::Off,
        intervention: Intervention::None,
        interventions: 0,
        alarm: true,
        footprint: 0.0,
        position_error: 0.0,
    });
    app.update(mech_gcs::ui::Action::Fleet(snap));
    let text = screen(&app, 120, 36);
    assert!(text.contains(" SAFETY OFF robot_2 "), "status bar: {text}");
    assert!(text.contains("#2 SAFETY OFF"), "robot_2's card: {text}");
    assert!(text.contains(" ok fence"), "robot_1's card: {text}");
    assert!(text.contains("±5cm"), "robot_1's position error: {text}");
    insta::assert_snapshot!(text);
}

/// The station's arena without anything else: at 80x24 the status bar
/// still shows the alarm first.
#[test]
fn the_safety_alarm_fits_a_narrow_status_bar() {
    use mech_gcs::ui::SafetyView;
    use mech_proto::{Intervention, SafetyState};

    let mut app = populated(80, 24);
    let mut snap = fixture::fleet(6);
    for r in &mut snap.robots[2..5] {
        r.safety = Some(SafetyView {
            state: SafetyState::Off,
            intervention: Intervention::None,
            interventions: 0,
            alarm: true,
            footprint: 0.0,
            position_error: 0.0,
        });
    }
    app.update(mech_gcs::ui::Action::Fleet(snap));
    let text = screen(&app, 80, 24);
    let bar = text.lines().next().unwrap();
    assert!(bar.contains(" SAFETY OFF 3 robots "), "{bar}");
}

/// A robot's last minute in charts, and the fleet table's trend of the
/// column it is sorted by: robot_1 was sent three waypoints from this TUI
/// (its cross-track error is measured against them), then a minute of
/// the fixture fleet played in.
fn with_a_minute(w: u16, h: u16) -> mech_gcs::ui::App {
    let mut app = fixture::app(6, w, h);
    app.update(Action::Select(Select::Only("robot_1".into())));
    for (x, y) in [(1.0, 0.4), (1.4, 1.0), (0.0, 1.5)] {
        app.update(Action::AddWaypoint(Waypoint {
            x,
            y,
            z: 0.0,
            time: None,
        }));
    }
    app.update(Action::SendWaypoints);
    app.take_requests();
    fixture::minute(&mut app, 6);
    app.update(Action::ToggleTable);
    app
}

#[test]
fn robot_detail_plots_80x24() {
    let mut app = with_a_minute(80, 24);
    app.update(Action::ToggleDetail);
    insta::assert_snapshot!(screen(&app, 80, 24));
}

#[test]
fn robot_detail_plots_200x50() {
    let mut app = with_a_minute(200, 50);
    app.update(Action::ToggleDetail);
    insta::assert_snapshot!(screen(&app, 200, 50));
}

#[test]
fn fleet_table_trend_of_the_sort_column_80x24() {
    let mut app = with_a_minute(80, 24);
    app.update(Action::SortBy(mech_gcs::ui::Column::Loss));
    app.update(Action::SortReverse);
    insta::assert_snapshot!(screen(&app, 80, 24));
}
