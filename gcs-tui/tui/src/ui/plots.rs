//! A robot's last minute as charts, in the detail view (live and in a
//! replay): its speed as it reports it against the speed its positions
//! show, heading, battery, link loss, round trip, and the cross-track error
//! of a mission this TUI sent. Each chart is a ratatui [`Chart`] in braille
//! (dots for the second series), so it reads over SSH and without colour:
//! the title says which mark is which. Drawn from [`History`] alone.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::style::Style;
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Chart, Dataset, GraphType, Paragraph, Widget};

use super::app::{HISTORY_SECONDS, History, RobotHistory};
use super::series::Series;
use super::theme::Theme;

/// The least height of a chart, borders included: a line of plot between
/// its title, its y labels and its x labels.
pub const MIN_HEIGHT: u16 = 5;

/// One chart: its title, its series (the first drawn as a braille line, a
/// second as dots) and its y range.
#[derive(Debug, Clone, PartialEq)]
pub struct Plot {
    pub title: String,
    pub series: Vec<Vec<(f64, f64)>>,
    /// A fixed range (battery, heading), or the data's, at least this wide.
    pub range: Range,
    /// Shown in place of the chart when there is nothing to draw.
    pub empty: &'static str,
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Range {
    Fixed(f64, f64),
    /// From the data, at least this span, and from 0 when `from_zero`.
    Auto {
        min_span: f64,
        from_zero: bool,
    },
}

/// The charts of a robot, in the order shown.
pub fn plots(history: &History, robot: &str) -> Vec<Plot> {
    let empty = RobotHistory::default();
    let h = history.robot(robot).unwrap_or(&empty);
    let now = history.now;
    let own = if h.measured { "enc" } else { "cmd" };
    let xte_empty = if history.knows_path(robot) {
        "no leg being flown"
    } else {
        "send waypoints from here"
    };
    let auto = |min_span| Range::Auto {
        min_span,
        from_zero: true,
    };
    vec![
        Plot {
            title: format!(" speed m/s ⠤{own} •pos "),
            series: vec![
                h.points(Series::Speed, now),
                h.points(Series::GroundSpeed, now),
            ],
            range: auto(0.1),
            empty: "no telemetry yet",
        },
        Plot {
            title: " heading ° ".into(),
            series: vec![h.points(Series::Heading, now)],
            range: Range::Fixed(-180.0, 180.0),
            empty: "no telemetry yet",
        },
        Plot {
            title: " battery % ".into(),
            series: vec![h.points(Series::Battery, now)],
            range: Range::Fixed(0.0, 100.0),
            empty: "not reported",
        },
        Plot {
            title: " loss % ".into(),
            series: vec![h.points(Series::Loss, now)],
            range: auto(5.0),
            empty: "not measured yet",
        },
        Plot {
            title: " round trip ms ".into(),
            series: vec![h.points(Series::Rtt, now)],
            range: auto(1.0),
            empty: "not measured yet",
        },
        Plot {
            title: " cross-track m ".into(),
            series: vec![h.points(Series::CrossTrack, now)],
            range: Range::Auto {
                min_span: 0.1,
                from_zero: false,
            },
            empty: xte_empty,
        },
    ]
}

/// Where `n` charts go in `area`: three across from 72 cells, two from 44,
/// else one; as many rows as fit at [`MIN_HEIGHT`] (the first charts
/// first), sharing the height.
pub fn grid(area: Rect, n: usize) -> Vec<Rect> {
    let cols: u16 = if area.width >= 72 {
        3
    } else if area.width >= 44 {
        2
    } else {
        1
    };
    let fit_rows = area.height / MIN_HEIGHT;
    let rows = (n as u16).div_ceil(cols).min(fit_rows);
    if rows == 0 {
        return Vec::new();
    }
    let (w, h) = (area.width / cols, area.height / rows);
    let mut out = Vec::new();
    for row in 0..rows {
        for col in 0..cols {
            if out.len() == n {
                return out;
            }
            // The last column and row take what division left over.
            let width = if col + 1 == cols {
                area.width - w * col
            } else {
                w
            };
            let height = if row + 1 == rows {
                area.height - h * row
            } else {
                h
            };
            out.push(Rect::new(area.x + w * col, area.y + h * row, width, height));
        }
    }
    out
}

/// A number for an axis label: as few digits as tell it.
fn label(v: f64) -> String {
    let a = v.abs();
    if a >= 100.0 || v == 0.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else {
        format!("{v:.2}")
    }
}

/// The y range of a plot.
fn bounds(plot: &Plot) -> [f64; 2] {
    match plot.range {
        Range::Fixed(lo, hi) => [lo, hi],
        Range::Auto {
            min_span,
            from_zero,
        } => {
            let values = plot.series.iter().flatten().map(|p| p.1);
            let (mut lo, mut hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                (l.min(v), h.max(v))
            });
            if from_zero {
                lo = lo.min(0.0);
            }
            if hi - lo < min_span {
                if from_zero && lo >= 0.0 {
                    hi = lo + min_span;
                } else {
                    let mid = (hi + lo) / 2.0;
                    (lo, hi) = (mid - min_span / 2.0, mid + min_span / 2.0);
                }
            }
            [lo, hi]
        }
    }
}

/// One chart in `area`, with its border and title.
pub fn draw(plot: &Plot, area: Rect, buf: &mut Buffer, t: &Theme) {
    let block = Block::bordered()
        .title(plot.title.as_str())
        .border_style(t.dim());
    if plot.series.iter().all(Vec::is_empty) {
        let inner = block.inner(area);
        block.render(area, buf);
        Paragraph::new(Line::styled(plot.empty, t.dim())).render(inner, buf);
        return;
    }
    let marks = [
        (Marker::Braille, GraphType::Line),
        (Marker::Dot, GraphType::Scatter),
    ];
    let datasets: Vec<Dataset> = plot
        .series
        .iter()
        .zip(marks)
        .map(|(points, (marker, graph))| {
            Dataset::default()
                .marker(marker)
                .graph_type(graph)
                .style(Style::new())
                .data(points)
        })
        .collect();
    let [lo, hi] = bounds(plot);
    let x = Axis::default()
        .bounds([-HISTORY_SECONDS, 0.0])
        .style(t.dim())
        .labels([
            Span::raw(format!("-{HISTORY_SECONDS:.0}s")),
            Span::raw("now"),
        ]);
    let y = Axis::default()
        .bounds([lo, hi])
        .style(t.dim())
        .labels([Span::raw(label(lo)), Span::raw(label(hi))]);
    Chart::new(datasets)
        .block(block)
        .x_axis(x)
        .y_axis(y)
        .legend_position(None)
        .render(area, buf);
}

/// The last minute of `points` (`(seconds before now, value)`) in
/// `width` cells of block bars `▁`..`█`: each cell the mean of its share of
/// the minute, scaled from the minute's least value over at least
/// `min_span` (so noise stays flat); a blank where nothing was known.
pub fn spark(points: &[(f64, f64)], width: usize, min_span: f64) -> String {
    const BARS: [char; 8] = ['▁', '▂', '▃', '▄', '▅', '▆', '▇', '█'];
    let mut sums = vec![(0.0, 0u32); width];
    for &(t, v) in points {
        let at = ((t + HISTORY_SECONDS) / HISTORY_SECONDS * width as f64).floor();
        if at >= 0.0 {
            let cell = (at as usize).min(width.saturating_sub(1));
            sums[cell].0 += v;
            sums[cell].1 += 1;
        }
    }
    let means: Vec<Option<f64>> = sums
        .iter()
        .map(|&(s, n)| (n > 0).then(|| s / f64::from(n)))
        .collect();
    let known = means.iter().flatten();
    let lo = known.clone().fold(f64::INFINITY, |a, &b| a.min(b));
    let hi = known
        .fold(f64::NEG_INFINITY, |a, &b| a.max(b))
        .max(lo + min_span);
    means
        .iter()
        .map(|m| match m {
            Some(v) => {
                let level = ((v - lo) / (hi - lo) * 7.0).round().clamp(0.0, 7.0);
                BARS[level as usize]
            }
            None => ' ',
        })
        .collect()
}

/// The trend of `robot`'s `series` over the last minute, as [`spark`].
pub fn trend(
    history: &History,
    robot: &str,
    series: Series,
    width: usize,
    min_span: f64,
) -> String {
    let points = history
        .robot(robot)
        .map(|h| h.points(series, history.now))
        .unwrap_or_default();
    spark(&points, width, min_span)
}

/// The charts of `robot` over `area`, as many as fit.
#[derive(Debug)]
pub struct PlotGrid<'a> {
    pub history: &'a History,
    pub robot: &'a str,
    pub theme: Theme,
}

impl Widget for PlotGrid<'_> {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let all = plots(self.history, self.robot);
        for (plot, rect) in all.iter().zip(grid(area, all.len())) {
            draw(plot, rect, buf, &self.theme);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn six_charts_three_across_when_wide_and_fewer_when_short() {
        let wide = grid(Rect::new(0, 0, 78, 14), 6);
        assert_eq!(wide.len(), 6);
        assert_eq!((wide[0].width, wide[0].height), (26, 7));
        assert_eq!(wide[5], Rect::new(52, 7, 26, 7));
        let narrow = grid(Rect::new(0, 0, 50, 15), 6);
        assert_eq!(narrow.len(), 6, "two across, three down");
        let short = grid(Rect::new(0, 0, 78, 6), 6);
        assert_eq!(short.len(), 3, "one row: the first three");
        assert!(grid(Rect::new(0, 0, 78, 4), 6).is_empty());
    }

    #[test]
    fn a_spark_shows_the_minute_left_to_right_and_blanks_the_unknown() {
        let rising: Vec<(f64, f64)> = (0..60)
            .map(|i| (f64::from(i) - 59.5, f64::from(i)))
            .collect();
        assert_eq!(spark(&rising, 8, 1.0), "▁▂▃▄▅▆▇█");
        let flat_noise: Vec<(f64, f64)> = (0..60)
            .map(|i| (f64::from(i) - 59.5, 20.0 + 0.01 * f64::from(i % 2)))
            .collect();
        assert_eq!(spark(&flat_noise, 8, 2.0), "▁▁▁▁▁▁▁▁");
        let gap: Vec<(f64, f64)> = vec![(-50.0, 1.0), (-1.0, 3.0)];
        assert_eq!(spark(&gap, 4, 1.0), "▁  █");
    }

    #[test]
    fn ranges_hold_the_data_and_never_collapse() {
        let p = |points: Vec<(f64, f64)>, range| Plot {
            title: String::new(),
            series: vec![points],
            range,
            empty: "",
        };
        let auto = Range::Auto {
            min_span: 5.0,
            from_zero: true,
        };
        assert_eq!(bounds(&p(vec![(0.0, 0.0)], auto)), [0.0, 5.0]);
        assert_eq!(bounds(&p(vec![(0.0, 2.0), (1.0, 12.0)], auto)), [0.0, 12.0]);
        let centred = Range::Auto {
            min_span: 0.1,
            from_zero: false,
        };
        let [lo, hi] = bounds(&p(vec![(0.0, -0.02)], centred));
        assert!((lo + 0.07).abs() < 1e-12 && (hi - 0.03).abs() < 1e-12);
        assert_eq!(label(-180.0), "-180");
        assert_eq!(label(0.42), "0.42");
    }
}
