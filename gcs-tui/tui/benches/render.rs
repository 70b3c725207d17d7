//! Frame render time: the full screen for 200 and 1,000 robots (with 10 s
//! paths and a cluster, the map's labels laid out) on a 200x50 terminal,
//! and 1,000 robots in the fleet table (sorted by name, and filtered).
//! Target: <= 2 ms per frame (p99).

use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
use mech_gcs::ui::fixture;
use mech_gcs::ui::keys::on_key;
use mech_gcs::ui::{Action, Select};
use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::widgets::Widget;

fn app_with_paths(n: usize, w: u16, h: u16) -> mech_gcs::ui::App {
    let mut app = fixture::app(n, w, h);
    // 10 s of path at 10 Hz: every robot drifted along its heading.
    let mut snap = fixture::fleet(n);
    for r in &mut snap.robots {
        let (x0, y0) = (r.telemetry.pose.x, r.telemetry.pose.y);
        r.trail = (0..100u32)
            .map(|k| {
                let f = f64::from(k) * 0.01;
                (
                    x0 + f * r.telemetry.pose.heading.cos(),
                    y0 + f * r.telemetry.pose.heading.sin(),
                )
            })
            .collect();
        if let Some(&(x, y)) = r.trail.last() {
            r.telemetry.pose.x = x;
            r.telemetry.pose.y = y;
        }
    }
    app.update(Action::Fleet(snap));
    app.update(Action::Select(Select::All));
    app.update(Action::MakeCluster);
    app.update(Action::Select(Select::Only("robot_1".into())));
    app
}

/// CPU time this thread has used: unlike the wall clock, it leaves out
/// the time other processes had the CPU (on a loaded 2-core machine those
/// preemptions, not the drawing, make the wall clock's p99).
fn thread_cpu() -> Duration {
    let ts = rustix::time::clock_gettime(rustix::time::ClockId::ThreadCPUTime);
    Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32)
}

/// Renders `app` 500 times and prints the frame time's percentiles, wall
/// clock and CPU.
fn percentiles(what: &str, app: &mech_gcs::ui::App) {
    let (w, h) = app.screen.size;
    let area = Rect::new(0, 0, w, h);
    let mut buf = Buffer::empty(area);
    let (mut wall, mut cpu) = (Vec::with_capacity(500), Vec::with_capacity(500));
    for _ in 0..500 {
        buf.reset();
        let (t, c) = (Instant::now(), thread_cpu());
        app.render(area, &mut buf);
        cpu.push(thread_cpu() - c);
        wall.push(t.elapsed());
    }
    let pct = |v: &mut Vec<Duration>, p: f64| {
        v.sort();
        v[((v.len() - 1) as f64 * p) as usize]
    };
    println!(
        "render {what} @ {w}x{h}: wall p50 {:?} p99 {:?}; cpu p50 {:?} p99 {:?}",
        pct(&mut wall, 0.5),
        pct(&mut wall, 0.99),
        pct(&mut cpu, 0.5),
        pct(&mut cpu, 0.99),
    );
}

/// `n` robots in the fleet table (`v`), sorted by name; with `filter`
/// typed after `/` when given.
fn table_app(n: usize, w: u16, h: u16, filter: Option<&str>) -> mech_gcs::ui::App {
    let mut app = app_with_paths(n, w, h);
    app.update(Action::ToggleTable);
    if let Some(text) = filter {
        let keys = std::iter::once('/').chain(text.chars()).map(KeyCode::Char);
        for code in keys.chain([KeyCode::Enter]) {
            for a in on_key(&app, &KeyEvent::new(code, KeyModifiers::NONE)) {
                app.update(a);
            }
        }
    }
    app
}

fn render(c: &mut Criterion) {
    percentiles("1000 robots, map", &app_with_paths(1000, 200, 50));
    percentiles("1000 robots, table", &table_app(1000, 200, 50, None));
    let filtered = table_app(1000, 200, 50, Some("robot_9"));
    percentiles("1000 robots, table /robot_9", &filtered);
    percentiles("4 robots, map", &app_with_paths(4, 80, 24));
    let (w, h) = (200, 50);
    let app = app_with_paths(200, w, h);
    let area = Rect::new(0, 0, w, h);
    let mut buf = Buffer::empty(area);
    percentiles("200 robots, map", &app);
    c.bench_function("render_200_robots_200x50", |b| {
        b.iter(|| {
            buf.reset();
            (&app).render(area, &mut buf);
        })
    });
    let table = table_app(1000, w, h, None);
    c.bench_function("render_1000_robots_table_200x50", |b| {
        b.iter(|| {
            buf.reset();
            (&table).render(area, &mut buf);
        })
    });
}

criterion_group!(benches, render);
criterion_main!(benches);
