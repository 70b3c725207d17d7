//! Frame render time: the full screen for 200 robots (with 10 s paths and a
//! cluster) on a 200x50 terminal. Target: <= 2 ms per frame.

use std::time::Instant;

use criterion::{Criterion, criterion_group, criterion_main};
use mech_gcs::ui::fixture;
use mech_gcs::ui::{Action, Select};
use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::widgets::Widget;

fn app_with_paths(n: usize, w: u16, h: u16) -> mech_gcs::ui::App {
    let mut app = fixture::app(n, w, h);
    // 10 s of path at 10 Hz: every robot drifted along its heading.
    let mut snap = fixture::fleet(n);
    for r in &mut snap.robots {
        let (x0, y0) = (r.pose.x, r.pose.y);
        r.trail = (0..100u32)
            .map(|k| {
                let f = f64::from(k) * 0.01;
                (x0 + f * r.pose.heading.cos(), y0 + f * r.pose.heading.sin())
            })
            .collect();
        if let Some(&(x, y)) = r.trail.last() {
            r.pose.x = x;
            r.pose.y = y;
        }
    }
    app.update(Action::Fleet(snap));
    app.update(Action::Select(Select::All));
    app.update(Action::MakeCluster);
    app.update(Action::Select(Select::Only("robot_1".into())));
    app
}

fn percentiles(n: usize, w: u16, h: u16) {
    let app = app_with_paths(n, w, h);
    let area = Rect::new(0, 0, w, h);
    let mut buf = Buffer::empty(area);
    let mut samples = Vec::with_capacity(200);
    for _ in 0..200 {
        buf.reset();
        let t = Instant::now();
        (&app).render(area, &mut buf);
        samples.push(t.elapsed());
    }
    samples.sort();
    let pct = |p: f64| samples[((samples.len() - 1) as f64 * p) as usize];
    println!(
        "render {n} robots @ {w}x{h}: p50 {:?} p99 {:?}",
        pct(0.5),
        pct(0.99)
    );
}

fn render(c: &mut Criterion) {
    percentiles(1000, 200, 50);
    percentiles(4, 80, 24);
    let (w, h) = (200, 50);
    let app = app_with_paths(200, w, h);
    let area = Rect::new(0, 0, w, h);
    let mut buf = Buffer::empty(area);
    // A plain percentile summary alongside criterion's estimate.
    let mut samples = Vec::with_capacity(500);
    for _ in 0..500 {
        buf.reset();
        let t = Instant::now();
        (&app).render(area, &mut buf);
        samples.push(t.elapsed());
    }
    samples.sort();
    let pct = |p: f64| samples[((samples.len() - 1) as f64 * p) as usize];
    println!(
        "render 200 robots @ {w}x{h}: p50 {:?} p99 {:?} max {:?}",
        pct(0.5),
        pct(0.99),
        pct(1.0)
    );
    c.bench_function("render_200_robots_200x50", |b| {
        b.iter(|| {
            buf.reset();
            (&app).render(area, &mut buf);
        })
    });
}

criterion_group!(benches, render);
criterion_main!(benches);
