//! The map's state: the viewport (which part of the arena, in metres, the
//! map shows), the arena's outline, the robot under the mouse pointer, a
//! drag that pans the map, and whether the view was fitted to the fleet
//! yet; fitting the view to the fleet.

use super::App;
use crate::ui::layout::Areas;
use crate::ui::view::ArenaBounds;
use crate::ui::viewport::Viewport;

/// What the map shows and how the mouse is moving it.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MapState {
    pub viewport: Viewport,
    /// Arena outline, from the options or the station.
    pub arena: Option<ArenaBounds>,
    /// The robot under the mouse pointer on the map: always labelled.
    pub hover: Option<String>,
    /// The cell a drag last reached, while the button is down.
    drag_from: Option<(u16, u16)>,
    /// The view was fitted to the first robots that reported a position.
    fitted_once: bool,
}

impl MapState {
    /// A drag starts at a cell.
    pub fn start_drag(&mut self, col: u16, row: u16) {
        self.drag_from = Some((col, row));
    }

    /// The drag reached a cell: the map follows the pointer.
    pub fn drag_to(&mut self, col: u16, row: u16) {
        let Some((c0, r0)) = self.drag_from else {
            return;
        };
        let dx = f64::from(c0) - f64::from(col);
        let dy = f64::from(row) - f64::from(r0);
        self.viewport.pan_cells(dx, dy);
        self.drag_from = Some((col, row));
    }

    pub fn end_drag(&mut self) {
        self.drag_from = None;
    }

    /// True the first time it is asked: the view is to be fitted to the
    /// fleet once, when robots first report where they are.
    pub fn first_fit(&mut self) -> bool {
        !std::mem::replace(&mut self.fitted_once, true)
    }
}

impl App {
    /// Fits the map to the fleet, the arena and the waypoints (as the map
    /// view lays it out, also while the table hides the map).
    pub(super) fn fit_fleet(&mut self) {
        let area = ratatui::layout::Rect::new(0, 0, self.screen.size.0, self.screen.size.1);
        let inner = Areas::compute(area, self.screen.side, false).map_inner();
        let mut pts: Vec<(f64, f64)> = self
            .fleet
            .robots
            .iter()
            .map(|r| (r.telemetry.pose.x, r.telemetry.pose.y))
            .collect();
        if let Some(a) = self.map.arena {
            pts.push((a.min_x, a.min_y));
            pts.push((a.max_x, a.max_y));
        }
        pts.extend(self.waypoints.list.iter().map(|w| (w.x, w.y)));
        self.map.viewport.fit(pts, inner.width, inner.height, 1.0);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_drag_pans_by_the_cells_moved_and_only_while_held() {
        let mut m = MapState::default();
        m.drag_to(10, 10);
        assert_eq!(m.viewport, Viewport::default(), "no drag started");
        m.start_drag(10, 10);
        m.drag_to(6, 12);
        let d = Viewport::default().metres_per_dot;
        assert!((m.viewport.centre_x - 4.0 * 2.0 * d).abs() < 1e-12);
        assert!((m.viewport.centre_y - 2.0 * 4.0 * d).abs() < 1e-12);
        m.end_drag();
        let before = m.viewport;
        m.drag_to(0, 0);
        assert_eq!(m.viewport, before);
        assert!(m.first_fit() && !m.first_fit(), "fitted once");
    }
}
