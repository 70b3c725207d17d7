//! The fleet table's columns: what each shows, how wide it is, which stay
//! when the table is narrow, how rows sort by each, and what the `/`
//! filter matches. Pure functions of the view model, shared by the App
//! (which keeps the sorted, filtered rows) and the table widget.

use std::cmp::Ordering;

use mech_core::names::natural_cmp;
use mech_proto::{FailsafeState, MissionProgress};

use super::series::Series;
use super::view::{RobotView, failsafe_str, health_str, link_label, mode_str};

/// Cells before the first column: the selection mark and a space.
pub const GUTTER: usize = 2;

/// Cells of the trend drawn after the column the table is sorted by.
pub const TREND_WIDTH: usize = 8;

/// One column of the fleet table.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum Column {
    #[default]
    Name,
    Platform,
    Link,
    Route,
    Mode,
    Failsafe,
    Pose,
    Speed,
    Battery,
    Mission,
    /// Messages per second from the robot.
    Rx,
    /// Messages per second to the robot.
    Tx,
    Loss,
    Rtt,
}

impl Column {
    /// Every column, in the order shown.
    pub const ALL: [Column; 14] = [
        Column::Name,
        Column::Platform,
        Column::Link,
        Column::Route,
        Column::Mode,
        Column::Failsafe,
        Column::Pose,
        Column::Speed,
        Column::Battery,
        Column::Mission,
        Column::Rx,
        Column::Tx,
        Column::Loss,
        Column::Rtt,
    ];

    pub fn header(self) -> &'static str {
        match self {
            Column::Name => "NAME",
            Column::Platform => "PLATFORM",
            Column::Link => "LINK",
            Column::Route => "ROUTE",
            Column::Mode => "MODE",
            Column::Failsafe => "FAILSAFE",
            Column::Pose => "     X      Y   HDG",
            Column::Speed => "SPEED",
            Column::Battery => "BAT",
            Column::Mission => "MISSION",
            Column::Rx => "RX/s",
            Column::Tx => "TX/s",
            Column::Loss => "LOSS",
            Column::Rtt => "RTT",
        }
    }

    /// Width in cells (a space separates columns).
    pub fn width(self) -> usize {
        match self {
            Column::Name | Column::Platform => 10,
            Column::Link | Column::Mode => 9,
            Column::Route => 16,
            Column::Failsafe => 11,
            Column::Pose => 19,
            Column::Speed => 5,
            Column::Battery => 4,
            Column::Mission => 7,
            Column::Rx | Column::Tx => 5,
            Column::Loss => 6,
            Column::Rtt => 7,
        }
    }

    /// Which columns stay when the table is narrow: lower first. What an
    /// operator scans a fleet for (who, is it there, who drives it, is it
    /// safe, is its link good) before where it is and what it runs on.
    fn priority(self) -> u8 {
        match self {
            Column::Name => 0,
            Column::Link => 1,
            Column::Loss => 2,
            Column::Route => 3,
            Column::Failsafe => 4,
            Column::Mode => 5,
            Column::Rtt => 6,
            Column::Battery => 7,
            Column::Mission => 8,
            Column::Speed => 9,
            Column::Rx => 10,
            Column::Tx => 11,
            Column::Platform => 12,
            Column::Pose => 13,
        }
    }

    /// The column `step` places after this one (wrapping), for the sort
    /// keys.
    pub fn step(self, step: i32) -> Column {
        let n = Column::ALL.len() as i64;
        let i = Column::ALL.iter().position(|c| *c == self).unwrap_or(0) as i64;
        Column::ALL[(i + i64::from(step)).rem_euclid(n) as usize]
    }

    /// What the cell shows for `r`.
    pub fn text(self, r: &RobotView) -> String {
        let q = &r.quality;
        let measured = |v: f64| {
            if q.measured() {
                format!("{v:.1}")
            } else {
                "–".into()
            }
        };
        match self {
            Column::Name => r.name.clone(),
            Column::Platform => r.platform.clone(),
            Column::Link => link_label(r.link).into(),
            Column::Route => route_text(r),
            Column::Mode => mode_str(r.telemetry.mode).into(),
            Column::Failsafe => failsafe_str(r.telemetry.failsafe).into(),
            Column::Pose => format!(
                "{:6.2} {:6.2} {:4.0}°",
                r.telemetry.pose.x,
                r.telemetry.pose.y,
                r.heading_deg()
            ),
            Column::Speed => format!("{:.2}", r.speed()),
            Column::Battery => r
                .telemetry
                .battery
                .map_or_else(|| "–".into(), |b| format!("{:.0}%", b * 100.0)),
            Column::Mission => r.telemetry.mission.map_or_else(|| "–".into(), mission_text),
            Column::Rx => measured(q.rx_hz),
            Column::Tx => measured(q.tx_hz),
            Column::Loss => q.loss_text(),
            Column::Rtt => q.rtt_text(),
        }
    }

    /// The series of the last minute the trend after this column draws
    /// when the table is sorted by it (and the least span its bars scale
    /// to, so noise stays flat): the numbers that move.
    pub fn trend(self) -> Option<(Series, f64)> {
        match self {
            Column::Speed => Some((Series::Speed, 0.05)),
            Column::Battery => Some((Series::Battery, 2.0)),
            Column::Rx => Some((Series::Rx, 2.0)),
            Column::Tx => Some((Series::Tx, 2.0)),
            Column::Loss => Some((Series::Loss, 2.0)),
            Column::Rtt => Some((Series::Rtt, 0.5)),
            _ => None,
        }
    }

    /// Order of two robots by this column, ascending; ties are left to
    /// the caller (the table keeps natural name order among equals).
    pub fn cmp(self, a: &RobotView, b: &RobotView) -> Ordering {
        match self {
            Column::Name => natural_cmp(&a.name, &b.name),
            Column::Platform => a.platform.cmp(&b.platform),
            Column::Link => link_rank(a).cmp(&link_rank(b)),
            Column::Route => a.route.channel.cmp(&b.route.channel),
            Column::Mode => mode_str(a.telemetry.mode).cmp(mode_str(b.telemetry.mode)),
            Column::Failsafe => {
                failsafe_rank(a.telemetry.failsafe).cmp(&failsafe_rank(b.telemetry.failsafe))
            }
            Column::Pose => a
                .telemetry
                .pose
                .x
                .total_cmp(&b.telemetry.pose.x)
                .then(a.telemetry.pose.y.total_cmp(&b.telemetry.pose.y)),
            Column::Speed => a.speed().total_cmp(&b.speed()),
            Column::Battery => option_cmp(a.telemetry.battery, b.telemetry.battery),
            Column::Mission => option_cmp(
                a.telemetry.mission.map(progress),
                b.telemetry.mission.map(progress),
            ),
            Column::Rx => a.quality.rx_hz.total_cmp(&b.quality.rx_hz),
            Column::Tx => a.quality.tx_hz.total_cmp(&b.quality.tx_hz),
            Column::Loss => option_cmp(a.quality.loss, b.quality.loss),
            Column::Rtt => a.quality.rtt.cmp(&b.quality.rtt),
        }
    }
}

/// `wp/gcs✓` acknowledged, `joy/0…` pending, `none`.
pub fn route_text(r: &RobotView) -> String {
    if r.route.channel.is_empty() {
        "none".to_string()
    } else if r.route.acknowledged {
        format!("{}✓", r.route.channel)
    } else {
        format!("{}…", r.route.channel)
    }
}

/// `wp 2/3`, or `arrived` once past the last waypoint.
pub fn mission_text(m: MissionProgress) -> String {
    if m.next >= m.total {
        "arrived".into()
    } else {
        format!("wp {}/{}", m.next + 1, m.total)
    }
}

fn progress(m: MissionProgress) -> f64 {
    if m.total == 0 {
        1.0
    } else {
        f64::from(m.next) / f64::from(m.total)
    }
}

fn link_rank(r: &RobotView) -> u8 {
    r.link as u8
}

/// Worse states sort later.
fn failsafe_rank(f: FailsafeState) -> u8 {
    match f {
        FailsafeState::Ok => 0,
        FailsafeState::ChannelSilent => 1,
        FailsafeState::RouterLost => 2,
        FailsafeState::Fault => 3,
        FailsafeState::EStopped => 4,
    }
}

/// Unknown before every known value.
fn option_cmp(a: Option<f64>, b: Option<f64>) -> Ordering {
    match (a, b) {
        (Some(x), Some(y)) => x.total_cmp(&y),
        (a, b) => a.is_some().cmp(&b.is_some()),
    }
}

/// The columns that fit in `width` cells (after the gutter), in the order
/// shown: by priority while they fit.
pub fn visible(width: usize) -> Vec<Column> {
    let mut by_priority = Column::ALL;
    by_priority.sort_by_key(|c| c.priority());
    let mut room = width.saturating_sub(GUTTER);
    let mut shown = Vec::new();
    for c in by_priority {
        let need = c.width() + usize::from(!shown.is_empty());
        if need <= room {
            room -= need;
            shown.push(c);
        }
    }
    Column::ALL
        .into_iter()
        .filter(|c| shown.contains(c))
        .collect()
}

/// How the table is laid out in `width` cells when sorted by `sort`: the
/// columns shown, and the column a trend follows: the sort column, when it
/// has one and still shows with the trend's room taken.
pub fn layout(width: usize, sort: Column) -> (Vec<Column>, Option<Column>) {
    if sort.trend().is_some() {
        let narrower = visible(width.saturating_sub(TREND_WIDTH + 1));
        if narrower.contains(&sort) {
            return (narrower, Some(sort));
        }
    }
    (visible(width), None)
}

/// The column under cell `x` of a table laid out with `columns` (and a
/// trend after `trend_after`), `x` counted from the table's left inner
/// edge; the trend's cells are its column's.
pub fn column_at(columns: &[Column], trend_after: Option<Column>, x: usize) -> Option<Column> {
    let mut left = GUTTER;
    for c in columns {
        let mut width = c.width();
        if trend_after == Some(*c) {
            width += 1 + TREND_WIDTH;
        }
        if x >= left && x < left + width {
            return Some(*c);
        }
        left += width + 1;
    }
    None
}

/// Whether `r` matches the filter `needle` (already lower case): its name,
/// route, platform, link, mode, failsafe or health contains it, ignoring
/// case. An empty filter matches everything.
pub fn matches(r: &RobotView, needle: &str) -> bool {
    needle.is_empty()
        || [
            r.name.as_str(),
            r.route.channel.as_str(),
            r.platform.as_str(),
            link_label(r.link),
            mode_str(r.telemetry.mode),
            failsafe_str(r.telemetry.failsafe),
            health_str(r.telemetry.health),
        ]
        .iter()
        .any(|field| contains_ignoring_case(field, needle))
}

fn contains_ignoring_case(haystack: &str, needle: &str) -> bool {
    let (h, n) = (haystack.as_bytes(), needle.as_bytes());
    n.len() <= h.len()
        && h.windows(n.len())
            .any(|w| w.iter().zip(n).all(|(a, b)| a.to_ascii_lowercase() == *b))
}

/// The rows of the table: indices into `robots` (which are in natural name
/// order) of those matching `filter`, sorted by `by`; equal rows keep
/// natural name order whichever the direction.
pub fn sorted_rows(robots: &[RobotView], by: Column, descending: bool, filter: &str) -> Vec<usize> {
    let needle = filter.to_lowercase();
    let mut rows: Vec<usize> = (0..robots.len())
        .filter(|&i| matches(&robots[i], &needle))
        .collect();
    if by == Column::Name {
        if descending {
            rows.reverse();
        }
        return rows;
    }
    rows.sort_by(|&a, &b| {
        let o = by.cmp(&robots[a], &robots[b]);
        if descending { o.reverse() } else { o }
    });
    rows
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ui::fixture;

    #[test]
    fn a_narrow_table_keeps_the_most_telling_columns() {
        let all = visible(500);
        assert_eq!(all, Column::ALL);
        let narrow = visible(82);
        assert_eq!(
            narrow,
            [
                Column::Name,
                Column::Link,
                Column::Route,
                Column::Mode,
                Column::Failsafe,
                Column::Battery,
                Column::Loss,
                Column::Rtt
            ]
        );
        let used: usize = GUTTER + narrow.iter().map(|c| c.width() + 1).sum::<usize>() - 1;
        assert!(used <= 82);
        assert_eq!(visible(14), [Column::Name]);
    }

    #[test]
    fn a_click_finds_its_column() {
        let cols = [Column::Name, Column::Link];
        assert_eq!(column_at(&cols, None, 0), None, "the gutter");
        assert_eq!(column_at(&cols, None, GUTTER), Some(Column::Name));
        assert_eq!(column_at(&cols, None, GUTTER + 10), None, "the separator");
        assert_eq!(column_at(&cols, None, GUTTER + 11), Some(Column::Link));
        let cols = [Column::Name, Column::Loss, Column::Rtt];
        let trend = Some(Column::Loss);
        let rtt = GUTTER + 11 + 7 + TREND_WIDTH + 1;
        assert_eq!(
            column_at(&cols, trend, rtt - 2),
            Some(Column::Loss),
            "the trend"
        );
        assert_eq!(column_at(&cols, trend, rtt), Some(Column::Rtt));
    }

    #[test]
    fn the_sort_column_has_its_trend_where_it_helps_and_fits() {
        let (cols, trend) = layout(78, Column::Loss);
        assert_eq!(trend, Some(Column::Loss));
        let used: usize = GUTTER + cols.iter().map(|c| c.width() + 1).sum::<usize>() + TREND_WIDTH;
        assert!(used <= 78, "{cols:?}");
        assert_eq!(
            layout(78, Column::Name),
            (visible(78), None),
            "names do not trend"
        );
        let (_, trend) = layout(20, Column::Pose);
        assert_eq!(trend, None, "pose is not shown that narrow, nor trended");
    }

    #[test]
    fn rows_sort_by_a_column_and_keep_name_order_among_equals() {
        let robots = fixture::fleet(8).robots;
        // Links cycle Connected, Connected, Stale, Lost.
        let rows = sorted_rows(&robots, Column::Link, false, "");
        let names: Vec<&str> = rows.iter().map(|&i| robots[i].name.as_str()).collect();
        assert_eq!(
            names,
            [
                "robot_1", "robot_2", "robot_5", "robot_6", "robot_3", "robot_7", "robot_4",
                "robot_8"
            ]
        );
        let rows = sorted_rows(&robots, Column::Link, true, "");
        assert_eq!(robots[rows[0]].name, "robot_4", "lost first, by name");
        let rows = sorted_rows(&robots, Column::Name, true, "");
        assert_eq!(robots[rows[0]].name, "robot_8");
    }

    #[test]
    fn the_filter_matches_name_route_or_state_ignoring_case() {
        let robots = fixture::fleet(12).robots;
        let names = |f: &str| -> Vec<String> {
            sorted_rows(&robots, Column::Name, false, f)
                .into_iter()
                .map(|i| robots[i].name.clone())
                .collect()
        };
        assert_eq!(
            names("robot_1"),
            ["robot_1", "robot_10", "robot_11", "robot_12"]
        );
        assert_eq!(names("JOY/0"), ["robot_2", "robot_6", "robot_10"]);
        assert_eq!(names("router-lost"), ["robot_4", "robot_8", "robot_12"]);
        assert_eq!(names("").len(), 12);
        assert!(names("nothing like it").is_empty());
    }
}
