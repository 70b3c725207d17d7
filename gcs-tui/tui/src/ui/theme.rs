//! Colours and text styles, with a monochrome variant that carries every
//! distinction (selection, alarms, pending) by modifiers alone.

use ratatui::style::{Color, Modifier, Style};

/// Robot colours, in fleet order.
const PALETTE: [Color; 8] = [
    Color::Cyan,
    Color::Yellow,
    Color::Magenta,
    Color::Green,
    Color::LightBlue,
    Color::LightRed,
    Color::LightGreen,
    Color::LightMagenta,
];

/// Styles for one frame.
#[derive(Debug, Clone, Copy)]
pub struct Theme {
    pub mono: bool,
}

impl Theme {
    pub fn new(mono: bool) -> Theme {
        Theme { mono }
    }

    fn fg(&self, c: Color) -> Color {
        if self.mono { Color::Reset } else { c }
    }

    /// Colour of the `i`-th robot.
    pub fn robot(&self, i: usize) -> Color {
        self.fg(PALETTE[i % PALETTE.len()])
    }

    pub fn grid(&self) -> Color {
        self.fg(Color::DarkGray)
    }

    pub fn arena(&self) -> Color {
        self.fg(Color::Gray)
    }

    /// Keep-outs and obstacle discs on the map.
    pub fn keep_out(&self) -> Color {
        self.fg(Color::LightRed)
    }

    /// Slow zones on the map.
    pub fn slow_zone(&self) -> Color {
        self.fg(Color::Yellow)
    }

    pub fn waypoint(&self) -> Color {
        self.fg(Color::LightYellow)
    }

    pub fn cluster(&self) -> Color {
        self.fg(Color::White)
    }

    pub fn title(&self) -> Style {
        Style::new().add_modifier(Modifier::BOLD)
    }

    pub fn dim(&self) -> Style {
        if self.mono {
            Style::new().add_modifier(Modifier::DIM)
        } else {
            Style::new().fg(Color::DarkGray)
        }
    }

    pub fn ok(&self) -> Style {
        Style::new().fg(self.fg(Color::Green))
    }

    pub fn warn(&self) -> Style {
        Style::new()
            .fg(self.fg(Color::Yellow))
            .add_modifier(Modifier::BOLD)
    }

    pub fn alarm(&self) -> Style {
        if self.mono {
            Style::new().add_modifier(Modifier::REVERSED | Modifier::BOLD)
        } else {
            Style::new()
                .fg(Color::White)
                .bg(Color::Red)
                .add_modifier(Modifier::BOLD)
        }
    }

    pub fn selected(&self) -> Style {
        Style::new().add_modifier(Modifier::REVERSED)
    }

    pub fn focused_border(&self) -> Style {
        if self.mono {
            Style::new().add_modifier(Modifier::BOLD)
        } else {
            Style::new().fg(Color::LightCyan)
        }
    }

    pub fn bar(&self) -> Style {
        if self.mono {
            Style::new().add_modifier(Modifier::REVERSED)
        } else {
            Style::new().fg(Color::Black).bg(Color::Gray)
        }
    }
}
