//! The figures of one scenario, how they are read off the station's
//! events, the robots' telemetry and the agents' counters, and the table
//! they are printed as.

use mech_e2e::harness::controller::{Controller, Sample};
use mech_e2e::harness::station::Line;
use mech_proto::FailsafeState;

/// Resend period of routes and e-stops (the router's defaults): an
/// acknowledgement arriving later than this needed a resend.
const RESEND_S: f64 = 0.1;

/// One row of the table.
#[derive(Debug, Default, Clone)]
pub struct Figures {
    pub scenario: String,
    /// Commands published while the robots were routed, and obeyed.
    pub sent: u64,
    pub obeyed: u64,
    /// Worst time from the controller's last command to the robot's
    /// failsafe stop, ms.
    pub trip_ms: Option<f64>,
    /// Failsafe trips beyond those the scenario causes on purpose.
    pub false_trips: Option<i64>,
    /// Route acknowledgements that came only after a resend, of all.
    pub acks_resent: (usize, usize),
    /// E-stop acknowledgements that came only after a resend, of all.
    pub estops_resent: (usize, usize),
    /// Worst time from the e-stop to a robot stopped by it, ms.
    pub estop_ms: Option<f64>,
    /// Worst time to recover (see each scenario), ms.
    pub recovery_ms: Option<f64>,
    pub note: String,
}

fn ms(v: Option<f64>) -> String {
    v.map_or("-".into(), |v| format!("{v:.0}"))
}

/// The figures as a Markdown table.
pub fn table(rows: &[Figures]) -> String {
    let mut t = String::from(
        "| scenario | commands delivered | failsafe trip (ms, worst) | false trips | route acks resent | e-stops resent | e-stop reach (ms, worst) | recovery (ms, worst) |\n\
         | --- | --- | --- | --- | --- | --- | --- | --- |\n",
    );
    for r in rows {
        let delivered = if r.sent == 0 {
            "-".to_string()
        } else {
            format!(
                "{}/{} ({:.0}%)",
                r.obeyed,
                r.sent,
                100.0 * r.obeyed as f64 / r.sent as f64
            )
        };
        t += &format!(
            "| {}{} | {delivered} | {} | {} | {}/{} | {}/{} | {} | {} |\n",
            r.scenario,
            if r.note.is_empty() {
                String::new()
            } else {
                format!(" ({})", r.note)
            },
            ms(r.trip_ms),
            r.false_trips.map_or("-".into(), |n| n.to_string()),
            r.acks_resent.0,
            r.acks_resent.1,
            r.estops_resent.0,
            r.estops_resent.1,
            ms(r.estop_ms),
            ms(r.recovery_ms),
        );
    }
    t
}

/// Of the acknowledgements `ack` answering events `start` (matched by
/// robot, the latest start before each), how many came later than one
/// resend period, and how many there were.
pub fn resent(lines: &[Line], start: &str, ack: &str) -> (usize, usize) {
    let mut n = (0, 0);
    for a in lines.iter().filter(|l| l.is_event(ack)) {
        let begun = lines
            .iter()
            .filter(|l| l.is_event(start) && (l.robot() == a.robot() || l.robot().is_empty()))
            .filter(|l| l.t() <= a.t())
            .map(Line::t)
            .fold(f64::NAN, f64::max);
        if begun.is_nan() {
            continue;
        }
        n.1 += 1;
        if a.t() - begun >= RESEND_S {
            n.0 += 1;
        }
    }
    n
}

/// The worst, over `robots`, of the time from `since_us` to the robot's
/// first telemetry stamped after it that matches `want`, ms; `None` if a
/// robot never reported it.
pub fn worst_time(
    ctl: &Controller,
    robots: &[&str],
    since_us: u64,
    want: impl Fn(&Sample) -> bool,
) -> Option<f64> {
    let mut worst: f64 = 0.0;
    for r in robots {
        let s = ctl.first(r, since_us, &want)?;
        worst = worst.max((s.stamp_us - since_us) as f64 / 1000.0);
    }
    Some(worst)
}

/// The time from `since_us` to an agent's reported time `at` (µs since
/// the Unix epoch, same machine and clock), ms; `None` if it is not after.
pub fn after(at: &serde_json::Value, since_us: u64) -> Option<f64> {
    let at = at.as_u64()?;
    (at >= since_us).then(|| (at - since_us) as f64 / 1000.0)
}

/// The worse of two times; `None` (never happened) is worst.
pub fn worse(a: Option<f64>, b: Option<f64>) -> Option<f64> {
    Some(a?.max(b?))
}

/// Driving again: commanded, failsafe clear.
pub fn driving(s: &Sample) -> bool {
    s.failsafe == FailsafeState::Ok && s.moving
}
