//! Map geometry: which part of the arena, in metres, the map shows, and the
//! exact conversion between terminal cells, braille dots and metres.
//!
//! A braille cell is 2 dots wide and 4 dots tall; terminal cells are about
//! twice as tall as wide, so dots are square and one scale
//! (`metres_per_dot`) serves both axes. World x grows to the right, world y
//! grows up (REP 103 seen from above); screen rows grow down.
//!
//! Dot `(i, j)` of an area covers world `x` in
//! `[left + i*m, left + (i+1)*m)` and `y` in `(top - (j+1)*m, top - j*m]`,
//! the same truncation ratatui's canvas uses for bounds
//! `[left, left + (dots_x - 1)*m]`, so what is drawn and what is clicked
//! agree to the dot.

/// The visible part of the world: centre (m) and scale (m per braille dot).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Viewport {
    pub centre_x: f64,
    pub centre_y: f64,
    pub metres_per_dot: f64,
}

impl Default for Viewport {
    fn default() -> Self {
        Self {
            centre_x: 0.0,
            centre_y: 0.0,
            metres_per_dot: 0.05,
        }
    }
}

/// Finest and coarsest scales the zoom keys reach (1 mm .. 100 m per dot).
const MIN_SCALE: f64 = 1e-3;
const MAX_SCALE: f64 = 100.0;

/// A viewport laid over a concrete area of `width x height` cells.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Projection {
    /// World x of the left edge of dot column 0.
    pub left: f64,
    /// World y of the top edge of dot row 0.
    pub top: f64,
    pub metres_per_dot: f64,
    /// Area size in cells.
    pub width: u16,
    pub height: u16,
}

impl Viewport {
    pub fn new(centre_x: f64, centre_y: f64, metres_per_dot: f64) -> Self {
        Self {
            centre_x,
            centre_y,
            metres_per_dot: metres_per_dot.clamp(MIN_SCALE, MAX_SCALE),
        }
    }

    /// The projection onto an area of `width x height` cells.
    pub fn project(&self, width: u16, height: u16) -> Projection {
        let m = self.metres_per_dot;
        Projection {
            left: self.centre_x - f64::from(width) * m,
            top: self.centre_y + f64::from(height) * 2.0 * m,
            metres_per_dot: m,
            width,
            height,
        }
    }

    /// Zooms by `factor` (> 1 zooms in) keeping the world point `(x, y)`
    /// where it is on screen (zoom about the cursor).
    pub fn zoom_about(&mut self, factor: f64, x: f64, y: f64) {
        if !(factor.is_finite() && factor > 0.0) {
            return;
        }
        let new_scale = (self.metres_per_dot / factor).clamp(MIN_SCALE, MAX_SCALE);
        let k = new_scale / self.metres_per_dot;
        self.centre_x = x + (self.centre_x - x) * k;
        self.centre_y = y + (self.centre_y - y) * k;
        self.metres_per_dot = new_scale;
    }

    /// Zooms about the centre.
    pub fn zoom(&mut self, factor: f64) {
        let (x, y) = (self.centre_x, self.centre_y);
        self.zoom_about(factor, x, y);
    }

    /// Pans by a number of cells (positive = view moves right / up).
    pub fn pan_cells(&mut self, dx_cells: f64, dy_cells: f64) {
        self.centre_x += dx_cells * 2.0 * self.metres_per_dot;
        self.centre_y += dy_cells * 4.0 * self.metres_per_dot;
    }

    /// Fits the points (with a margin of 10 % and at least `min_span` m)
    /// into an area of `width x height` cells. No points: unchanged.
    pub fn fit(
        &mut self,
        points: impl IntoIterator<Item = (f64, f64)>,
        width: u16,
        height: u16,
        min_span: f64,
    ) {
        let mut it = points
            .into_iter()
            .filter(|(x, y)| x.is_finite() && y.is_finite());
        let Some((x0, y0)) = it.next() else {
            return;
        };
        let (mut xmin, mut xmax, mut ymin, mut ymax) = (x0, x0, y0, y0);
        for (x, y) in it {
            xmin = xmin.min(x);
            xmax = xmax.max(x);
            ymin = ymin.min(y);
            ymax = ymax.max(y);
        }
        let span_x = (xmax - xmin).max(min_span) * 1.2;
        let span_y = (ymax - ymin).max(min_span) * 1.2;
        let dots_x = (f64::from(width) * 2.0 - 1.0).max(1.0);
        let dots_y = (f64::from(height) * 4.0 - 1.0).max(1.0);
        let m = (span_x / dots_x).max(span_y / dots_y);
        *self = Viewport::new((xmin + xmax) / 2.0, (ymin + ymax) / 2.0, m);
    }
}

impl Projection {
    /// Canvas x bounds that make ratatui's dot mapping match this projection.
    pub fn x_bounds(&self) -> [f64; 2] {
        let dots = (f64::from(self.width) * 2.0 - 1.0).max(1.0);
        [self.left, self.left + dots * self.metres_per_dot]
    }

    /// Canvas y bounds that make ratatui's dot mapping match this projection.
    pub fn y_bounds(&self) -> [f64; 2] {
        let dots = (f64::from(self.height) * 4.0 - 1.0).max(1.0);
        [self.top - dots * self.metres_per_dot, self.top]
    }

    pub fn dots(&self) -> (usize, usize) {
        (usize::from(self.width) * 2, usize::from(self.height) * 4)
    }

    /// The braille dot containing a world point, if it is on screen: dot
    /// `floor((x - left) / m)`, `floor((top - y) / m)`. The bounds are
    /// checked on the quotients before they are cut to integers, which for
    /// a quotient in `[0, dots)` is the floor: the same dot, without a
    /// `floor` call per point (the map projects every point of every path,
    /// every frame).
    pub fn world_to_dot(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let (i, j) = self.world_to_dots(x, y);
        self.dot_at(i, j)
    }

    /// A world point in dot units, not cut to a dot: `(x - left) / m`,
    /// `(top - y) / m`.
    pub fn world_to_dots(&self, x: f64, y: f64) -> (f64, f64) {
        (
            (x - self.left) / self.metres_per_dot,
            (self.top - y) / self.metres_per_dot,
        )
    }

    /// The dot containing the point `(i, j)` in dot units, if it is on
    /// screen.
    pub fn dot_at(&self, i: f64, j: f64) -> Option<(usize, usize)> {
        let (w, h) = self.dots();
        (i >= 0.0 && j >= 0.0 && i < w as f64 && j < h as f64).then_some((i as usize, j as usize))
    }

    /// World point at the centre of a dot.
    pub fn dot_to_world(&self, i: usize, j: usize) -> (f64, f64) {
        (
            self.left + (i as f64 + 0.5) * self.metres_per_dot,
            self.top - (j as f64 + 0.5) * self.metres_per_dot,
        )
    }

    /// The cell (column, row, relative to the area) containing a world point.
    pub fn world_to_cell(&self, x: f64, y: f64) -> Option<(u16, u16)> {
        self.world_to_dot(x, y)
            .map(|(i, j)| ((i / 2) as u16, (j / 4) as u16))
    }

    /// World point at the centre of a cell (column, row relative to the
    /// area): where a mouse click in that cell lands.
    pub fn cell_to_world(&self, col: u16, row: u16) -> (f64, f64) {
        (
            self.left + (f64::from(col) * 2.0 + 1.0) * self.metres_per_dot,
            self.top - (f64::from(row) * 4.0 + 2.0) * self.metres_per_dot,
        )
    }

    /// A world point that ratatui's canvas places a text label at in cell
    /// (column, row). Labels use a coarser mapping than dots
    /// (`floor((x - left) * (cells - 1) / width)`), so a label is placed
    /// through this to land exactly in the cell its dot is in.
    pub fn label_anchor(&self, col: u16, row: u16) -> (f64, f64) {
        let [l, r] = self.x_bounds();
        let [b, t] = self.y_bounds();
        let res_x = f64::from(self.width.saturating_sub(1)).max(1.0);
        let res_y = f64::from(self.height.saturating_sub(1)).max(1.0);
        let x = l + (f64::from(col) + 0.5) * (r - l) / res_x;
        let y = t - (f64::from(row) + 0.5) * (t - b) / res_y;
        (x.min(r), y.max(b))
    }

    /// World rectangle shown: `(xmin, ymin, xmax, ymax)`.
    pub fn world_rect(&self) -> (f64, f64, f64, f64) {
        let (w, h) = self.dots();
        (
            self.left,
            self.top - h as f64 * self.metres_per_dot,
            self.left + w as f64 * self.metres_per_dot,
            self.top,
        )
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    #[test]
    fn centre_of_view_is_the_middle_cell_corner() {
        let v = Viewport::new(3.0, -2.0, 0.1);
        let p = v.project(40, 20);
        // The viewport centre sits at the corner between cells (19,9) and (20,10).
        assert_eq!(p.world_to_cell(3.0 + 1e-9, -2.0 - 1e-9), Some((20, 10)));
        assert_eq!(p.world_to_cell(3.0 - 1e-9, -2.0 + 1e-9), Some((19, 9)));
        let (x0, y0, x1, y1) = p.world_rect();
        assert!((x0 + x1) / 2.0 - 3.0 < 1e-9 && ((y0 + y1) / 2.0 + 2.0).abs() < 1e-9);
        assert!(((x1 - x0) - 8.0).abs() < 1e-9, "80 dots of 0.1 m");
        assert!(((y1 - y0) - 8.0).abs() < 1e-9, "80 dots of 0.1 m");
    }

    #[test]
    fn off_screen_points_have_no_cell() {
        let p = Viewport::new(0.0, 0.0, 0.1).project(10, 10);
        assert_eq!(p.world_to_cell(100.0, 0.0), None);
        assert_eq!(p.world_to_cell(0.0, -100.0), None);
    }

    #[test]
    fn zoom_about_keeps_the_cursor_point_fixed() {
        let mut v = Viewport::new(0.0, 0.0, 0.1);
        let p = v.project(60, 20);
        let (wx, wy) = p.cell_to_world(10, 3);
        v.zoom_about(2.0, wx, wy);
        let p2 = v.project(60, 20);
        assert_eq!(p2.world_to_cell(wx, wy), Some((10, 3)));
        assert!((v.metres_per_dot - 0.05).abs() < 1e-12);
    }

    #[test]
    fn pan_moves_by_whole_cells() {
        let mut v = Viewport::new(0.0, 0.0, 0.25);
        let before = v.project(20, 10).cell_to_world(5, 5);
        v.pan_cells(3.0, -2.0);
        let after = v.project(20, 10).cell_to_world(2, 3);
        assert!((before.0 - after.0).abs() < 1e-9 && (before.1 - after.1).abs() < 1e-9);
    }

    #[test]
    fn fit_shows_every_point() {
        let pts = [(-3.0, 1.0), (4.0, 2.5), (0.5, -6.0)];
        let mut v = Viewport::default();
        v.fit(pts, 50, 20, 1.0);
        let p = v.project(50, 20);
        for (x, y) in pts {
            assert!(p.world_to_cell(x, y).is_some(), "({x}, {y}) visible");
        }
    }

    #[test]
    fn canvas_bounds_match_ratatui_truncation() {
        // ratatui maps x to dot floor((x - left) * (dots - 1) / width).
        let p = Viewport::new(1.0, 2.0, 0.07).project(33, 11);
        let [l, r] = p.x_bounds();
        let [b, t] = p.y_bounds();
        let (w, h) = p.dots();
        for (x, y) in [(1.013, 2.021), (0.317, 1.113), (2.203, 2.971)] {
            let rx = ((x - l) * (w as f64 - 1.0) / (r - l)) as usize;
            let ry = ((t - y) * (h as f64 - 1.0) / (t - b)) as usize;
            assert_eq!(p.world_to_dot(x, y), Some((rx, ry)));
        }
    }

    #[test]
    fn label_anchor_lands_in_its_cell() {
        let p = Viewport::new(0.3, -0.2, 0.04).project(57, 21);
        let [l, r] = p.x_bounds();
        let [b, t] = p.y_bounds();
        for (c, row) in [(0u16, 0u16), (10, 3), (55, 19), (28, 10)] {
            let (x, y) = p.label_anchor(c, row);
            let lc = ((x - l) * 56.0 / (r - l)) as u16;
            let lr = ((t - y) * 20.0 / (t - b)) as u16;
            assert_eq!((lc, lr), (c, row));
        }
    }

    proptest! {
        #[test]
        fn cell_round_trip_under_zoom_and_pan(
            cx in -100.0f64..100.0, cy in -100.0f64..100.0,
            scale in 0.005f64..2.0, zoom in 0.2f64..5.0,
            px in -30.0f64..30.0, py in -30.0f64..30.0,
            w in 10u16..200, h in 5u16..60,
            col_frac in 0.0f64..1.0, row_frac in 0.0f64..1.0,
        ) {
            let mut v = Viewport::new(cx, cy, scale);
            v.zoom(zoom);
            v.pan_cells(px, py);
            let p = v.project(w, h);
            let col = ((f64::from(w) - 1.0) * col_frac) as u16;
            let row = ((f64::from(h) - 1.0) * row_frac) as u16;
            let (x, y) = p.cell_to_world(col, row);
            prop_assert_eq!(p.world_to_cell(x, y), Some((col, row)));
        }

        #[test]
        fn dot_round_trip(
            scale in 0.01f64..1.0, w in 2u16..100, h in 2u16..40,
            i_frac in 0.0f64..1.0, j_frac in 0.0f64..1.0,
        ) {
            let p = Viewport::new(0.0, 0.0, scale).project(w, h);
            let (dw, dh) = p.dots();
            let i = ((dw - 1) as f64 * i_frac) as usize;
            let j = ((dh - 1) as f64 * j_frac) as usize;
            let (x, y) = p.dot_to_world(i, j);
            prop_assert_eq!(p.world_to_dot(x, y), Some((i, j)));
        }

        /// The dot of any point, on the map, at its edges or off it, is the
        /// floor of its distance in dots from the top-left corner.
        #[test]
        fn a_point_is_on_the_dot_its_floored_distance_says(
            scale in 0.01f64..1.0, w in 2u16..100, h in 2u16..40,
            x in -60.0f64..60.0, y in -100.0f64..100.0, edge in 0usize..4,
        ) {
            let p = Viewport::new(0.5, -0.25, scale).project(w, h);
            let (dw, dh) = p.dots();
            // Points exactly on a dot's edge, and at the map's edges.
            let (x, y) = match edge {
                0 => (x, y),
                1 => (p.left + (x * 10.0).round() * scale, p.top - (y * 10.0).round() * scale),
                2 => (p.left + dw as f64 * scale, p.top - dh as f64 * scale),
                _ => (p.left - 1e-12, p.top + 1e-12),
            };
            let i = ((x - p.left) / scale).floor();
            let j = ((p.top - y) / scale).floor();
            let on = i >= 0.0 && j >= 0.0 && i < dw as f64 && j < dh as f64;
            prop_assert_eq!(p.world_to_dot(x, y), on.then_some((i as usize, j as usize)));
        }
    }
}
