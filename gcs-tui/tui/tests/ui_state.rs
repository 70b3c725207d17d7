//! UI state changes, driven by `App::update(Action)` and the key bindings.

use crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use mech_gcs::ui::fixture;
use mech_gcs::ui::keys::on_key;
use mech_gcs::ui::{Action, App, Prompt, Request, Select};
use mech_proto::Waypoint;
use ratatui::Terminal;
use ratatui::backend::TestBackend;

fn render(app: &App) -> ratatui::buffer::Buffer {
    let mut term = Terminal::new(TestBackend::new(app.screen.size.0, app.screen.size.1))
        .expect("test terminal");
    term.draw(|f| f.render_widget(app, f.area()))
        .expect("draws");
    term.backend().buffer().clone()
}

/// Cell (absolute) where a robot's glyph was drawn on the map.
fn drawn_robot_cell(app: &App, name: &str) -> (u16, u16) {
    let buf = render(app);
    let inner = app.areas().map_inner();
    let r = app.robot(name).expect("robot exists");
    let right = inner.x + inner.width;
    for row in inner.y..inner.y + inner.height {
        for col in inner.x..right.saturating_sub(2) {
            let g = buf[(col, row)].symbol();
            let label: String = (col + 2..(col + 2 + r.name.len() as u16).min(right))
                .map(|c| buf[(c, row)].symbol())
                .collect();
            if (g == "●" || g == "◉") && label == r.name {
                return (col, row);
            }
        }
    }
    panic!("{name} not drawn on the map");
}

fn key(code: KeyCode) -> KeyEvent {
    KeyEvent::new(code, KeyModifiers::NONE)
}

#[test]
fn clicking_a_robot_selects_it_and_shift_click_adds() {
    let mut app = fixture::app(6, 160, 48);
    let (c, r) = drawn_robot_cell(&app, "robot_3");
    app.update(Action::Click {
        col: c,
        row: r,
        add: false,
    });
    assert_eq!(app.cards.selection.iter().collect::<Vec<_>>(), ["robot_3"]);
    let (c, r) = drawn_robot_cell(&app, "robot_5");
    app.update(Action::Click {
        col: c,
        row: r,
        add: true,
    });
    assert_eq!(
        app.cards.selection.iter().collect::<Vec<_>>(),
        ["robot_3", "robot_5"]
    );
}

#[test]
fn clicking_a_card_selects_its_robot() {
    let mut app = fixture::app(6, 80, 24);
    let cards = app.areas().cards.expect("cards shown");
    // Third card: two cards down inside the border.
    app.update(Action::Click {
        col: cards.x + 3,
        row: cards.y + 1 + 2 * mech_gcs::ui::layout::CARD_HEIGHT as u16,
        add: false,
    });
    assert_eq!(app.cards.selection.iter().collect::<Vec<_>>(), ["robot_3"]);
}

#[test]
fn keys_cycle_select_all_and_clear() {
    let mut app = fixture::app(4, 80, 24);
    for a in on_key(&app, &key(KeyCode::Char('n'))) {
        app.update(a);
    }
    assert!(app.cards.selection.contains("robot_1"));
    app.update(Action::Select(Select::Next));
    app.update(Action::Select(Select::Next));
    assert_eq!(app.cards.selection.iter().collect::<Vec<_>>(), ["robot_3"]);
    app.update(Action::Select(Select::Prev));
    assert_eq!(app.cards.selection.iter().collect::<Vec<_>>(), ["robot_2"]);
    app.update(Action::Select(Select::AddNext));
    assert_eq!(app.cards.selection.len(), 2);
    app.update(Action::Select(Select::All));
    assert_eq!(app.cards.selection.len(), 4);
    app.update(Action::Select(Select::Clear));
    assert!(app.cards.selection.is_empty());
}

#[test]
fn cluster_from_selection_is_listed_and_requested() {
    let mut app = fixture::app(4, 80, 24);
    app.update(Action::Select(Select::Only("robot_2".into())));
    app.update(Action::MakeCluster);
    assert!(app.fleet.clusters.is_empty(), "one robot is not a cluster");
    app.update(Action::Select(Select::Toggle("robot_4".into())));
    app.take_requests();
    app.update(Action::MakeCluster);
    assert_eq!(app.fleet.clusters.len(), 1);
    assert_eq!(app.fleet.clusters[0].name, "c1");
    assert_eq!(app.fleet.clusters[0].members, ["robot_2", "robot_4"]);
    assert_eq!(
        app.take_requests(),
        vec![Request::DefineCluster {
            name: "c1".into(),
            members: vec!["robot_2".into(), "robot_4".into()]
        }]
    );
    app.update(Action::Select(Select::Clear));
    for a in on_key(&app, &key(KeyCode::Char('1'))) {
        app.update(a);
    }
    assert_eq!(app.cards.selection.len(), 2, "1 selects cluster c1");
}

#[test]
fn waypoint_click_lands_in_metres_under_zoom_and_pan() {
    let mut app = fixture::app(6, 160, 48);
    app.update(Action::Zoom(1.6));
    app.update(Action::Pan(3.0, -2.0));
    app.update(Action::WaypointMode(true));

    // 1. Exact arithmetic: the click maps to the centre of the clicked cell.
    let inner = app.areas().map_inner();
    let v = app.map.viewport;
    let (col, row) = (inner.x + 7, inner.y + 5);
    app.update(Action::Click {
        col,
        row,
        add: false,
    });
    let m = v.metres_per_dot;
    let want_x = v.centre_x - f64::from(inner.width) * m + (2.0 * 7.0 + 1.0) * m;
    let want_y = v.centre_y + f64::from(inner.height) * 2.0 * m - (4.0 * 5.0 + 2.0) * m;
    let w = app.waypoints.list[0];
    assert!(
        (w.x - want_x).abs() < 1e-9 && (w.y - want_y).abs() < 1e-9,
        "{w:?}"
    );

    // 2. Agreement with the drawing: clicking where robot_2 is drawn places
    //    the waypoint on robot_2, within half a cell.
    let (c, r) = drawn_robot_cell(&app, "robot_2");
    app.update(Action::Click {
        col: c,
        row: r,
        add: false,
    });
    let w = app.waypoints.list[1];
    let pose = app.robot("robot_2").expect("robot_2").telemetry.pose;
    assert!((w.x - pose.x).abs() <= m + 1e-9, "x {} vs {}", w.x, pose.x);
    assert!(
        (w.y - pose.y).abs() <= 2.0 * m + 1e-9,
        "y {} vs {}",
        w.y,
        pose.y
    );
    assert!(
        app.cards.selection.is_empty(),
        "waypoint mode clicks do not select"
    );
}

#[test]
fn typed_waypoints_edit_and_send_to_the_selection() {
    let mut app = fixture::app(4, 80, 24);
    app.update(Action::Select(Select::Only("robot_2".into())));
    app.update(Action::WaypointMode(true));
    for a in on_key(&app, &key(KeyCode::Char('e'))) {
        app.update(a);
    }
    for ch in "1.5,-0.5,8".chars() {
        app.update(Action::PromptChar(ch));
    }
    app.update(Action::PromptSubmit);
    app.update(Action::OpenWaypointEntry);
    for ch in "2,x".chars() {
        app.update(Action::PromptChar(ch));
    }
    app.update(Action::PromptSubmit);
    let err = app.prompt.error.clone().expect("bad waypoint reported");
    assert_eq!(err.column, Some(2), "points at the bad field");
    assert!(
        matches!(app.prompt.open, Some(Prompt::Waypoint(_))),
        "stays open"
    );
    app.update(Action::PromptCancel);
    app.update(Action::AddWaypoint(Waypoint {
        x: 0.0,
        y: 0.0,
        z: 0.0,
        time: None,
    }));
    app.update(Action::AddWaypoint(Waypoint {
        x: 9.0,
        y: 9.0,
        z: 0.0,
        time: None,
    }));
    for a in on_key(&app, &key(KeyCode::Backspace)) {
        app.update(a);
    }
    assert_eq!(app.waypoints.list.len(), 2);
    app.take_requests();
    for a in on_key(&app, &key(KeyCode::Enter)) {
        app.update(a);
    }
    assert_eq!(
        app.take_requests(),
        vec![Request::Mission {
            robots: vec!["robot_2".into()],
            waypoints: vec![
                Waypoint {
                    x: 1.5,
                    y: -0.5,
                    z: 0.0,
                    time: Some(8.0)
                },
                Waypoint {
                    x: 0.0,
                    y: 0.0,
                    z: 0.0,
                    time: None
                },
            ]
        }]
    );
    for a in on_key(&app, &key(KeyCode::Esc)) {
        app.update(a);
    }
    assert!(!app.waypoints.placing);
    app.update(Action::ClearWaypoints);
    assert!(app.waypoints.list.is_empty());
}

#[test]
fn route_change_from_the_table_cursor() {
    let mut app = fixture::app(4, 80, 24);
    app.update(Action::FocusPrev); // map -> routes
    let cols = app.route_columns();
    let key0 = cols
        .iter()
        .position(|c| c == "key/0")
        .expect("key/0 column");
    for a in on_key(&app, &key(KeyCode::Down)) {
        app.update(a);
    }
    for _ in 0..key0 {
        for a in on_key(&app, &key(KeyCode::Right)) {
            app.update(a);
        }
    }
    app.take_requests();
    for a in on_key(&app, &key(KeyCode::Enter)) {
        app.update(a);
    }
    assert_eq!(
        app.take_requests(),
        vec![Request::Route {
            robot: "robot_2".into(),
            channel: "key/0".into()
        }]
    );
    let r = app.robot("robot_2").expect("robot_2");
    assert_eq!(r.route.channel, "key/0");
    assert!(
        !r.route.acknowledged,
        "pending until the core reports the ack"
    );
    app.update(Action::Route {
        robot: "robot_99".into(),
        channel: "joy/0".into(),
    });
    assert!(app.take_requests().is_empty(), "unknown robot is refused");
}

#[test]
fn estop_key_works_in_every_mode_and_shows_a_banner() {
    let mut app = fixture::app(4, 80, 24);
    let shift_x = KeyEvent::new(KeyCode::Char('X'), KeyModifiers::SHIFT);
    let ctrl_x = KeyEvent::new(KeyCode::Char('x'), KeyModifiers::CONTROL);
    let modes: [fn(&mut App); 5] = [
        |_| {},
        |a| a.update(Action::ToggleHelp),
        |a| a.update(Action::WaypointMode(true)),
        |a| a.update(Action::ToggleKeyTeleop),
        |a| a.update(Action::FocusPrev),
    ];
    for enter in &modes {
        let mut a = fixture::app(4, 80, 24);
        enter(&mut a);
        assert_eq!(on_key(&a, &shift_x), vec![Action::EStop]);
        assert_eq!(on_key(&a, &ctrl_x), vec![Action::EStop]);
    }
    app.update(Action::OpenCommandLine);
    assert_eq!(on_key(&app, &ctrl_x), vec![Action::EStop], "typing: Ctrl+X");
    assert_eq!(
        on_key(&app, &shift_x),
        vec![Action::PromptChar('X')],
        "typing: X is a letter"
    );
    app.update(Action::PromptCancel);

    app.take_requests();
    app.update(Action::EStop);
    assert!(app.fleet.estop);
    assert_eq!(app.take_requests(), vec![Request::EStop { engage: true }]);
    let screen = format!("{:?}", render(&app));
    assert!(screen.contains("E-STOP ENGAGED"));
    app.update(Action::Release);
    assert_eq!(app.take_requests(), vec![Request::EStop { engage: false }]);
    assert!(!format!("{:?}", render(&app)).contains("E-STOP ENGAGED"));
}

#[test]
fn command_line_runs_through_the_core_with_history() {
    let mut app = fixture::app(2, 80, 24);
    for line in ["route robot_1 joy/0", "estop"] {
        app.update(Action::OpenCommandLine);
        for ch in line.chars() {
            app.update(Action::PromptChar(ch));
        }
        app.update(Action::PromptSubmit);
    }
    assert_eq!(
        app.take_requests(),
        vec![
            Request::Exec("route robot_1 joy/0".into()),
            Request::Exec("estop".into())
        ]
    );
    app.update(Action::OpenCommandLine);
    app.update(Action::HistoryPrev);
    app.update(Action::HistoryPrev);
    assert_eq!(
        app.prompt.open,
        Some(Prompt::Command("route robot_1 joy/0".into()))
    );
    app.update(Action::HistoryNext);
    assert_eq!(app.prompt.open, Some(Prompt::Command("estop".into())));
    app.update(Action::PromptCancel);
    app.update(Action::CommandResult(Ok(
        "2 channels\n joy/0 gcs\n wp/gcs gcs".into(),
    )));
    let tail: Vec<&str> = app
        .events
        .iter()
        .rev()
        .take(3)
        .map(|l| l.text.as_str())
        .collect();
    assert_eq!(
        tail,
        [" wp/gcs gcs", " joy/0 gcs", "2 channels"],
        "details logged line by line"
    );
    app.update(Action::CommandResult(Err(mech_gcs::ui::PromptError {
        line: "route robot_9 joy/0".into(),
        message: "no robot robot_9".into(),
        column: Some(6),
    })));
    let screen = format!("{:?}", render(&app));
    assert!(screen.contains("      ^ no robot robot_9"), "{screen}");
}

#[test]
fn zoom_keys_and_wheel_change_scale_fit_restores() {
    let mut app = fixture::app(4, 80, 24);
    let fitted = app.map.viewport;
    for a in on_key(&app, &key(KeyCode::Char('+'))) {
        app.update(a);
    }
    assert!(app.map.viewport.metres_per_dot < fitted.metres_per_dot);
    let inner = app.areas().map_inner();
    let (c, r) = (inner.x + 4, inner.y + 3);
    let before = app.map_point(c, r).expect("on map");
    app.update(Action::Scroll {
        col: c,
        row: r,
        steps: 2,
    });
    let after = app.map_point(c, r).expect("on map");
    assert!((before.0 - after.0).abs() < 1e-9 && (before.1 - after.1).abs() < 1e-9);
    app.update(Action::FitFleet);
    assert_eq!(app.map.viewport, fitted);
}

#[test]
fn clicking_a_routes_cell_picks_it_and_a_second_click_routes() {
    let mut app = fixture::app(4, 160, 48);
    let routes = app.areas().routes.expect("routes panel shown");
    let cols = app.route_columns();
    let wp = cols
        .iter()
        .position(|c| c == "wp/gcs")
        .expect("wp/gcs column");
    // Rows: border, header, robot_1, robot_2 ...; columns: border, 9-wide
    // name and a space, then 7-wide channel cells.
    let col = routes.x + 1 + 10 + 7 * wp as u16 + 1;
    let row = routes.y + 1 + 1 + 3; // robot_4
    app.take_requests();
    app.update(Action::Click {
        col,
        row,
        add: false,
    });
    assert_eq!(app.routes.cursor, (3, wp));
    assert!(app.take_requests().is_empty(), "first click only picks");
    app.update(Action::Click {
        col,
        row,
        add: false,
    });
    assert_eq!(
        app.take_requests(),
        vec![Request::Route {
            robot: "robot_4".into(),
            channel: "wp/gcs".into()
        }]
    );
}

#[test]
fn dragging_the_map_pans_it_with_the_pointer() {
    let mut app = fixture::app(4, 160, 48);
    let inner = app.areas().map_inner();
    // A corner cell, away from every robot.
    let (c, r) = (inner.x + 1, inner.y + 1);
    assert!(app.robot_at_cell(c, r).is_none());
    let grabbed = app.map_point(c, r).expect("on map");
    app.update(Action::Click {
        col: c,
        row: r,
        add: false,
    });
    app.update(Action::Drag {
        col: c + 5,
        row: r + 3,
    });
    app.update(Action::MouseUp);
    let under = app.map_point(c + 5, r + 3).expect("on map");
    assert!((under.0 - grabbed.0).abs() < 1e-9 && (under.1 - grabbed.1).abs() < 1e-9);
    assert!(app.cards.selection.is_empty());
}

#[test]
fn nav_toggle_asks_for_the_selected_robots_only() {
    let mut app = fixture::app(4, 80, 24);
    app.update(Action::ToggleNav);
    assert!(app.take_requests().is_empty(), "nothing selected");
    assert!(app.events.iter().any(|l| l.text.contains("select a robot")));

    app.update(Action::Select(Select::Only("robot_3".into())));
    app.update(Action::Select(Select::Toggle("robot_1".into())));
    app.update(Action::ToggleNav);
    assert_eq!(
        app.take_requests(),
        [Request::ToggleNav {
            robots: vec!["robot_1".into(), "robot_3".into()]
        }]
    );
}

/// `R` asks the station to toggle recording.
#[test]
fn the_record_key_toggles_recording_at_the_station() {
    let mut app = fixture::app(2, 80, 24);
    for a in on_key(&app, &key(KeyCode::Char('R'))) {
        app.update(a);
    }
    assert_eq!(
        app.take_requests(),
        vec![Request::Exec("record toggle".into())]
    );
}

/// A waypoint past a mission's limit is not added, and the operator is told.
#[test]
fn a_waypoint_past_the_limit_is_refused_with_a_message() {
    let mut app = fixture::app(2, 80, 24);
    let w = |x: f64| mech_proto::Waypoint {
        x,
        y: 0.0,
        z: 0.0,
        time: None,
    };
    for i in 0..mech_proto::MAX_WAYPOINTS {
        app.update(Action::AddWaypoint(w(i as f64)));
    }
    let before = app.events.len();
    app.update(Action::AddWaypoint(w(-1.0)));
    assert_eq!(app.waypoints.list.len(), mech_proto::MAX_WAYPOINTS);
    assert_eq!(app.events.len(), before + 1);
    assert!(
        app.events
            .last()
            .is_some_and(|l| l.text.contains("at most 1024 waypoints")),
        "{:?}",
        app.events.last()
    );
}
/// The core lists robots as text (robot_1, robot_10, robot_2); the screen
/// shows them in natural order, and next/previous follow it.
#[test]
fn robots_are_listed_in_natural_name_order() {
    let mut snap = fixture::fleet(12);
    snap.robots.sort_by(|a, b| a.name.cmp(&b.name));
    assert_eq!(snap.robots[2].name, "robot_11", "text order");
    let mut app = fixture::app(0, 160, 48);
    app.update(Action::Fleet(snap));
    let names: Vec<&str> = app.fleet.robots.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(names[..3], ["robot_1", "robot_2", "robot_3"]);
    assert_eq!(names[11], "robot_12");
    app.update(Action::Select(Select::Only("robot_9".into())));
    app.update(Action::Select(Select::Next));
    assert_eq!(app.cards.selection.iter().collect::<Vec<_>>(), ["robot_10"]);
}

/// A card's last line is the link as the router measures it.
#[test]
fn a_card_shows_the_link_quality() {
    let app = fixture::app(3, 160, 48);
    let buf = render(&app);
    let cards = app.areas().cards.expect("cards shown");
    let text: String = (cards.y..cards.y + cards.height)
        .map(|row| {
            (cards.x..cards.x + cards.width)
                .map(|col| buf[(col, row)].symbol())
                .collect::<String>()
                + "\n"
        })
        .collect();
    // robot_2: rx 20/s, tx 14/s, loss 6.0 %, rtt 1.0 ms (the fixture).
    assert!(
        text.contains("rx 20/s tx 14/s loss 6.0% rtt 1.00ms"),
        "{text}"
    );
}

/// The pointer over a robot on the map makes it the hovered one (always
/// labelled); off it, none.
#[test]
fn hovering_a_robot_on_the_map_marks_it() {
    let mut app = fixture::app(6, 160, 48);
    let (c, r) = drawn_robot_cell(&app, "robot_4");
    app.update(Action::Hover { col: c, row: r });
    assert_eq!(app.map.hover.as_deref(), Some("robot_4"));
    let inner = app.areas().map_inner();
    app.update(Action::Hover {
        col: inner.x,
        row: inner.y,
    });
    assert_eq!(app.map.hover, None);
}

/// A crowded map: its title counts the labels left out, every label the
/// placer kept is on the screen where it says, and the robot under the
/// pointer is labelled even in the crowd.
#[test]
fn a_crowded_map_counts_its_hidden_labels_and_labels_the_hovered_robot() {
    use mech_gcs::ui::labels::Kind;
    use mech_gcs::ui::map::map_text as on_map;
    let mut app = fixture::app(100, 120, 36);
    let labelled = |t: &mech_gcs::ui::labels::MapText, i: usize| {
        t.texts.iter().any(|p| p.kind == Kind::Robot(i))
    };
    let before = on_map(&app);
    let unlabelled = (0..100)
        .find(|&i| !labelled(&before, i))
        .expect("100 robots at 120x36 leave some unlabelled");
    app.map.hover = Some(app.fleet.robots[unlabelled].name.clone());
    let text = on_map(&app);
    assert!(labelled(&text, unlabelled), "the hovered robot is labelled");
    assert!(text.hidden > 0);
    let buf = render(&app);
    let inner = app.areas().map_inner();
    let title: String = (inner.x..inner.x + inner.width)
        .map(|c| buf[(c, inner.y - 1)].symbol().to_string())
        .collect();
    assert!(
        title.contains(&format!("{} labels hidden", text.hidden)),
        "{title}"
    );
    for p in &text.texts {
        let drawn: String = (0..p.width())
            .map(|k| {
                buf[(inner.x + p.col + k, inner.y + p.row)]
                    .symbol()
                    .to_string()
            })
            .collect();
        assert_eq!(drawn, p.text, "{p:?} drawn where placed");
    }
}

/// The map fits the fleet once robots say where they are: a robot that has
/// only registered reads as the origin and is not fitted to.
#[test]
fn the_map_fits_the_first_robots_that_reported_a_position() {
    let mut app = App::new("127.0.0.1:7400", std::time::Instant::now());
    app.update(Action::Resize(160, 48));
    let at = |x: f64, y: f64| mech_gcs::ui::FleetSnapshot {
        robots: vec![mech_gcs::ui::RobotView::at("robot_1", 1, "kiwi", x, y, 0.0)],
        ..Default::default()
    };
    app.update(Action::Fleet(at(0.0, 0.0)));
    assert_eq!(
        (app.map.viewport.centre_x, app.map.viewport.centre_y),
        (0.0, 0.0)
    );
    app.update(Action::Fleet(at(6.0, 4.0)));
    let (x, y) = (app.map.viewport.centre_x, app.map.viewport.centre_y);
    assert!((x - 6.0).abs() < 0.5 && (y - 4.0).abs() < 0.5, "{x} {y}");
    // Once: after that the operator's view is left alone.
    app.update(Action::Fleet(at(9.0, 9.0)));
    assert_eq!(
        (app.map.viewport.centre_x, app.map.viewport.centre_y),
        (x, y)
    );
}

#[test]
fn waypoints_for_a_robot_not_routed_to_them_say_so_and_offer_the_route() {
    let mut app = fixture::app(4, 160, 48);
    // robot_1 is routed to wp/gcs, robot_2 to joy/0 (the fixture).
    app.update(Action::Select(Select::Only("robot_2".into())));
    app.update(Action::AddWaypoint(Waypoint {
        x: 1.0,
        y: 1.0,
        z: 0.0,
        time: None,
    }));
    app.update(Action::SendWaypoints);
    let log: Vec<String> = app.events.iter().map(|l| l.text.clone()).collect();
    assert!(
        log.iter().any(|l| l.contains(
            "robot_2 is routed to joy/0: it follows these waypoints only once routed to wp/gcs"
        )),
        "{log:#?}"
    );
    assert!(
        app.prompt.open.is_none(),
        "the keyboard stays the operator's"
    );
    app.update(Action::OpenCommandLine);
    app.update(Action::HistoryPrev);
    assert_eq!(
        app.prompt.open,
        Some(Prompt::Command("route robot_2 wp/gcs".into()))
    );

    // Routed to the mission's channel: no hint, nothing offered.
    app.update(Action::PromptCancel);
    app.update(Action::Select(Select::Only("robot_1".into())));
    let before = app.events.iter().count();
    let history = app.prompt.history.clone();
    app.update(Action::SendWaypoints);
    let added: Vec<String> = app
        .events
        .iter()
        .skip(before)
        .map(|l| l.text.clone())
        .collect();
    assert!(added.iter().all(|l| !l.contains("routed to")), "{added:#?}");
    assert_eq!(app.prompt.history, history);
}

/// Backspace, Delete and Enter edit and send the waypoints from the map
/// (the panel focused at start) and the cards too, not only in waypoint
/// mode or the waypoint list: after typing one with `e`, Enter sends it.
#[test]
fn waypoint_keys_work_from_the_map_and_the_cards() {
    let mut app = fixture::app(4, 160, 48);
    app.update(Action::Select(Select::Only("robot_1".into())));
    let press = |app: &mut App, code| {
        for a in on_key(app, &key(code)) {
            app.update(a);
        }
    };
    let wp = |x| Waypoint {
        x,
        y: 0.0,
        z: 0.0,
        time: None,
    };
    for x in [1.0, 2.0, 3.0] {
        app.update(Action::AddWaypoint(wp(x)));
    }
    assert!(!app.waypoints.placing);
    press(&mut app, KeyCode::Backspace);
    assert_eq!(app.waypoints.list.len(), 2, "Backspace on the map");
    app.take_requests();
    press(&mut app, KeyCode::Enter);
    assert_eq!(
        app.take_requests(),
        vec![Request::Mission {
            robots: vec!["robot_1".into()],
            waypoints: vec![wp(1.0), wp(2.0)],
        }],
        "Enter on the map sends"
    );
    press(&mut app, KeyCode::Tab);
    press(&mut app, KeyCode::Delete);
    assert!(app.waypoints.list.is_empty(), "Delete on the cards");
}
