//! What the live view shows, from the router's event subscription (a
//! bounded queue: what does not fit is dropped and counted, the router does
//! not wait): each robot's telemetry and pose as it comes, other events,
//! and, on a timer, the event log's new lines, the fleet as a scene and the
//! clusters. Messages are made by `mech_core::record`'s encoders, so they
//! are those of a recording; nothing is encoded for a channel nobody
//! subscribes to. The scene is drawn from a copy of the fleet model fed by
//! the same events (as the recorder does), so making it never holds the
//! station's fleet model.

use std::collections::HashMap;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use mech_core::event::{Event, Stamped};
use mech_core::fleet::Fleet;
use mech_core::record::{encode, scene, schema, unix_ns};
use mech_core::{Gcs, Subscription};

use super::hub::Hub;

/// How often drops are looked at (and logged if they grew).
const REPORT_EVERY: Duration = Duration::from_secs(10);

/// Clusters are sent again this often (a new subscriber sees them).
const CLUSTERS_EVERY: Duration = Duration::from_secs(1);

/// Events taken from the queue at a time, between looks at the timer.
const BATCH: usize = 256;

/// What the source took from the router and lost.
#[derive(Debug, Default)]
pub(super) struct Counts {
    /// Router events taken from the queue.
    pub(super) events: AtomicU64,
    /// Router events dropped: the queue was full.
    pub(super) dropped: AtomicU64,
}

/// The station-wide channels.
#[derive(Debug, Clone, Copy)]
struct Fixed {
    events: u32,
    log: u32,
    scene: u32,
    clusters: u32,
}

/// The source task's state.
pub(super) struct Source {
    gcs: Gcs,
    hub: Arc<Hub>,
    fixed: Fixed,
    /// Robot name -> (telemetry, pose) channels.
    robots: HashMap<String, (u32, u32)>,
    replica: Fleet,
    start_ns: u64,
    scene_hz: f64,
    last_scene: Option<Instant>,
    last_clusters: Option<Instant>,
    log_seq: u64,
    pub(super) counts: Arc<Counts>,
    /// Drops (router events, client messages) as last reported.
    reported: (u64, u64),
}

impl Source {
    /// Subscribes to `gcs`'s router (`queue` events deep) and advertises
    /// the station's channels and those of the robots it knows.
    pub(super) fn new(
        gcs: &Gcs,
        hub: Arc<Hub>,
        queue: usize,
        scene_hz: f64,
    ) -> (Source, Subscription) {
        let fixed = Fixed {
            events: hub.channel(schema::EVENTS, schema::MECH_EVENT),
            log: hub.channel(schema::LOG, schema::FOXGLOVE_LOG),
            scene: hub.channel(schema::SCENE, schema::SCENE_UPDATE),
            clusters: hub.channel(schema::CLUSTERS, schema::MECH_CLUSTERS),
        };
        let router = gcs.router();
        let sub = router.subscribe(queue, true);
        // Subscribed first: an event between the two may be applied twice
        // to the copy (harmless), none is missed.
        let replica = gcs.with_fleet(Fleet::clone);
        let log_seq = replica.log.back().map_or(0, |e| e.seq);
        let mut source = Source {
            gcs: gcs.clone(),
            hub,
            fixed,
            robots: HashMap::new(),
            start_ns: mech_core::record::router_start_unix_ns(router),
            scene_hz,
            last_scene: None,
            last_clusters: None,
            log_seq,
            counts: Default::default(),
            reported: (0, 0),
            replica,
        };
        let names: Vec<String> = source.replica.robots.keys().cloned().collect();
        for name in names {
            source.robot(&name);
        }
        (source, sub)
    }

    /// Runs until the router stops or the task is aborted.
    pub(super) async fn run(mut self, mut sub: Subscription) {
        let mut tick = tokio::time::interval(Duration::from_secs_f64(1.0 / self.scene_hz));
        tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Skip);
        let mut report = Instant::now();
        loop {
            tokio::select! {
                ev = sub.recv() => {
                    let Some(ev) = ev else { return };
                    self.event(&ev);
                    for _ in 0..BATCH {
                        let Some(ev) = sub.try_recv() else { break };
                        self.event(&ev);
                    }
                }
                _ = tick.tick() => self.tick(),
            }
            self.counts.dropped.store(sub.dropped(), Ordering::Relaxed);
            if report.elapsed() >= REPORT_EVERY {
                report = Instant::now();
                self.report(sub.dropped());
            }
        }
    }

    fn ns(&self, at: Duration) -> u64 {
        unix_ns(self.start_ns, at)
    }

    /// A robot's (telemetry, pose) channels, advertised on first use.
    fn robot(&mut self, name: &str) -> (u32, u32) {
        if let Some(ids) = self.robots.get(name) {
            return *ids;
        }
        let telemetry = self
            .hub
            .channel(&schema::telemetry_topic(name), schema::MECH_TELEMETRY);
        let pose = self
            .hub
            .channel(&schema::pose_topic(name), schema::POSE_IN_FRAME);
        self.robots.insert(name.to_string(), (telemetry, pose));
        (telemetry, pose)
    }

    fn event(&mut self, s: &Stamped) {
        self.counts.events.fetch_add(1, Ordering::Relaxed);
        let ns = self.ns(s.at);
        match &s.event {
            Event::Telemetry { robot, telemetry } => {
                let (tel, pose) = self.robot(robot);
                self.hub
                    .publish(pose, ns, || encode::pose(ns, &telemetry.pose));
                self.hub.publish(tel, ns, || encode::telemetry(telemetry));
            }
            _ => self.hub.publish(self.fixed.events, ns, || encode::event(s)),
        }
        self.replica.apply(s);
    }

    /// The log's new lines, then the scene and the clusters when due.
    fn tick(&mut self) {
        let now = self.gcs.router().elapsed();
        self.log_lines();
        let period = scene::period(self.scene_hz, self.replica.robots.len());
        if self.last_scene.is_none_or(|t| t.elapsed() >= period) {
            self.last_scene = Some(Instant::now());
            self.clusters(now);
            let ns = self.ns(now);
            let replica = &self.replica;
            self.hub
                .publish(self.fixed.scene, ns, || scene::scene(ns, replica));
        }
    }

    /// Lines of the station's event log since the last look (GCS-side
    /// lines included, which are not router events), as `foxglove.Log`.
    fn log_lines(&mut self) {
        let after = self.log_seq;
        let wanted = self.hub.wants(self.fixed.log);
        let lines = self.gcs.with_fleet(|f| {
            let newest = f.log.back().map_or(after, |e| e.seq);
            let lines: Vec<_> = match wanted {
                true => f.log_after(after).cloned().collect(),
                false => Vec::new(),
            };
            (newest, lines)
        });
        self.log_seq = lines.0;
        for e in lines.1 {
            let ns = self.ns(e.at);
            self.hub.publish(self.fixed.log, ns, || {
                encode::log_line(ns, e.severity, &e.text, "mech")
            });
        }
    }

    /// Cluster definitions (not events: read from the station's model),
    /// when they change and every second.
    fn clusters(&mut self, now: Duration) {
        let live = self.gcs.with_fleet(|f| f.clusters.clone());
        let due = self
            .last_clusters
            .is_none_or(|t| t.elapsed() >= CLUSTERS_EVERY);
        if live == self.replica.clusters && !due {
            return;
        }
        self.last_clusters = Some(Instant::now());
        self.replica.clusters = live;
        let clusters = &self.replica.clusters;
        self.hub.publish(self.fixed.clusters, self.ns(now), || {
            encode::clusters(now, clusters)
        });
    }

    /// Logs drops that grew since the last report.
    fn report(&mut self, router_dropped: u64) {
        let client_dropped = self.hub.stats.dropped.load(Ordering::Relaxed);
        if (router_dropped, client_dropped) != self.reported {
            tracing::warn!(
                router_events_dropped = router_dropped,
                client_messages_dropped = client_dropped,
                clients = self.hub.clients(),
                "Foxglove live view fell behind: {} router events and {} client messages dropped so far",
                router_dropped,
                client_dropped
            );
            self.reported = (router_dropped, client_dropped);
        }
    }
}
