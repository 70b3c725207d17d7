//! The arena map: a braille canvas in metres with grid, scale and metre
//! ticks on the axes, the arena (the station's: its boundary, keep-outs,
//! slow zones dotted and obstacle discs; or the bounds the TUI was given),
//! robots with heading lines and recent
//! paths, selection rings, clusters joined to their centre, and numbered
//! waypoint flags; every robot marked and labelled where a label fits
//! (see [`super::labels`]), with a count of the labels left out.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::style::{Color, Style, Stylize};
use ratatui::symbols::Marker;
use ratatui::text::Line as TextLine;
use ratatui::widgets::canvas::{Canvas, Context, Painter, Shape};
use ratatui::widgets::{Block, Widget};

use super::app::{App, Focus};
use super::labels::{self, Kind, MapText};
use super::theme::Theme;
use super::view::{ArenaBounds, ArenaShape, ClusterControlView, ClusterOnScreen};
use super::viewport::Projection;

/// The map panel.
#[derive(Debug)]
pub struct MapPanel<'a> {
    pub app: &'a App,
    pub theme: Theme,
}

/// A grid spacing of 1, 2 or 5 x 10^k metres, at least `min` metres.
pub fn grid_step(min: f64) -> f64 {
    if !(min.is_finite() && min > 0.0) {
        return 1.0;
    }
    let mag = 10f64.powf(min.log10().floor());
    for k in [1.0, 2.0, 5.0, 10.0] {
        if k * mag >= min {
            return k * mag;
        }
    }
    10.0 * mag
}

/// Human-readable length.
pub fn format_length(m: f64) -> String {
    if m >= 1000.0 {
        format!("{} km", m / 1000.0)
    } else if m >= 1.0 {
        format!("{m} m")
    } else if m >= 0.01 {
        format!("{} cm", (m * 100.0).round())
    } else {
        format!("{} mm", (m * 1000.0).round())
    }
}

/// The text of `app`'s map as its panel draws it now (its inner area,
/// projection and grid step): see [`labels`].
pub fn map_text(app: &App) -> MapText {
    let inner = app.areas().map_inner();
    let proj = app.map.viewport.project(inner.width, inner.height);
    labels::layout(app, &proj, grid_step(proj.metres_per_dot * 16.0))
}

/// Dots painted straight from world coordinates through the projection, so
/// the map and click handling share one mapping.
struct Dots<'a> {
    proj: &'a Projection,
    points: &'a [(f64, f64)],
    color: Color,
}

impl Shape for Dots<'_> {
    fn draw(&self, painter: &mut Painter) {
        for &(x, y) in self.points {
            if let Some((i, j)) = self.proj.world_to_dot(x, y) {
                painter.paint(i, j, self.color);
            }
        }
    }
}

/// A robot's recent path: its points as dots, each painted once for a run
/// of points on the same dot. Painting a dot again in the same colour
/// leaves it as it was, so the picture is exactly the one every point
/// painted gives, while a path sampled finer than the map's dots (a fleet
/// seen whole) costs a paint per dot it crosses, not per point.
struct Path<'a> {
    proj: &'a Projection,
    points: &'a [(f64, f64)],
    color: Color,
}

impl Shape for Path<'_> {
    fn draw(&self, painter: &mut Painter) {
        let mut last = None;
        for &(x, y) in self.points {
            let dot = self.proj.world_to_dot(x, y);
            if let Some((i, j)) = dot.filter(|_| dot != last) {
                painter.paint(i, j, self.color);
                last = dot;
            }
        }
    }
}

/// A straight segment rasterised on the dot grid (clipped to the view).
struct Segment<'a> {
    proj: &'a Projection,
    from: (f64, f64),
    to: (f64, f64),
    color: Color,
    /// Paint every n-th dot (1 = solid).
    every: usize,
}

impl<'a> Segment<'a> {
    /// A heading line `len` metres long from pose `(x, y, heading)`.
    fn heading(
        proj: &'a Projection,
        (x, y, h): (f64, f64, f64),
        len: f64,
        color: Color,
        every: usize,
    ) -> Segment<'a> {
        Segment {
            proj,
            from: (x, y),
            to: (x + len * h.cos(), y + len * h.sin()),
            color,
            every,
        }
    }
}

impl Shape for Segment<'_> {
    /// `n + 1` points evenly spaced from end to end, `n` the length in
    /// dots rounded up, stepped in dot units (projecting the two ends
    /// only).
    fn draw(&self, painter: &mut Painter) {
        let (i0, j0) = self.proj.world_to_dots(self.from.0, self.from.1);
        let (i1, j1) = self.proj.world_to_dots(self.to.0, self.to.1);
        let (di, dj) = (i1 - i0, j1 - j0);
        let len_dots = (di * di + dj * dj).sqrt().ceil();
        if !len_dots.is_finite() {
            return;
        }
        let n = (len_dots as usize).clamp(1, 4096);
        let (si, sj) = (di / n as f64, dj / n as f64);
        for k in (0..=n).step_by(self.every.max(1)) {
            let k = k as f64;
            if let Some((i, j)) = self.proj.dot_at(i0 + si * k, j0 + sj * k) {
                painter.paint(i, j, self.color);
            }
        }
    }
}

impl Widget for MapPanel<'_> {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let app = self.app;
        let t = self.theme;
        let inner = super::layout::inner(area);
        let proj = app.map.viewport.project(inner.width, inner.height);
        let m = proj.metres_per_dot;
        let step = grid_step(m * 16.0);
        let text = labels::layout(app, &proj, step);
        let mut title = format!(" Map  grid {} ", format_length(step));
        if text.hidden > 0 {
            title.push_str(&format!("│ {} labels hidden ", text.hidden));
        }
        if app.waypoints.placing {
            title.push_str("│ WAYPOINT MODE: click to place, Esc leaves ");
        }
        let border = if app.screen.focus == Focus::Map {
            t.focused_border()
        } else {
            Style::new()
        };
        let block = Block::bordered().title(title).border_style(border);
        let canvas = Canvas::default()
            .block(block)
            .marker(Marker::Braille)
            .x_bounds(proj.x_bounds())
            .y_bounds(proj.y_bounds())
            .paint(|ctx| paint(ctx, app, &proj, step, &text, &t));
        canvas.render(area, buf);
    }
}

/// The map's content, bottom to top: grid, then arena, paths, waypoint
/// legs, clusters and robots, then the text laid out in `text`.
fn paint(ctx: &mut Context, app: &App, proj: &Projection, step: f64, text: &MapText, t: &Theme) {
    paint_grid(ctx, proj, step, t);
    ctx.layer();
    match (&app.fleet.arena, app.map.arena) {
        (Some(shape), _) => paint_shape(ctx, proj, shape, t),
        (None, Some(a)) => paint_arena(ctx, proj, a, t),
        (None, None) => {}
    }
    // Paths of the last seconds.
    for (i, r) in app.fleet.robots.iter().enumerate() {
        ctx.draw(&Path {
            proj,
            points: &r.trail,
            color: t.robot(i),
        });
    }
    // Waypoint legs, in mission order.
    for w in app.waypoints.list.windows(2) {
        ctx.draw(&Segment {
            proj,
            from: (w[0].x, w[0].y),
            to: (w[1].x, w[1].y),
            color: t.waypoint(),
            every: 3,
        });
    }
    paint_clusters(ctx, app, proj, t);
    paint_robots(ctx, app, proj, t);
    // Text last, so it sits on top; the marks over everything.
    print_text(ctx, app, proj, text, t);
}

/// A small cross at every grid intersection, the axes through the origin
/// dotted, so the robots stay the brightest thing on the map.
fn paint_grid(ctx: &mut Context, proj: &Projection, step: f64, t: &Theme) {
    let m = proj.metres_per_dot;
    let (xmin, ymin, xmax, ymax) = proj.world_rect();
    let mut crosses = Vec::new();
    let mut gx = (xmin / step).ceil() * step;
    while gx <= xmax {
        let mut gy = (ymin / step).ceil() * step;
        while gy <= ymax {
            crosses.extend([
                (gx, gy),
                (gx - m, gy),
                (gx + m, gy),
                (gx, gy - m),
                (gx, gy + m),
            ]);
            gy += step;
        }
        gx += step;
    }
    ctx.draw(&Dots {
        proj,
        points: &crosses,
        color: t.grid(),
    });
    if xmin <= 0.0 && xmax >= 0.0 {
        ctx.draw(&Segment {
            proj,
            from: (0.0, ymin),
            to: (0.0, ymax),
            color: t.grid(),
            every: 3,
        });
    }
    if ymin <= 0.0 && ymax >= 0.0 {
        ctx.draw(&Segment {
            proj,
            from: (xmin, 0.0),
            to: (xmax, 0.0),
            color: t.grid(),
            every: 3,
        });
    }
}

fn paint_arena(ctx: &mut Context, proj: &Projection, a: ArenaBounds, t: &Theme) {
    let corners = [
        (a.min_x, a.min_y),
        (a.max_x, a.min_y),
        (a.max_x, a.max_y),
        (a.min_x, a.max_y),
    ];
    for k in 0..4 {
        ctx.draw(&Segment {
            proj,
            from: corners[k],
            to: corners[(k + 1) % 4],
            color: t.arena(),
            every: 1,
        });
    }
}

/// The closed polygon through `points`, every `every`-th dot.
fn paint_polygon(
    ctx: &mut Context,
    proj: &Projection,
    points: &[mech_proto::Point],
    color: Color,
    every: usize,
) {
    for (k, a) in points.iter().enumerate() {
        let b = points[(k + 1) % points.len()];
        ctx.draw(&Segment {
            proj,
            from: (a.x, a.y),
            to: (b.x, b.y),
            color,
            every,
        });
    }
}

/// The station's arena: the boundary solid, keep-outs solid in their
/// colour and crossed corner to corner (the inside is out of bounds),
/// slow zones dotted, obstacle discs as circles.
fn paint_shape(ctx: &mut Context, proj: &Projection, a: &ArenaShape, t: &Theme) {
    paint_polygon(ctx, proj, &a.boundary, t.arena(), 1);
    for k in &a.keep_out {
        paint_polygon(ctx, proj, k, t.keep_out(), 1);
        if k.len() >= 4 {
            for (i, j) in [(0, 2), (1, 3)] {
                ctx.draw(&Segment {
                    proj,
                    from: (k[i].x, k[i].y),
                    to: (k[j].x, k[j].y),
                    color: t.keep_out(),
                    every: 3,
                });
            }
        }
    }
    for z in &a.slow_zones {
        paint_polygon(ctx, proj, &z.polygon, t.slow_zone(), 3);
    }
    for d in &a.obstacles {
        let ring: Vec<mech_proto::Point> = (0..24)
            .map(|k| {
                let angle = f64::from(k) * std::f64::consts::TAU / 24.0;
                mech_proto::Point {
                    x: d.x + d.radius * angle.cos(),
                    y: d.y + d.radius * angle.sin(),
                }
            })
            .collect();
        paint_polygon(ctx, proj, &ring, t.keep_out(), 1);
    }
}

/// Clusters: members joined to the centre, and what the controller
/// reports when it runs the cluster.
fn paint_clusters(ctx: &mut Context, app: &App, proj: &Projection, t: &Theme) {
    for c in &app.fleet.clusters {
        paint_cluster(ctx, app, c, proj, t);
    }
}

/// A cluster's members joined to its centre (the controller's measured
/// pose, or the members' centroid: [`labels::cluster_centre`]), and what
/// its controller reports.
fn paint_cluster(ctx: &mut Context, app: &App, c: &ClusterOnScreen, proj: &Projection, t: &Theme) {
    let pos = labels::member_positions(app, c);
    let Some((cx, cy)) = labels::centre_of(c, &pos) else {
        return;
    };
    if let Some(k) = c.control.as_ref() {
        paint_cluster_control(ctx, app, k, proj, t);
    }
    for p in &pos {
        ctx.draw(&Segment {
            proj,
            from: *p,
            to: (cx, cy),
            color: t.cluster(),
            every: 2,
        });
    }
}

/// Slot targets, each joined to its member by a sparse line, and the
/// desired and measured cluster poses with their headings.
fn paint_cluster_control(
    ctx: &mut Context,
    app: &App,
    k: &ClusterControlView,
    proj: &Projection,
    t: &Theme,
) {
    for s in &k.slots {
        if let Some(r) = app.robot(&s.robot) {
            ctx.draw(&Segment {
                proj,
                from: (r.telemetry.pose.x, r.telemetry.pose.y),
                to: (s.x, s.y),
                color: t.cluster(),
                every: 3,
            });
        }
    }
    let m = proj.metres_per_dot;
    if let Some(desired) = k.desired {
        ctx.draw(&Segment::heading(proj, desired, 8.0 * m, t.cluster(), 1));
    }
    if let Some(measured) = k.measured {
        ctx.draw(&Segment::heading(proj, measured, 6.0 * m, t.cluster(), 2));
    }
}

/// Robots: heading line, the disc its safety layer keeps (its radius
/// grown by its position error) when that is wider than the mark, and a
/// ring round the selected ones.
fn paint_robots(ctx: &mut Context, app: &App, proj: &Projection, t: &Theme) {
    let m = proj.metres_per_dot;
    for (i, r) in app.fleet.robots.iter().enumerate() {
        let (x, y, h) = (
            r.telemetry.pose.x,
            r.telemetry.pose.y,
            r.telemetry.pose.heading,
        );
        let colour = t.robot(i);
        ctx.draw(&Segment::heading(proj, (x, y, h), 6.0 * m, colour, 1));
        let footprint = r.safety.map_or(0.0, |s| s.footprint);
        if footprint > 4.0 * m && footprint.is_finite() {
            let dots = (footprint / m * 1.5).clamp(12.0, 64.0) as u32;
            let disc: Vec<(f64, f64)> = (0..dots)
                .map(|k| {
                    let a = f64::from(k) * std::f64::consts::TAU / f64::from(dots);
                    (x + footprint * a.cos(), y + footprint * a.sin())
                })
                .collect();
            ctx.draw(&Dots {
                proj,
                points: &disc,
                color: colour,
            });
        }
        if app.cards.selection.contains(&r.name) {
            let ring: Vec<(f64, f64)> = (0..16)
                .map(|k| {
                    let a = f64::from(k) * std::f64::consts::TAU / 16.0;
                    (x + 3.0 * m * a.cos(), y + 3.0 * m * a.sin())
                })
                .collect();
            ctx.draw(&Dots {
                proj,
                points: &ring,
                color: colour,
            });
        }
    }
}

/// The laid-out text: flags, cluster glyphs, ticks and labels, then every
/// robot's mark on top (ringed and reversed when selected).
fn print_text(ctx: &mut Context, app: &App, proj: &Projection, text: &MapText, t: &Theme) {
    for p in &text.texts {
        let style = match p.kind {
            Kind::Robot(i) if app.cards.selection.contains(&app.fleet.robots[i].name) => {
                Style::new().fg(t.robot(i)).patch(t.title())
            }
            Kind::Robot(i) => Style::new().fg(t.robot(i)),
            Kind::Waypoint(_) => Style::new().fg(t.waypoint()).bold(),
            Kind::Cluster => Style::new().bold(),
            Kind::Slot => Style::new(),
            Kind::Tick => Style::new().fg(t.grid()),
        };
        print_at(
            ctx,
            proj,
            p.col,
            p.row,
            TextLine::styled(p.text.clone(), style),
        );
    }
    for &(col, row, i) in &text.marks {
        let selected = app.cards.selection.contains(&app.fleet.robots[i].name);
        let mut style = Style::new().fg(t.robot(i));
        if selected {
            style = style.patch(t.selected());
        }
        // Another station's robot (read-only) is a hollow mark.
        let glyph = match (selected, app.fleet.robots[i].remote.is_some()) {
            (true, _) => "◉",
            (false, true) => "○",
            (false, false) => "●",
        };
        print_at(ctx, proj, col, row, TextLine::styled(glyph, style));
    }
}

/// Prints a line of text starting in cell (`col`, `row`) of the map.
fn print_at(ctx: &mut Context, proj: &Projection, col: u16, row: u16, line: TextLine<'static>) {
    if col < proj.width && row < proj.height {
        let (x, y) = proj.label_anchor(col, row);
        ctx.print(x, y, line);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grid_steps_are_round() {
        assert_eq!(grid_step(0.7), 1.0);
        assert_eq!(grid_step(1.2), 2.0);
        assert_eq!(grid_step(3.0), 5.0);
        assert!((grid_step(0.031) - 0.05).abs() < 1e-12);
    }

    #[test]
    fn lengths_read_naturally() {
        assert_eq!(format_length(2.0), "2 m");
        assert_eq!(format_length(0.5), "50 cm");
    }

    /// `shape` drawn alone on a braille canvas over `proj`.
    fn canvas(proj: &Projection, shape: &dyn Fn(&mut Context)) -> Buffer {
        let area = Rect::new(0, 0, proj.width, proj.height);
        let mut buf = Buffer::empty(area);
        Canvas::default()
            .marker(Marker::Braille)
            .x_bounds(proj.x_bounds())
            .y_bounds(proj.y_bounds())
            .paint(|ctx| shape(ctx))
            .render(area, &mut buf);
        buf
    }

    proptest::proptest! {
        /// A segment stepped in dot units paints the dots of its evenly
        /// spaced world points, every `every`-th, on the map or partly
        /// off it. (A point exactly on a dot's edge, as on an axis at round
        /// coordinates, may fall on either side: the two ways round
        /// differently. Random ends never put one there.)
        #[test]
        fn a_segment_paints_the_dots_of_its_points(
            scale in 0.005f64..0.5, w in 4u16..120, h in 2u16..40,
            x0 in -30.0f64..30.0, y0 in -30.0f64..30.0,
            x1 in -30.0f64..30.0, y1 in -30.0f64..30.0, every in 1usize..4,
        ) {
            let proj = super::super::viewport::Viewport::new(0.3, -0.1, scale).project(w, h);
            let len = ((x1 - x0).hypot(y1 - y0) / scale).ceil() as usize;
            let n = len.clamp(1, 4096);
            let points: Vec<(f64, f64)> = (0..=n)
                .step_by(every)
                .map(|k| {
                    let f = k as f64 / n as f64;
                    (x0 + (x1 - x0) * f, y0 + (y1 - y0) * f)
                })
                .collect();
            let color = Color::Cyan;
            let stepped = canvas(&proj, &|ctx| {
                ctx.draw(&Segment { proj: &proj, from: (x0, y0), to: (x1, y1), color, every })
            });
            let projected = canvas(&proj, &|ctx| {
                ctx.draw(&Dots { proj: &proj, points: &points, color })
            });
            proptest::prop_assert_eq!(stepped, projected);
        }
    }
}
