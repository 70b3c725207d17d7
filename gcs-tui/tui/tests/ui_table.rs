//! The fleet table, driven by `App::update(Action)` and the key bindings:
//! switching to it, sorting, the `/` filter, selection and clusters from
//! its rows, routing beside it, and the detail view.

use crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use mech_gcs::ui::fixture;
use mech_gcs::ui::keys::on_key;
use mech_gcs::ui::{Action, App, Column, Focus, Request, RobotsView};
use ratatui::Terminal;
use ratatui::backend::TestBackend;

fn screen(app: &App) -> String {
    let mut term = Terminal::new(TestBackend::new(app.screen.size.0, app.screen.size.1))
        .expect("test terminal");
    term.draw(|f| f.render_widget(app, f.area()))
        .expect("draws");
    term.backend().to_string()
}

fn press(app: &mut App, code: KeyCode) {
    press_with(app, code, KeyModifiers::NONE);
}

fn press_with(app: &mut App, code: KeyCode, modifiers: KeyModifiers) {
    for a in on_key(app, &KeyEvent::new(code, modifiers)) {
        app.update(a);
    }
}

fn typed(app: &mut App, text: &str) {
    for ch in text.chars() {
        press(app, KeyCode::Char(ch));
    }
}

/// Names in the table's rows, top to bottom.
fn rows(app: &App) -> Vec<String> {
    app.table
        .rows
        .iter()
        .map(|&i| app.fleet.robots[i].name.clone())
        .collect()
}

fn selected(app: &App) -> Vec<&str> {
    app.cards.selection.iter().map(String::as_str).collect()
}

/// `fixture::app` with the table shown.
fn table(n: usize, w: u16, h: u16) -> App {
    let mut app = fixture::app(n, w, h);
    press(&mut app, KeyCode::Char('v'));
    app
}

#[test]
fn v_shows_the_table_in_place_of_cards_and_map_and_back() {
    let mut app = table(12, 200, 50);
    assert_eq!(app.screen.robots_view, RobotsView::Table);
    assert_eq!(
        app.screen.focus,
        Focus::Cards,
        "the table takes the robot keys"
    );
    let areas = app.areas();
    assert!(areas.table.is_some() && areas.cards.is_none() && areas.map.is_empty());
    let text = screen(&app);
    assert!(text.contains("Fleet 12/12"), "{text}");
    assert!(text.contains("robot_12"), "every row fits: {text}");
    press(&mut app, KeyCode::Char('v'));
    assert_eq!(app.screen.robots_view, RobotsView::Cards);
    assert!(app.areas().cards.is_some());
}

#[test]
fn names_sort_naturally_and_any_column_sorts_either_way() {
    let mut app = table(12, 200, 50);
    assert_eq!(rows(&app)[..3], ["robot_1", "robot_2", "robot_3"]);
    assert_eq!(rows(&app)[9], "robot_10", "not after robot_1");
    app.update(Action::SortBy(Column::Name));
    assert_eq!(rows(&app)[0], "robot_12", "the same column again reverses");
    // The fixture's loss is (i % 5) * 6 %: robot_5 and robot_10 lose most.
    app.update(Action::SortBy(Column::Loss));
    assert_eq!(rows(&app)[..2], ["robot_1", "robot_6"], "ascending");
    press(&mut app, KeyCode::Char('r'));
    assert_eq!(rows(&app)[..2], ["robot_5", "robot_10"], "r reverses");
    press(&mut app, KeyCode::Char('>'));
    assert_eq!(app.table.sort, Column::Rtt);
    press(&mut app, KeyCode::Char('<'));
    press(&mut app, KeyCode::Char('<'));
    assert_eq!(app.table.sort, Column::Tx);
    let text = screen(&app);
    assert!(text.contains("sort tx/s ▲"), "{text}");
}

#[test]
fn slash_filters_as_it_is_typed_and_esc_clears() {
    let mut app = fixture::app(100, 200, 50);
    press(&mut app, KeyCode::Char('/'));
    assert_eq!(
        app.screen.robots_view,
        RobotsView::Table,
        "/ opens the table"
    );
    typed(&mut app, "robot_9");
    let want: Vec<String> = std::iter::once(9)
        .chain(90..=99)
        .map(|k| format!("robot_{k}"))
        .collect();
    assert_eq!(rows(&app), want);
    press(&mut app, KeyCode::Enter);
    assert!(app.prompt.open.is_none(), "Enter keeps the filter");
    let text = screen(&app);
    assert!(text.contains("Fleet 11/100"), "{text}");
    press(&mut app, KeyCode::Esc);
    assert_eq!(rows(&app).len(), 100, "Esc clears the filter");
    // By state: the fixture's lost robots.
    press(&mut app, KeyCode::Char('/'));
    typed(&mut app, "LOST");
    assert_eq!(rows(&app).len(), 25);
    press(&mut app, KeyCode::Esc);
    assert!(app.table.filter.is_empty() && app.prompt.open.is_none());
}

#[test]
fn rows_select_as_cards_do_in_the_order_shown() {
    let mut app = table(12, 200, 50);
    app.update(Action::SortBy(Column::Loss));
    app.update(Action::SortReverse);
    press(&mut app, KeyCode::Down);
    assert_eq!(selected(&app), ["robot_5"], "the first row");
    press(&mut app, KeyCode::Down);
    assert_eq!(selected(&app), ["robot_10"], "the next row, not robot_6");
    press_with(&mut app, KeyCode::Down, KeyModifiers::SHIFT);
    assert_eq!(selected(&app), ["robot_10", "robot_4"], "Shift adds");
    press(&mut app, KeyCode::Char(' '));
    assert_eq!(
        selected(&app),
        ["robot_10"],
        "Space takes the cursor's robot out"
    );
    press(&mut app, KeyCode::Char(' '));
    press(&mut app, KeyCode::Char('n'));
    assert_eq!(selected(&app), ["robot_9"], "n follows the table too");
    press(&mut app, KeyCode::End);
    assert_eq!(selected(&app), ["robot_11"], "no loss, in name order");
    press(&mut app, KeyCode::Home);
    assert_eq!(selected(&app), ["robot_5"]);
}

#[test]
fn a_cluster_is_made_from_rows_and_routing_works_beside_the_table() {
    let mut app = table(12, 200, 50);
    press(&mut app, KeyCode::Down);
    press_with(&mut app, KeyCode::Down, KeyModifiers::SHIFT);
    press_with(&mut app, KeyCode::Down, KeyModifiers::SHIFT);
    app.take_requests();
    press(&mut app, KeyCode::Char('c'));
    assert_eq!(
        app.take_requests(),
        [Request::DefineCluster {
            name: "c1".into(),
            members: vec!["robot_1".into(), "robot_2".into(), "robot_3".into()],
        }]
    );
    // Route the row under the cursor: Tab goes to the routing table (the
    // map is hidden), whose cursor is on the robot picked in the table.
    app.update(Action::SortBy(Column::Name));
    press(&mut app, KeyCode::Home);
    assert_eq!(selected(&app), ["robot_12"]);
    press(&mut app, KeyCode::Tab);
    press(&mut app, KeyCode::Tab);
    assert_eq!(app.screen.focus, Focus::Routes);
    press(&mut app, KeyCode::Right);
    press(&mut app, KeyCode::Enter);
    assert_eq!(
        app.take_requests(),
        [Request::Route {
            robot: "robot_12".into(),
            channel: "wp/gcs".into()
        }]
    );
    press(&mut app, KeyCode::Tab);
    assert_eq!(
        app.screen.focus,
        Focus::Cards,
        "past the hidden map, back to the table"
    );
}

#[test]
fn clicks_sort_by_a_header_and_select_rows() {
    let mut app = table(12, 200, 50);
    let t = app.areas().table.expect("table shown");
    let (header, first_row) = (t.y + 1, t.y + 2);
    // LINK is the third column: gutter 2, NAME 10, PLATFORM 10, spaces.
    let link_col = t.x + 1 + 2 + 11 + 11 + 1;
    app.update(Action::Click {
        col: link_col,
        row: header,
        add: false,
    });
    assert_eq!(app.table.sort, Column::Link);
    app.update(Action::Click {
        col: t.x + 5,
        row: first_row + 2,
        add: false,
    });
    assert_eq!(selected(&app), ["robot_5"], "third row by link");
    app.update(Action::Click {
        col: t.x + 5,
        row: first_row,
        add: true,
    });
    assert_eq!(selected(&app), ["robot_1", "robot_5"]);
}

#[test]
fn enter_shows_the_robot_in_detail_and_esc_goes_back() {
    let mut app = table(6, 160, 48);
    app.update(Action::Log(
        mech_gcs::ui::LogLevel::Warn,
        "robot_2 link stale".into(),
    ));
    app.update(Action::Log(
        mech_gcs::ui::LogLevel::Info,
        "robot_21 is someone else".into(),
    ));
    press(&mut app, KeyCode::Down);
    press(&mut app, KeyCode::Down);
    press(&mut app, KeyCode::Enter);
    assert!(app.table.detail);
    let text = screen(&app);
    assert!(text.contains("robot_2 #2 │ Enter/Esc back"), "{text}");
    assert!(text.contains("loss 6.0%"), "{text}");
    assert!(text.contains("received 1001, sent 201, lost 60"), "{text}");
    assert!(text.contains(" robot_2 link stale"), "{text}");
    assert!(!text.contains(" robot_21 is someone else"), "{text}");
    press(&mut app, KeyCode::Esc);
    assert!(!app.table.detail);
    assert_eq!(selected(&app), ["robot_2"], "Esc left the selection alone");
}

#[test]
fn the_cursor_stays_on_screen_in_a_long_table() {
    let mut app = table(1000, 120, 36);
    let page = app.table_page();
    press(&mut app, KeyCode::PageDown);
    press(&mut app, KeyCode::PageDown);
    let row = app.cursor_row().expect("cursor in the rows");
    assert!(row >= app.table.scroll && row < app.table.scroll + page);
    let name = app.table.cursor.clone().expect("a cursor");
    assert!(
        screen(&app).contains(&format!("▶ {name} ")),
        "drawn selected"
    );
}
