//! Where the map's text goes, so that nothing overlaps at any density: a
//! mark (`●`, `◉` selected) in every robot's cell; waypoint flags and
//! cluster glyphs where they are (moved a few cells along their row when
//! two fall together); then the labels of the robot under the mouse pointer
//! and the selected robots, the metre ticks on the axes, and the other
//! robots' labels while there is room. A label is the name, or when that
//! does not fit its short form (`r12` for `robot_12`), right, left, above
//! or below its mark; it never covers a mark or another text and keeps a
//! blank cell between itself and the next text or mark on its row, or it
//! is left out and counted. The hovered robot and the first
//! `FAR_SEARCHES` selected ones, when a crowd leaves no room near their
//! mark, take the nearest room anywhere on the map, so they are labelled
//! while the map has room for a short name at all. A pure function of the
//! App and the projection, so tests read exactly what is drawn.

use super::app::App;
use super::viewport::Projection;

/// What a piece of map text is, for its style.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Kind {
    /// Robot `i`'s name (or its short form).
    Robot(usize),
    /// Waypoint `k` (0-based) of the list being edited.
    Waypoint(usize),
    /// A cluster's name at its centre.
    Cluster,
    /// A slot target or a desired cluster pose.
    Slot,
    /// A metre value along an axis.
    Tick,
}

/// A piece of text at a cell of the map (relative to its inner area).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Placed {
    pub col: u16,
    pub row: u16,
    pub text: String,
    pub kind: Kind,
}

impl Placed {
    /// Cells it covers.
    pub fn width(&self) -> u16 {
        self.text.chars().count() as u16
    }
}

/// Everything written on the map, in drawing order: `texts`, then the
/// `marks` on top.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct MapText {
    /// Robot marks: cell and robot index, the selected ones last.
    pub marks: Vec<(u16, u16, usize)>,
    pub texts: Vec<Placed>,
    /// Robots on the map whose label did not fit.
    pub hidden: usize,
}

const FREE: u8 = 0;
const MARK: u8 = 1;
const TEXT: u8 = 2;

/// Which cells hold a mark or text.
struct Grid {
    w: u16,
    h: u16,
    cells: Vec<u8>,
}

impl Grid {
    fn new(w: u16, h: u16) -> Grid {
        Grid {
            w,
            h,
            cells: vec![FREE; usize::from(w) * usize::from(h)],
        }
    }

    fn at(&self, col: i32, row: i32) -> u8 {
        if col < 0 || row < 0 || col >= i32::from(self.w) || row >= i32::from(self.h) {
            return FREE;
        }
        self.cells[row as usize * usize::from(self.w) + col as usize]
    }

    fn set(&mut self, col: u16, row: u16, v: u8) {
        if col < self.w && row < self.h {
            let i = usize::from(row) * usize::from(self.w) + usize::from(col);
            self.cells[i] = self.cells[i].max(v);
        }
    }

    /// Whether `len` cells from (`col`, `row`) are on the map and free,
    /// and so is the cell either side (a label never runs into another
    /// text or a mark, which would read as its own).
    fn fits(&self, col: i32, row: i32, len: i32) -> bool {
        if col < 0 || row < 0 || row >= i32::from(self.h) || col + len > i32::from(self.w) {
            return false;
        }
        (col - 1..=col + len).all(|c| self.at(c, row) == FREE)
    }

    fn take(&mut self, col: u16, row: u16, len: u16) {
        for c in col..col.saturating_add(len) {
            self.set(c, row, TEXT);
        }
    }

    /// Places text that belongs at (`col`, `row`) (a flag, a cluster's
    /// name): there when no other text is, else at the nearest place on its
    /// row free of text, a few cells either way; it may cover a mark (drawn
    /// over it). None when the row has no room there.
    fn place_fixed(&mut self, text: &str, col: u16, row: u16, kind: Kind) -> Option<Placed> {
        let len = text.chars().count() as i32;
        let (c, r) = (i32::from(col), i32::from(row));
        let free = |g: &Grid, s: i32| {
            s >= 0 && s + len <= i32::from(g.w) && (s..s + len).all(|k| g.at(k, r) != TEXT)
        };
        let start = (0..=len + 2)
            .flat_map(|d| [c - d, c + d])
            .find(|&s| free(self, s))?;
        self.take(start as u16, row, len as u16);
        Some(Placed {
            col: start as u16,
            row,
            text: text.to_string(),
            kind,
        })
    }

    /// Places `text` at the first of `at` where it fits.
    fn place(
        &mut self,
        text: &str,
        at: impl IntoIterator<Item = (i32, i32)>,
        kind: Kind,
    ) -> Option<Placed> {
        let len = text.chars().count() as i32;
        let (col, row) = at.into_iter().find(|&(c, r)| self.fits(c, r, len))?;
        let (col, row) = (col as u16, row as u16);
        self.take(col, row, len as u16);
        Some(Placed {
            col,
            row,
            text: text.to_string(),
            kind,
        })
    }
}

/// The short form of a robot name: its first letter and the number it ends
/// with (`robot_12` -> `r12`), or its first three characters.
pub fn short_name(name: &str) -> String {
    let digits = name.len() - name.trim_end_matches(|c: char| c.is_ascii_digit()).len();
    if digits > 0 && digits < name.len() {
        let first = name.chars().next().unwrap_or('r');
        format!("{first}{}", &name[name.len() - digits..])
    } else {
        name.chars().take(3).collect()
    }
}

/// Where a robot's label may go, best first: right of its mark (a blank
/// cell between), left of it, then above and below.
fn spots(col: u16, row: u16, len: usize) -> [(i32, i32); 6] {
    let (c, r, l) = (i32::from(col), i32::from(row), len as i32);
    [
        (c + 2, r),
        (c - 1 - l, r),
        (c, r - 1),
        (c + 1 - l, r - 1),
        (c, r + 1),
        (c + 1 - l, r + 1),
    ]
}

/// Further places for the label of a robot that must be labelled
/// (selected or under the pointer) when a crowd fills the near ones:
/// anywhere on the `w` x `h` map, nearest rows first and, in a row, the
/// places nearest its column first.
fn far_spots(col: u16, row: u16, len: usize, w: u16, h: u16) -> impl Iterator<Item = (i32, i32)> {
    let (c, r, l) = (i32::from(col), i32::from(row), len as i32);
    let (w, h) = (i32::from(w), i32::from(h));
    let base = c - l / 2;
    let rows =
        (0..h).flat_map(move |d| [r - d, r + d].into_iter().take(if d == 0 { 1 } else { 2 }));
    rows.filter(move |&row| (0..h).contains(&row))
        .flat_map(move |row| {
            (0..w).flat_map(move |d| {
                [(base - d, row), (base + d, row)]
                    .into_iter()
                    .take(if d == 0 { 1 } else { 2 })
            })
        })
}

/// Robots a frame searches the whole map for (the hovered one, then the
/// selected ones in name order); beyond them a selected robot is labelled
/// near its mark or counted hidden, so a selection of the whole fleet
/// costs no more than a few searches.
const FAR_SEARCHES: usize = 8;

/// A metre value as a tick label, with as many decimals as the grid step
/// needs.
pub fn tick_text(v: f64, step: f64) -> String {
    let decimals = (-step.log10().floor()).max(0.0) as usize;
    let v = if v.abs() < step * 1e-6 { 0.0 } else { v };
    format!("{v:.decimals$}")
}

/// The map's text for `app` drawn through `proj` with grid spacing `step`.
pub fn layout(app: &App, proj: &Projection, step: f64) -> MapText {
    let mut grid = Grid::new(proj.width, proj.height);
    let mut out = MapText::default();
    let cell = |x: f64, y: f64| proj.world_to_cell(x, y);

    // Every robot's mark, the selected ones drawn last (on top).
    let mut on_map = Vec::new();
    for (i, r) in app.fleet.robots.iter().enumerate() {
        if let Some((c, row)) = cell(r.telemetry.pose.x, r.telemetry.pose.y) {
            grid.set(c, row, MARK);
            on_map.push((i, c, row));
        }
    }
    let selected = |i: usize| app.cards.selection.contains(&app.fleet.robots[i].name);
    out.marks = on_map.iter().map(|&(i, c, r)| (c, r, i)).collect();
    out.marks.sort_by_key(|&(_, _, i)| selected(i));

    fixed_texts(app, proj, &mut grid, &mut out);

    // Labels: the hovered and selected robots first, then the ticks, then
    // the rest in name order.
    let hovered = |i: usize| app.map.hover.as_deref() == Some(app.fleet.robots[i].name.as_str());
    let first = |i: usize| selected(i) || hovered(i);
    let mut must: Vec<_> = on_map
        .iter()
        .copied()
        .filter(|&(i, _, _)| first(i))
        .collect();
    must.sort_by_key(|&(i, _, _)| !hovered(i));
    for (k, robot) in must.into_iter().enumerate() {
        let far = k < FAR_SEARCHES;
        label_robot(app, robot, far, &mut grid, &mut out);
    }
    ticks(proj, step, &mut grid, &mut out);
    for &robot in on_map.iter().filter(|(i, _, _)| !first(*i)) {
        label_robot(app, robot, false, &mut grid, &mut out);
    }
    out
}

/// Robot `i`'s label at its mark in cell (`c`, `row`): its name or short
/// form at one of the near [`spots`], else, when `far`, its short form
/// wherever on the map is nearest; or counted hidden.
fn label_robot(
    app: &App,
    (i, c, row): (usize, u16, u16),
    far: bool,
    grid: &mut Grid,
    out: &mut MapText,
) {
    let name = &app.fleet.robots[i].name;
    let short = short_name(name);
    let near = [name.as_str(), short.as_str()]
        .into_iter()
        .find_map(|text| grid.place(text, spots(c, row, text.chars().count()), Kind::Robot(i)));
    let placed = near.or_else(|| {
        let (w, h) = (grid.w, grid.h);
        let at = far_spots(c, row, short.chars().count(), w, h);
        far.then(|| grid.place(&short, at, Kind::Robot(i)))
            .flatten()
    });
    match placed {
        Some(p) => out.texts.push(p),
        None => out.hidden += 1,
    }
}

/// Waypoint flags, cluster names and controller glyphs, where they are
/// (they may not move): reserved before any label.
fn fixed_texts(app: &App, proj: &Projection, grid: &mut Grid, out: &mut MapText) {
    let mut fixed = |x: f64, y: f64, text: String, kind: Kind| {
        let at = proj.world_to_cell(x, y);
        if let Some(p) = at.and_then(|(c, r)| grid.place_fixed(&text, c, r, kind)) {
            out.texts.push(p);
        }
    };
    for c in &app.fleet.clusters {
        if let Some(k) = &c.control {
            for s in &k.slots {
                fixed(s.x, s.y, "◇".into(), Kind::Slot);
            }
            if let Some((x, y, _)) = k.desired {
                fixed(x, y, "⊕".into(), Kind::Slot);
            }
        }
        if let Some((x, y)) = cluster_centre(app, c) {
            fixed(x, y, format!("✚{}", c.name), Kind::Cluster);
        }
    }
    for (k, w) in app.waypoints.list.iter().enumerate() {
        fixed(w.x, w.y, format!("⚑{}", k + 1), Kind::Waypoint(k));
    }
}

/// The controller's measured cluster pose when it runs the cluster, else
/// the members' centroid.
pub fn cluster_centre(app: &App, c: &super::view::ClusterOnScreen) -> Option<(f64, f64)> {
    if let Some((x, y, _)) = c.control.as_ref().and_then(|k| k.measured) {
        return Some((x, y));
    }
    centre_of(c, &member_positions(app, c))
}

/// Where the members of cluster `c` that are in the fleet are, in member
/// order.
pub fn member_positions(app: &App, c: &super::view::ClusterOnScreen) -> Vec<(f64, f64)> {
    app.fleet
        .robots_named(&c.members)
        .map(|r| (r.telemetry.pose.x, r.telemetry.pose.y))
        .collect()
}

/// [`cluster_centre`] of a cluster whose members on the map are at `pos`
/// (in member order).
pub fn centre_of(c: &super::view::ClusterOnScreen, pos: &[(f64, f64)]) -> Option<(f64, f64)> {
    if let Some((x, y, _)) = c.control.as_ref().and_then(|k| k.measured) {
        return Some((x, y));
    }
    if pos.is_empty() {
        return None;
    }
    let n = pos.len() as f64;
    Some((
        pos.iter().map(|p| p.0).sum::<f64>() / n,
        pos.iter().map(|p| p.1).sum::<f64>() / n,
    ))
}

/// Metre values at the grid lines, along the axes: x values under the
/// x axis (y = 0), y values left of the y axis (x = 0); an axis out of
/// view puts its values along that edge of the map.
fn ticks(proj: &Projection, step: f64, grid: &mut Grid, out: &mut MapText) {
    let (xmin, ymin, xmax, ymax) = proj.world_rect();
    let (w, h) = (i32::from(proj.width), i32::from(proj.height));
    if w < 4 || h < 2 {
        return;
    }
    let col_of = |x: f64| ((x - proj.left) / (2.0 * proj.metres_per_dot)).floor() as i32;
    let row_of = |y: f64| ((proj.top - y) / (4.0 * proj.metres_per_dot)).floor() as i32;
    // The x values' row: under the x axis, or the edge it is beyond.
    let axis_row = row_of(0.0);
    let x_row = if axis_row < 0 {
        0
    } else if axis_row >= h - 1 {
        h - 1
    } else {
        axis_row + 1
    };
    let mut gx = (xmin / step).ceil() * step;
    while gx <= xmax {
        let text = tick_text(gx, step);
        if let Some(p) = grid.place(&text, [(col_of(gx), x_row)], Kind::Tick) {
            out.texts.push(p);
        }
        gx += step;
    }
    // The y values end left of the y axis (or start right of it when
    // there is no room), or sit along the edge it is beyond.
    let axis_col = col_of(0.0);
    let mut gy = (ymin / step).ceil() * step;
    while gy <= ymax {
        let text = tick_text(gy, step);
        let len = text.chars().count() as i32;
        let row = row_of(gy);
        let at = if axis_col < 0 {
            (0, row)
        } else if axis_col >= w {
            (w - len, row)
        } else if axis_col - 1 - len >= 0 {
            (axis_col - 1 - len, row)
        } else {
            (axis_col + 2, row)
        };
        if gy.abs() > step * 1e-6 {
            if let Some(p) = grid.place(&text, [at], Kind::Tick) {
                out.texts.push(p);
            }
        }
        gy += step;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ui::Action;
    use crate::ui::fixture;

    /// Every text on its own cells, a blank cell between a label and the
    /// next text or mark on its row, no text on a mark.
    fn assert_apart(t: &MapText) {
        let mut cells = std::collections::HashMap::new();
        for (k, p) in t.texts.iter().enumerate() {
            for c in p.col..p.col + p.width() {
                if let Some(other) = cells.insert((c, p.row), k) {
                    panic!("{:?} overlaps {:?}", p, t.texts[other]);
                }
            }
        }
        for p in t
            .texts
            .iter()
            .filter(|p| matches!(p.kind, Kind::Robot(_) | Kind::Tick))
        {
            let before = p.col.checked_sub(1).and_then(|c| cells.get(&(c, p.row)));
            let after = cells.get(&(p.col + p.width(), p.row));
            assert!(before.is_none() && after.is_none(), "{p:?} touches a text");
            let gap = [p.col.wrapping_sub(1), p.col + p.width()];
            assert!(
                !t.marks
                    .iter()
                    .any(|&(mc, mr, _)| mr == p.row && gap.contains(&mc)),
                "{p:?} touches a mark"
            );
            for c in p.col..p.col + p.width() {
                assert!(
                    !t.marks.iter().any(|&(mc, mr, _)| (mc, mr) == (c, p.row)),
                    "{p:?} covers a mark"
                );
            }
        }
    }

    fn map_text(app: &App) -> MapText {
        let inner = app.areas().map_inner();
        let proj = app.map.viewport.project(inner.width, inner.height);
        let step = crate::ui::map::grid_step(proj.metres_per_dot * 16.0);
        layout(app, &proj, step)
    }

    #[test]
    fn labels_never_overlap_at_any_density() {
        for (n, w, h) in [(4, 80, 24), (30, 120, 36), (100, 120, 36), (1000, 200, 50)] {
            let app = fixture::app(n, w, h);
            let t = map_text(&app);
            assert_apart(&t);
            let labelled = t
                .texts
                .iter()
                .filter(|p| matches!(p.kind, Kind::Robot(_)))
                .count();
            assert_eq!(
                labelled + t.hidden,
                n,
                "{n} robots: each labelled or counted"
            );
            assert_eq!(t.marks.len(), n, "every robot marked");
        }
    }

    #[test]
    fn selected_and_hovered_robots_are_labelled_first() {
        let mut app = fixture::app(1000, 120, 36);
        app.update(Action::Select(crate::ui::Select::Only("robot_777".into())));
        app.update(Action::Select(crate::ui::Select::Toggle(
            "robot_500".into(),
        )));
        app.map.hover = Some("robot_123".into());
        let t = map_text(&app);
        assert_apart(&t);
        for i in [776, 499, 122] {
            assert!(
                t.texts.iter().any(|p| p.kind == Kind::Robot(i)),
                "{} labelled",
                app.fleet.robots[i].name
            );
        }
        assert!(t.hidden > 500, "a crowd: most labels left out");
        let (_, _, last) = t.marks.last().copied().unwrap();
        assert!(
            app.cards.selection.contains(&app.fleet.robots[last].name),
            "selected on top"
        );
    }

    #[test]
    fn a_name_that_does_not_fit_is_shortened() {
        assert_eq!(short_name("robot_12"), "r12");
        assert_eq!(short_name("rover"), "rov");
        assert_eq!(short_name("42"), "42");
        let app = fixture::app(30, 120, 36);
        let t = map_text(&app);
        assert!(t.texts.iter().any(|p| p.text.starts_with("robot_")));
        let shortened = t.texts.iter().any(|p| {
            matches!(p.kind, Kind::Robot(_)) && p.text.starts_with('r') && !p.text.contains('_')
        });
        assert!(shortened || t.hidden == 0, "{t:?}");
    }

    /// A fleet of `pos.len()` robots at `pos` (m) on a `w` x `h` terminal,
    /// the map fitted to them, with `wps` waypoints among them.
    fn random_app(pos: &[(f64, f64)], w: u16, h: u16, wps: usize) -> App {
        let robots = pos
            .iter()
            .enumerate()
            .map(|(i, &(x, y))| {
                let name = format!("robot_{}", i + 1);
                crate::ui::RobotView::at(&name, (i + 1) as u16, "kiwi", x, y, 0.0)
            })
            .collect();
        let mut app = App::new("127.0.0.1:7700", std::time::Instant::now());
        app.update(Action::Resize(w, h));
        app.update(Action::Fleet(crate::ui::FleetSnapshot {
            robots,
            ..Default::default()
        }));
        app.update(Action::FitFleet);
        app.waypoints.list = pos
            .iter()
            .take(wps)
            .map(|&(x, y)| mech_proto::Waypoint {
                x: x + 0.1,
                y,
                z: 0.0,
                time: None,
            })
            .collect();
        app
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(96))]

        /// Random dense fleets on random terminals: every robot marked, no
        /// two texts overlap or touch, each label either drawn or counted,
        /// and the selected and hovered robots always labelled.
        #[test]
        fn random_dense_fleets_never_overlap(
            pos in proptest::collection::vec((0.0f64..3.0, 0.0f64..3.0), 1..400),
            w in 80u16..220,
            h in 24u16..60,
            picks in proptest::collection::vec(proptest::prelude::any::<proptest::sample::Index>(), 0..4),
            hover in proptest::prelude::any::<Option<proptest::sample::Index>>(),
            wps in 0usize..3,
        ) {
            let mut app = random_app(&pos, w, h, wps);
            let chosen: Vec<usize> = picks.iter().map(|k| k.index(pos.len())).collect();
            for &i in &chosen {
                let name = app.fleet.robots[i].name.clone();
                app.update(Action::Select(crate::ui::Select::Toggle(name)));
            }
            let hovered = hover.map(|k| k.index(pos.len()));
            app.map.hover = hovered.map(|i| app.fleet.robots[i].name.clone());
            let t = map_text(&app);
            assert_apart(&t);
            proptest::prop_assert_eq!(t.marks.len(), pos.len(), "every robot marked");
            let labelled = t.texts.iter().filter(|p| matches!(p.kind, Kind::Robot(_))).count();
            proptest::prop_assert_eq!(labelled + t.hidden, pos.len());
            let must: Vec<usize> = (0..pos.len())
                .filter(|&i| app.cards.selection.contains(&app.fleet.robots[i].name) || hovered == Some(i))
                .collect();
            for i in must {
                proptest::prop_assert!(
                    t.texts.iter().any(|p| p.kind == Kind::Robot(i)),
                    "{} selected or hovered but not labelled",
                    app.fleet.robots[i].name
                );
            }
        }
    }

    #[test]
    fn ticks_name_the_grid_lines_in_metres() {
        assert_eq!(tick_text(2.0, 1.0), "2");
        assert_eq!(tick_text(-0.5, 0.5), "-0.5");
        assert_eq!(tick_text(0.15000001, 0.05), "0.15");
        assert_eq!(tick_text(-1e-12, 0.2), "0.0");
        let app = fixture::app(4, 160, 48);
        let t = map_text(&app);
        let ticks: Vec<&str> = t
            .texts
            .iter()
            .filter(|p| p.kind == Kind::Tick)
            .map(|p| p.text.as_str())
            .collect();
        // The fixture's arena is -3..3 m: the fit shows it with a margin.
        for v in ["-2", "-1", "0", "1", "2"] {
            assert!(ticks.contains(&v), "{v} in {ticks:?}");
        }
    }
}
