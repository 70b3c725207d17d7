//! The driving scenarios: robots commanded at 20 Hz under a fault, then
//! the controller goes quiet (the failsafe must stop them), then an e-stop
//! and its release, then the agents stop and report their counters.

use std::time::Duration;

use crate::figures::{self, Figures};
use crate::rig::{FAILSAFE, Rig};
use mech_e2e::harness::unix_us;

/// How long the robots are driven under the fault.
const DRIVE: Duration = Duration::from_secs(6);

/// What a scenario does besides the common run.
struct Plan<'a> {
    name: String,
    /// Applied once the robots are routed.
    fault: &'a dyn Fn(&Rig),
    /// Run after driving under the fault; returns a recovery time, ms.
    middle: &'a dyn Fn(&Rig) -> Option<f64>,
    /// Failsafe trips each robot has on purpose (the final silence, and a
    /// partition's).
    trips_each: i64,
}

/// The common run.
fn run(mut rig: Rig, plan: &Plan<'_>) -> Figures {
    rig.wait_routed();
    let names = rig.names();
    let robots: Vec<&str> = names.iter().map(String::as_str).collect();
    let sent0 = rig.ctl.sent.load(std::sync::atomic::Ordering::SeqCst);
    (plan.fault)(&rig);
    std::thread::sleep(DRIVE);
    let recovery_ms = (plan.middle)(&rig);
    let stop = unix_us();
    rig.ctl.publish(false);
    let sent = rig.ctl.sent.load(std::sync::atomic::Ordering::SeqCst) - sent0;
    std::thread::sleep(Duration::from_millis(1500));
    let estop = rig.ctl.estop(true);
    std::thread::sleep(Duration::from_secs(2));
    rig.ctl.estop(false);
    std::thread::sleep(Duration::from_millis(500));
    let (mut obeyed, mut trips) = (0, 0);
    let (mut trip_ms, mut estop_ms) = (Some(0.0_f64), Some(0.0_f64));
    for a in &mut rig.agents {
        let c = a.stop().unwrap_or_default();
        obeyed += c["commands"].as_u64().unwrap_or(0);
        let tripped = c["failsafe_trips"].as_i64().unwrap_or(0);
        trips += tripped;
        if tripped > plan.trips_each {
            // What the failsafe did, to tell a false trip's cause.
            let log = a.log();
            let lines: Vec<&str> = log.lines().filter(|l| l.contains("failsafe")).collect();
            println!("{}: {} trips:\n{}", a.name, tripped, lines.join("\n"));
        }
        trip_ms = figures::worse(trip_ms, figures::after(&c["tripped_at_us"], stop));
        estop_ms = figures::worse(estop_ms, figures::after(&c["estopped_at_us"], estop));
    }
    let lines = rig.station.lines();
    Figures {
        scenario: plan.name.clone(),
        sent,
        obeyed,
        trip_ms,
        false_trips: Some(trips - plan.trips_each * robots.len() as i64),
        acks_resent: figures::resent(&lines, "route_changed", "route_acked"),
        estops_resent: figures::resent(&lines, "estop", "estop_acked"),
        estop_ms,
        recovery_ms,
        note: String::new(),
    }
}

fn nothing(_: &Rig) {}

fn no_middle(_: &Rig) -> Option<f64> {
    None
}

/// `percent` random loss each way between the robots and the station.
pub fn loss(percent: u32, failures: &mut Vec<String>) -> Figures {
    let rig = Rig::udp(3, true, FAILSAFE, None);
    let fault = move |r: &Rig| r.net.as_ref().expect("namespace").set_loss(percent);
    let f = run(
        rig,
        &Plan {
            name: format!("{percent}% loss, 3 robots"),
            fault: &fault,
            middle: &no_middle,
            trips_each: 1,
        },
    );
    if percent == 50 {
        match f.estop_ms {
            Some(ms) if ms <= 1000.0 => {}
            other => failures.push(format!(
                "50% loss: the e-stop must reach every robot within 1 s; worst {other:?} ms"
            )),
        }
    }
    if percent == 10 && f.false_trips != Some(0) {
        failures.push(format!(
            "10% loss: no false failsafe trip allowed; got {:?}",
            f.false_trips
        ));
    }
    f
}

/// 200 ms delay with ±50 ms jitter each way (datagrams overtake each
/// other).
pub fn delay(_failures: &mut Vec<String>) -> Figures {
    let rig = Rig::udp(3, false, FAILSAFE, None);
    let fault = |r: &Rig| {
        let p = r.proxy.as_ref().expect("proxy");
        p.faults
            .delay(Duration::from_millis(200), Duration::from_millis(50));
    };
    run(
        rig,
        &Plan {
            name: "200 ms delay ±50 ms jitter, 3 robots".into(),
            fault: &fault,
            middle: &no_middle,
            trips_each: 1,
        },
    )
}

/// A 3 s partition, then healed; recovery is from the heal until every
/// robot drives again.
pub fn partition(_failures: &mut Vec<String>) -> Figures {
    let rig = Rig::udp(3, true, FAILSAFE, None);
    let middle = |r: &Rig| {
        let net = r.net.as_ref().expect("namespace");
        net.set_loss(100);
        std::thread::sleep(Duration::from_secs(3));
        let healed = unix_us();
        net.set_loss(0);
        std::thread::sleep(Duration::from_secs(3));
        let names = r.names();
        let robots: Vec<&str> = names.iter().map(String::as_str).collect();
        figures::worst_time(&r.ctl, &robots, healed, figures::driving)
    };
    let mut f = run(
        rig,
        &Plan {
            name: "partition 3 s, healed".into(),
            fault: &nothing,
            middle: &middle,
            trips_each: 2,
        },
    );
    f.note = "recovery: heal to driving".into();
    f
}

/// Two robots on one radio at a bit error rate of 1e-3.
pub fn radio(_failures: &mut Vec<String>) -> Figures {
    let rig = Rig::radio(2, 1e-3);
    let mut f = run(
        rig,
        &Plan {
            name: "radio, bit error rate 1e-3, 2 robots".into(),
            fault: &nothing,
            middle: &no_middle,
            trips_each: 1,
        },
    );
    f.note = "115200 baud".into();
    f
}
