//! The fault-injection suite: the real station and agents under loss
//! (network namespace + nftables random drop), delay with jitter (a
//! userspace proxy), a partition and its healing, the station and an
//! agent killed with SIGKILL and restarted, and a serial radio with a bit
//! error rate of 1e-3 (pseudo-terminals and a noisy frame hub).
//!
//! Each scenario prints its figures (commands delivered, failsafe trip
//! time, false trips, acknowledgements and e-stops that needed a resend,
//! e-stop reach time, recovery time) as a row of one table, then the
//! suite asserts the required outcomes:
//! - an e-stop reaches every robot within 1 s at 50% loss;
//! - no false failsafe trip at 10% loss;
//! - after a station restart every agent is registered again within 1 s
//!   of the station being back, and holds still (routed to none) until
//!   routed;
//! - a restarted agent does not resume its mission, and the station says
//!   the mission was lost.
//!
//! The namespace scenarios need root, `ip` and `nft`; the radio ones
//! `socat` (`scripts/deps.sh` installs them). Without them the suite says
//! what it skipped, and fails under CI (`CI` set), where they must run.

mod figures;
mod restart;
mod rig;
mod scenarios;

use figures::Figures;

#[test]
fn fault_injection_suite() {
    let mut rows: Vec<Figures> = Vec::new();
    let mut failures: Vec<String> = Vec::new();
    let netns = mech_e2e::harness::netns::available();
    let socat = mech_e2e::harness::have("socat", "-V");
    type Scenario = Box<dyn Fn(&mut Vec<String>) -> Figures>;
    let mut plan: Vec<(&str, Scenario)> = Vec::new();
    match &netns {
        Ok(()) => {
            for loss in [10, 30, 50] {
                plan.push(("loss", Box::new(move |f| scenarios::loss(loss, f))));
            }
            plan.push(("partition", Box::new(scenarios::partition)));
        }
        Err(why) => skipped(
            &format!("loss and partition scenarios: {why}"),
            &mut failures,
        ),
    }
    plan.push(("delay", Box::new(scenarios::delay)));
    plan.push(("station restart", Box::new(restart::station)));
    plan.push(("agent restart", Box::new(restart::agent)));
    if socat {
        plan.push(("radio", Box::new(scenarios::radio)));
    } else {
        skipped("radio scenario: socat is missing", &mut failures);
    }
    // MECH_FAULTS=partition (a word of the scenario names) runs only those.
    let only = std::env::var("MECH_FAULTS").ok();
    for (name, scenario) in plan {
        if only.as_deref().is_some_and(|o| !name.contains(o)) {
            continue;
        }
        let started = std::time::Instant::now();
        // A scenario that panics (a station that never routed, say) is a
        // failure of its own; the others still run and print.
        let ran =
            std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| scenario(&mut failures)));
        match ran {
            Ok(row) => rows.push(row),
            Err(e) => failures.push(format!("{name}: {}", panic_text(&e))),
        }
        println!("{name}: {:.1} s", started.elapsed().as_secs_f64());
    }
    println!("\n{}", figures::table(&rows));
    assert!(
        failures.is_empty(),
        "required outcomes not met:\n{}",
        failures.join("\n")
    );
}

fn panic_text(e: &Box<dyn std::any::Any + Send>) -> String {
    e.downcast_ref::<String>()
        .cloned()
        .or_else(|| e.downcast_ref::<&str>().map(|s| s.to_string()))
        .unwrap_or_else(|| "panicked".into())
}

/// A scenario this machine cannot run: said, and a failure under CI.
fn skipped(what: &str, failures: &mut Vec<String>) {
    println!("SKIPPED {what}");
    if std::env::var_os("CI").is_some() {
        failures.push(format!("CI must run every scenario; skipped {what}"));
    }
}
