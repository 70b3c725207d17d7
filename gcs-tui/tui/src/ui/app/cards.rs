//! The selection (the robots the keys, waypoints and clusters act on, by
//! name) and the cards' scroll: selecting by name, next and previous in the
//! order the robots panel shows them, all, a cluster's members; and keeping
//! the selected robot on screen.

use std::collections::BTreeSet;

use super::{App, RobotsView, Select};
use crate::ui::layout::CARD_HEIGHT;

/// The robots panel's state, shared by the map, the table and the
/// waypoint panel through the selection.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CardsState {
    /// Selected robots, by name.
    pub selection: BTreeSet<String>,
    /// First card shown.
    pub scroll: usize,
}

impl CardsState {
    /// Scrolls so that card `i` is among the `visible` cards shown.
    pub fn show(&mut self, i: usize, visible: usize) {
        let visible = visible.max(1);
        if i < self.scroll {
            self.scroll = i;
        } else if i >= self.scroll + visible {
            self.scroll = i + 1 - visible;
        }
    }

    /// Scrolls one card up (`steps` > 0, the wheel turned up) or down, in a
    /// fleet of `robots`.
    pub fn wheel(&mut self, steps: i32, robots: usize) {
        if steps < 0 {
            self.scroll = (self.scroll + 1).min(robots.saturating_sub(1));
        } else {
            self.scroll = self.scroll.saturating_sub(1);
        }
    }
}

impl App {
    /// Lines one robot card takes.
    pub fn card_height(&self) -> usize {
        CARD_HEIGHT
    }

    /// Selected robots, in card order.
    pub(super) fn selected_robots(&self) -> Vec<String> {
        self.fleet
            .robots
            .iter()
            .filter(|r| self.cards.selection.contains(&r.name))
            .map(|r| r.name.clone())
            .collect()
    }

    /// Robots in the order the robots panel shows them: the table's rows
    /// (sorted and filtered) in the table view, else the fleet in name
    /// order. Next and previous follow it.
    fn display_order(&self) -> Vec<String> {
        let robots = &self.fleet.robots;
        match self.screen.robots_view {
            RobotsView::Table => self
                .table
                .rows
                .iter()
                .map(|&i| robots[i].name.clone())
                .collect(),
            RobotsView::Cards => robots.iter().map(|r| r.name.clone()).collect(),
        }
    }

    /// Changes the selection; the robot acted on becomes the routing
    /// table's row and the table's cursor, and is scrolled into view.
    pub(super) fn select(&mut self, s: Select) {
        let acted_on = match s {
            Select::Only(n) => {
                self.cards.selection.clear();
                self.fleet.robot(&n).is_some().then(|| {
                    self.cards.selection.insert(n.clone());
                    n
                })
            }
            Select::Toggle(n) => {
                if !self.cards.selection.remove(&n) && self.fleet.robot(&n).is_some() {
                    self.cards.selection.insert(n.clone());
                }
                Some(n)
            }
            Select::Next | Select::Prev | Select::AddNext | Select::AddPrev => {
                match self.step_selection(&s) {
                    Some(n) => Some(n),
                    None => return,
                }
            }
            Select::All => {
                self.cards.selection = self.display_order().into_iter().collect();
                None
            }
            Select::Clear => {
                self.cards.selection.clear();
                None
            }
            Select::Cluster(c) => {
                if let Some(cl) = self.fleet.clusters.iter().find(|x| x.name == c) {
                    self.cards.selection = cl.members.iter().cloned().collect();
                    self.fleet.active_cluster = Some(c);
                }
                None
            }
        };
        if let Some(name) = acted_on {
            if let Some(i) = self.fleet.index_of(&name) {
                self.routes.cursor.0 = i;
            }
            self.table.cursor = Some(name);
        }
        self.keep_selection_visible();
    }

    /// Next, previous, add next or add previous in display order, wrapping
    /// around; the robot selected, None in an empty panel.
    fn step_selection(&mut self, s: &Select) -> Option<String> {
        let names = self.display_order();
        if names.is_empty() {
            return None;
        }
        let idx_of = |n: &str| names.iter().position(|x| x == n);
        let picked = self.cards.selection.iter().filter_map(|n| idx_of(n));
        let (first, last) = (picked.clone().min(), picked.max());
        let n = names.len();
        let i = match (s, first, last) {
            (Select::Prev | Select::AddPrev, Some(i), _) => (i + n - 1) % n,
            (Select::Prev | Select::AddPrev, None, _) => n - 1,
            (_, _, Some(i)) => (i + 1) % n,
            (_, _, None) => 0,
        };
        if !matches!(s, Select::AddNext | Select::AddPrev) {
            self.cards.selection.clear();
        }
        self.cards.selection.insert(names[i].clone());
        Some(names[i].clone())
    }

    /// Scrolls the cards (or the table) so the first selected robot shows.
    pub(super) fn keep_selection_visible(&mut self) {
        if self.screen.robots_view == RobotsView::Table {
            self.keep_cursor_visible();
            return;
        }
        let Some(area) = self.areas().cards else {
            return;
        };
        let visible = usize::from(area.height.saturating_sub(2)) / self.card_height();
        let selection = &self.cards.selection;
        if let Some(i) = self
            .fleet
            .robots
            .iter()
            .position(|r| selection.contains(&r.name))
        {
            self.cards.show(i, visible);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_card_scrolled_to_is_on_screen_and_the_wheel_stops_at_the_ends() {
        let mut c = CardsState::default();
        c.show(7, 3);
        assert_eq!(c.scroll, 5, "card 7 is the last of three shown");
        c.show(2, 3);
        assert_eq!(c.scroll, 2);
        c.show(3, 3);
        assert_eq!(c.scroll, 2, "already shown");
        c.wheel(1, 10);
        c.wheel(1, 10);
        c.wheel(1, 10);
        assert_eq!(c.scroll, 0);
        for _ in 0..20 {
            c.wheel(-1, 10);
        }
        assert_eq!(c.scroll, 9);
    }
}
