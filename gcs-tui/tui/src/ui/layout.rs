//! Screen layout as a pure function of the terminal size, shared by the
//! renderer and by click handling (so a click is resolved against exactly
//! the rectangles that were drawn).

use ratatui::layout::{Constraint, Layout, Rect};

/// Width and height from which every panel is shown at once.
pub const WIDE_MIN: (u16, u16) = (120, 36);

/// Panels that share the side column on small terminals.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum SidePanel {
    #[default]
    Cards,
    Waypoints,
    Routes,
}

/// Where each panel goes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Areas {
    pub status: Rect,
    pub cards: Option<Rect>,
    pub waypoints: Option<Rect>,
    pub routes: Option<Rect>,
    /// The map including its border.
    pub map: Rect,
    pub log: Rect,
    /// Key hints or the command line.
    pub bottom: Rect,
    /// All panels visible at once.
    pub wide: bool,
}

impl Areas {
    /// Lays out `area`; on a small terminal the side column shows `side`.
    pub fn compute(area: Rect, side: SidePanel) -> Areas {
        let wide = area.width >= WIDE_MIN.0 && area.height >= WIDE_MIN.1;
        let log_h = if wide { 7 } else { 2 };
        let [status, body, log, bottom] = Layout::vertical([
            Constraint::Length(1),
            Constraint::Min(3),
            Constraint::Length(log_h),
            Constraint::Length(1),
        ])
        .areas(area);
        if wide {
            let right_w = (area.width / 4).clamp(36, 56);
            let left_w = (area.width / 4).clamp(40, 56);
            let [left, map, right] = Layout::horizontal([
                Constraint::Length(left_w),
                Constraint::Min(10),
                Constraint::Length(right_w),
            ])
            .areas(body);
            let [wp, routes] =
                Layout::vertical([Constraint::Percentage(40), Constraint::Percentage(60)])
                    .areas(right);
            Areas {
                status,
                cards: Some(left),
                waypoints: Some(wp),
                routes: Some(routes),
                map,
                log,
                bottom,
                wide,
            }
        } else {
            // The routing table needs the width for its channel columns.
            let left_w = if side == SidePanel::Routes {
                (area.width / 2).clamp(20, 44)
            } else {
                (area.width * 2 / 5).clamp(20, 40)
            };
            let [left, map] =
                Layout::horizontal([Constraint::Length(left_w), Constraint::Min(10)]).areas(body);
            let (cards, waypoints, routes) = match side {
                SidePanel::Cards => (Some(left), None, None),
                SidePanel::Waypoints => (None, Some(left), None),
                SidePanel::Routes => (None, None, Some(left)),
            };
            Areas {
                status,
                cards,
                waypoints,
                routes,
                map,
                log,
                bottom,
                wide,
            }
        }
    }

    /// The map's drawing area (inside its border).
    pub fn map_inner(&self) -> Rect {
        inner(self.map)
    }
}

/// A rectangle minus a one-cell border.
pub fn inner(r: Rect) -> Rect {
    Rect {
        x: r.x.saturating_add(1),
        y: r.y.saturating_add(1),
        width: r.width.saturating_sub(2),
        height: r.height.saturating_sub(2),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_terminal_shares_the_side_column() {
        let a = Areas::compute(Rect::new(0, 0, 80, 24), SidePanel::Routes);
        assert!(!a.wide);
        assert!(a.cards.is_none() && a.waypoints.is_none());
        assert!(a.routes.is_some());
        assert!(a.map.width >= 40 && a.map.height >= 18);
    }

    #[test]
    fn large_terminal_shows_everything() {
        let a = Areas::compute(Rect::new(0, 0, 160, 48), SidePanel::Cards);
        assert!(a.wide);
        assert!(a.cards.is_some() && a.waypoints.is_some() && a.routes.is_some());
    }
}
