//! The events pane: the most recent log lines, newest at the bottom.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::text::Line;
use ratatui::widgets::{Block, Paragraph, Widget};

use super::app::{App, LogLevel};
use super::theme::Theme;

/// The events pane; bordered when there is room for it.
#[derive(Debug)]
pub struct EventsPanel<'a> {
    pub app: &'a App,
    pub theme: Theme,
    pub bordered: bool,
}

impl Widget for EventsPanel<'_> {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let t = self.theme;
        let inner = if self.bordered {
            let block = Block::bordered().title(" Events ");
            let inner = block.inner(area);
            block.render(area, buf);
            inner
        } else {
            area
        };
        let n = usize::from(inner.height);
        let skip = self.app.events.len().saturating_sub(n);
        let lines: Vec<Line> = self
            .app
            .events
            .iter()
            .skip(skip)
            .map(|l| {
                let style = match l.level {
                    LogLevel::Info => ratatui::style::Style::new(),
                    LogLevel::Warn => t.warn(),
                    LogLevel::Error => t.alarm(),
                };
                Line::styled(l.text.as_str(), style)
            })
            .collect();
        Paragraph::new(lines).render(inner, buf);
    }
}
