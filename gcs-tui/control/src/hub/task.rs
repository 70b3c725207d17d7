//! The control task: a period at every tick of [`super::HubConfig::rate_hz`]
//! and whenever a request kicks it, and the cluster commands of external
//! programs as they arrive. A period reads the fleet model once, steps
//! every concern's controllers (each under its own lock, one after the
//! other), publishes what they decided through per-channel publishers (so
//! sequence numbers run on per channel) and logs their events.

use std::sync::Weak;
use std::time::Duration;

use tokio::time::Instant;

use super::period::{Outgoing, PeriodInputs, PeriodOutput};
use super::{ControlHub, Shared};
use mech_core::Event;
use mech_core::fleet::Severity;
use mech_core::router::{Delivery, Publishers, Subscription};
use mech_core::sync::lock;

/// Runs until the last hub is dropped or the router stops: a period at
/// every tick or kick, an external cluster command as it arrives.
pub(super) async fn run(
    shared: Weak<Shared>,
    mut events: Subscription,
    mut publishers: Publishers,
    period: Duration,
) {
    let mut ticker = tokio::time::interval(period);
    ticker.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
    loop {
        {
            let Some(s) = shared.upgrade() else { return };
            let kick = async move { s.kick.notified().await };
            tokio::select! {
                _ = ticker.tick() => {}
                _ = kick => {}
                ev = events.recv() => match ev {
                    Some(ev) => {
                        if let Event::ClusterCommand { channel, command } = &ev.event {
                            if let Some(s) = shared.upgrade() {
                                ControlHub { shared: s }.external(channel, command);
                            }
                        }
                        continue;
                    }
                    None => return,
                },
            }
        }
        let Some(s) = shared.upgrade() else { return };
        let hub = ControlHub { shared: s };
        let output = hub.period();
        hub.publish(&mut publishers, output.outgoing).await;
        hub.record(output.log);
    }
}

impl ControlHub {
    /// One control period on the fleet model's telemetry: every cluster,
    /// follow and offboard controller steps once on the robots routed to it.
    fn period(&self) -> PeriodOutput {
        let s = &self.shared;
        let mut inputs = self.period_inputs();
        let mut output = PeriodOutput::default();
        lock(&s.clusters).step(&inputs, &mut output);
        lock(&s.follows).step(&inputs, &mut output);
        let mut navs = lock(&s.navs);
        navs.note_progress(std::mem::take(&mut inputs.progress));
        navs.step(&inputs, s.config.nav.telemetry_timeout, &mut output);
        output
    }

    /// What the controllers read from the fleet model this period.
    fn period_inputs(&self) -> PeriodInputs {
        let s = &self.shared;
        let now = s.gcs.router().elapsed().as_secs_f64();
        let idle =
            lock(&s.clusters).is_empty() && lock(&s.follows).is_empty() && lock(&s.navs).is_empty();
        s.gcs.with_fleet(|f| PeriodInputs::read(f, now, idle))
    }

    /// Publishes what a period decided; the first offboard command the router
    /// forwards to a robot completes its switch to offboard.
    async fn publish(&self, publishers: &mut Publishers, outgoing: Vec<Outgoing>) {
        for o in outgoing {
            match o {
                Outgoing::Fleet { channel, parts } => {
                    if let Err(e) = publishers.on(&channel).send_fleet(parts).await {
                        tracing::warn!(%channel, error = %e, "fleet command not published");
                    }
                }
                Outgoing::Nav {
                    channel,
                    robot,
                    command,
                } => match publishers.on(&channel).send(&robot, command).await {
                    Ok(Delivery::Forwarded(_)) => self.forwarded(&robot),
                    Ok(_) => {}
                    Err(e) => {
                        tracing::warn!(%channel, error = %e, "offboard command not published")
                    }
                },
            }
        }
    }

    /// Records that an offboard command for `robot` was forwarded, and wakes
    /// a switch to offboard waiting for it.
    fn forwarded(&self, robot: &str) {
        if lock(&self.shared.navs).forwarded(robot, Instant::now()) {
            self.shared.forwarded.notify_waiters();
        }
    }

    /// Logs a period's controller events, to tracing and the fleet log.
    fn record(&self, log: Vec<(Severity, String)>) {
        if log.is_empty() {
            return;
        }
        for (severity, text) in &log {
            if *severity >= Severity::Warn {
                tracing::warn!(target: "control", "{text}");
            } else {
                tracing::info!(target: "control", "{text}");
            }
        }
        self.shared.gcs.update_fleet(|f| {
            for (severity, text) in log {
                f.log(severity, text);
            }
        });
    }
}
