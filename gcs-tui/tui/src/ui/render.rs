//! `impl Widget for &App`: the whole screen as a pure function of the state.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::widgets::Widget;

use super::app::App;
use super::app::RobotsView;
use super::cards::CardsPanel;
use super::detail::DetailPanel;
use super::events::EventsPanel;
use super::help::HelpOverlay;
use super::layout::Areas;
use super::map::MapPanel;
use super::routes::RoutesPanel;
use super::status::{BottomBar, EStopBanner, PromptErrorBox, StatusBar};
use super::table::TablePanel;
use super::theme::Theme;
use super::waypoints::WaypointPanel;

impl Widget for &App {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let theme = Theme::new(self.session.monochrome);
        let a = Areas::compute(
            area,
            self.screen.side,
            self.screen.robots_view == RobotsView::Table,
        );
        StatusBar { app: self, theme }.render(a.status, buf);
        if let Some(r) = a.cards {
            CardsPanel { app: self, theme }.render(r, buf);
        }
        if let Some(r) = a.waypoints {
            WaypointPanel { app: self, theme }.render(r, buf);
        }
        if let Some(r) = a.routes {
            RoutesPanel { app: self, theme }.render(r, buf);
        }
        if let Some(r) = a.table {
            if self.table.detail {
                DetailPanel { app: self, theme }.render(r, buf);
            } else {
                TablePanel { app: self, theme }.render(r, buf);
            }
        }
        if !a.map.is_empty() {
            MapPanel { app: self, theme }.render(a.map, buf);
        }
        EventsPanel {
            app: self,
            theme,
            bordered: a.wide,
        }
        .render(a.log, buf);
        BottomBar { app: self, theme }.render(a.bottom, buf);
        if let Some(e) = &self.prompt.error {
            let h = 2;
            let r = Rect {
                x: area.x,
                y: a.bottom.y.saturating_sub(h),
                width: area.width,
                height: h.min(a.bottom.y),
            };
            PromptErrorBox { error: e, theme }.render(r, buf);
        }
        if self.fleet.estop {
            let over = a.table.unwrap_or(a.map);
            let r = Rect {
                x: over.x,
                y: over.y,
                width: over.width,
                height: 3.min(over.height),
            };
            EStopBanner { theme }.render(r, buf);
        }
        if self.screen.help.shown {
            HelpOverlay {
                theme,
                scroll: self.screen.help.scroll,
            }
            .render(area, buf);
        }
    }
}
