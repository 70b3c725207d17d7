//! The tokio loop around an agent core: receives messages from the link,
//! runs a control period on every tick, writes actuators and sends what the
//! core returns. One task per agent; a simulated fleet shares one tick.

use std::cell::RefCell;
use std::net::SocketAddr;
use std::time::Duration;

use mech_proto::Envelope;
use tokio::net::UdpSocket;
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;

use crate::hal::{Actuators, PositionSample, WheelEncoders};
use crate::links::LinkChoice;
use crate::machine::{Agent, Counters};

/// Something a vehicle's driver (an autopilot, a ROS 2 base) tells the
/// operator: a notice in the station's event log.
#[derive(Debug, Clone, PartialEq)]
pub struct Report {
    pub level: mech_proto::Level,
    pub text: String,
}

impl Report {
    pub fn info(text: String) -> Report {
        Report {
            level: mech_proto::Level::Info,
            text,
        }
    }

    pub fn warn(text: String) -> Report {
        Report {
            level: mech_proto::Level::Warn,
            text,
        }
    }

    pub fn error(text: String) -> Report {
        Report {
            level: mech_proto::Level::Error,
            text,
        }
    }

    /// The notice saying it (an error is a driver fault), logged too.
    pub fn notice(&self, agent: &mut Agent, now: Duration) -> Envelope {
        let code = if self.level >= mech_proto::Level::Error {
            mech_proto::NoticeCode::DriverFault
        } else {
            mech_proto::NoticeCode::Text
        };
        tracing::info!(level = ?self.level, "{}", self.text);
        agent.notice(self.level, code, &self.text, now)
    }
}

/// Puts what a vehicle's driver measures (an autopilot's, a ROS 2 base's)
/// into each telemetry among `outgoing`.
pub fn patch_telemetry(
    outgoing: &mut [Envelope],
    mut patch: impl FnMut(&mut mech_proto::Telemetry),
) {
    for env in outgoing {
        if let mech_proto::Body::Telemetry(t) = &mut env.body {
            patch(t);
        }
    }
}

/// What the loop drives: an agent core with its vehicle (hardware or
/// simulated).
pub trait Vehicle: Send {
    /// The agent core.
    fn agent(&self) -> &Agent;
    fn agent_mut(&mut self) -> &mut Agent;
    /// One control period; returns messages to send.
    fn tick(&mut self, now: Duration) -> Vec<Envelope>;
    /// Zeroes the actuators and returns the `Bye` to send.
    fn stop(&mut self, now: Duration) -> Envelope;
    /// Numbers a message about to be sent (once, on however many links).
    fn number(&mut self, env: &mut Envelope) {
        self.agent_mut().number(env);
    }
    /// Handles one received datagram.
    fn handle_bytes(&mut self, bytes: &[u8], now: Duration) -> Vec<Envelope> {
        self.agent_mut().handle_bytes(bytes, now)
    }
    /// Encodes a message to send on the robot's link number `link`
    /// (signed, when the robot has a key).
    fn encode(
        &mut self,
        env: &Envelope,
        link: u8,
        out: &mut Vec<u8>,
    ) -> Result<(), mech_proto::Error> {
        self.agent_mut().encode_on(env, link, out)
    }
    /// Handles one received message.
    fn handle(&mut self, env: Envelope, now: Duration) -> Vec<Envelope> {
        self.agent_mut().handle(env, now)
    }
    /// A heartbeat (a probe on a link not in use).
    fn heartbeat(&mut self, now: Duration) -> Envelope {
        self.agent_mut().heartbeat(now)
    }
    /// The agent's counters.
    fn counters(&self) -> Counters {
        self.agent().counters()
    }
}

/// A robot with real actuators, (optionally) a position source read by its
/// own thread, and (optionally) wheel encoders.
pub struct HardwareVehicle {
    pub agent: Agent,
    pub actuators: Box<dyn Actuators + Send>,
    /// Samples (or driver error texts) from the position thread.
    pub positions: Option<std::sync::mpsc::Receiver<Result<PositionSample, String>>>,
    /// Wheel encoders, read once per control period.
    pub encoders: Option<Box<dyn WheelEncoders + Send>>,
}

impl std::fmt::Debug for HardwareVehicle {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HardwareVehicle")
            .field("agent", &self.agent)
            .finish_non_exhaustive()
    }
}

impl Vehicle for HardwareVehicle {
    fn agent(&self) -> &Agent {
        &self.agent
    }
    fn agent_mut(&mut self) -> &mut Agent {
        &mut self.agent
    }
    fn tick(&mut self, now: Duration) -> Vec<Envelope> {
        let mut extra = Vec::new();
        // Odometry first: fixes are then compared with the pose at their
        // own (earlier) time.
        if let Some(encoders) = self.encoders.as_mut() {
            match encoders.read_all(now) {
                Ok(counts) => extra.extend(self.agent.observe_wheels(&counts, now)),
                Err(e) => {
                    tracing::warn!(error = %e, "encoders");
                    extra.extend(self.agent.driver_fault(&format!("encoders: {e}"), now));
                }
            }
        }
        if let Some(rx) = &self.positions {
            while let Ok(sample) = rx.try_recv() {
                match sample {
                    Ok(s) => self.agent.observe_position(s),
                    Err(e) => {
                        tracing::warn!(error = %e, "position source");
                        extra.extend(
                            self.agent
                                .driver_fault(&format!("position source: {e}"), now),
                        );
                    }
                }
            }
        }
        let tick = self.agent.tick(now);
        if let Err(e) = self.actuators.set_outputs(&tick.outputs) {
            tracing::error!(error = %e, "actuators");
            extra.extend(self.agent.actuator_fault(&format!("actuators: {e}"), now));
            // Zero what still answers.
            let _ = self.actuators.stop_all(tick.outputs.len());
        }
        let mut out = tick.outgoing;
        out.extend(extra);
        out
    }
    fn stop(&mut self, now: Duration) -> Envelope {
        let motors = self.agent.platform().motors();
        if let Err(e) = self.actuators.stop_all(motors) {
            tracing::error!(error = %e, "could not zero actuators on shutdown");
        }
        self.agent.bye("shutdown", now)
    }
}

/// How long a stopping agent waits for a link's writer thread to write
/// what was queued (its Bye) before it may exit.
pub const FLUSH_WAIT: Duration = Duration::from_secs(2);

/// The sending side of a link framed elsewhere (a serial link's writer
/// thread): messages queue to the thread. Dropped (the agent stops), it
/// ends the queue and waits up to [`FLUSH_WAIT`] for the thread to write
/// what was in it, so the agent's Bye is on the wire before the process
/// exits.
#[derive(Debug)]
pub struct FramesOut {
    queue: Option<std::sync::mpsc::Sender<Vec<u8>>>,
    /// Disconnected when the writer thread ends.
    done: std::sync::mpsc::Receiver<()>,
}

impl FramesOut {
    /// `queue` to the writer thread, which holds `done`'s sender until it
    /// ends.
    pub fn new(
        queue: std::sync::mpsc::Sender<Vec<u8>>,
        done: std::sync::mpsc::Receiver<()>,
    ) -> FramesOut {
        FramesOut {
            queue: Some(queue),
            done,
        }
    }

    /// Queues `bytes` for the writer; `Err` once the writer has ended.
    pub fn send(&self, bytes: Vec<u8>) -> Result<(), std::sync::mpsc::SendError<Vec<u8>>> {
        match &self.queue {
            Some(q) => q.send(bytes),
            None => Err(std::sync::mpsc::SendError(bytes)),
        }
    }
}

impl Drop for FramesOut {
    fn drop(&mut self) {
        drop(self.queue.take());
        let _ = self.done.recv_timeout(FLUSH_WAIT);
    }
}

/// The link to the router.
#[derive(Debug)]
pub enum Io {
    /// One message per datagram; datagrams from other addresses are ignored.
    Udp {
        socket: UdpSocket,
        router: SocketAddr,
    },
    /// Messages framed and deframed elsewhere (a serial link's threads),
    /// as encoded bytes, with news of the port failing and returning.
    Frames {
        incoming: mpsc::Receiver<FramesIn>,
        outgoing: FramesOut,
    },
    /// Several links (each `Udp` or `Frames`), in order of preference,
    /// with failover between them ([`LinkChoice`]).
    Failover {
        links: Vec<Io>,
        choice: LinkChoice,
        /// Links whose receiving side has ended.
        closed: Vec<bool>,
    },
}

/// What a framed link's threads hand the loop.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FramesIn {
    /// A received message's bytes.
    Frame(Vec<u8>),
    /// The port failed, or could not be opened: the sentence reporting the
    /// outage (once per outage; the threads keep reopening it).
    Down(String),
    /// The port was opened again after an outage: the sentence saying so.
    Up(String),
}

/// What paces the control periods.
#[derive(Debug)]
pub enum Ticker {
    /// The agent's own interval.
    Own(Duration),
    /// A tick shared by many agents (a simulated fleet): the value is the
    /// tick's time since the common origin.
    Shared(watch::Receiver<Duration>),
}

enum Incoming {
    /// A message, and the link it came on (0 for a single link).
    Bytes(Vec<u8>, usize),
    /// A link's port failed (`Warn`) or returned (`Info`), and which link
    /// (0 for a single link): the station is told in a notice, on whichever
    /// link carries it.
    News(mech_proto::Level, String, usize),
    Ignored,
    Closed,
}

thread_local! {
    /// One receive buffer per runtime thread instead of one per agent: a
    /// fleet of hundreds of agents would otherwise hold 60 kB each.
    static RECV_BUF: RefCell<Vec<u8>> = RefCell::new(vec![0; mech_proto::MAX_MESSAGE_LEN + 1]);
}

impl Io {
    async fn recv(&mut self) -> Incoming {
        match self {
            Io::Failover { links, closed, .. } => recv_any(links, closed).await,
            single => single.recv_one().await,
        }
    }

    /// Receives on a single link (`Udp` or `Frames`).
    async fn recv_one(&mut self) -> Incoming {
        match self {
            Io::Udp { socket, router } => loop {
                if socket.readable().await.is_err() {
                    return Incoming::Closed;
                }
                let got = RECV_BUF.with(|b| {
                    let mut b = b.borrow_mut();
                    match socket.try_recv_from(&mut b) {
                        Ok((n, from)) if from == *router => {
                            Some(Incoming::Bytes(b[..n].to_vec(), 0))
                        }
                        Ok(_) => Some(Incoming::Ignored),
                        Err(e) if e.kind() == std::io::ErrorKind::WouldBlock => None,
                        // ICMP port unreachable while the router is down.
                        Err(_) => Some(Incoming::Ignored),
                    }
                });
                if let Some(got) = got {
                    return got;
                }
            },
            Io::Frames { incoming, .. } => match incoming.recv().await {
                Some(FramesIn::Frame(bytes)) => Incoming::Bytes(bytes, 0),
                Some(FramesIn::Down(text)) => Incoming::News(mech_proto::Level::Warn, text, 0),
                Some(FramesIn::Up(text)) => Incoming::News(mech_proto::Level::Info, text, 0),
                None => Incoming::Closed,
            },
            Io::Failover { .. } => Incoming::Closed,
        }
    }

    async fn send(&mut self, bytes: &[u8]) {
        match self {
            Io::Udp { socket, router } => {
                if let Err(e) = socket.send_to(bytes, *router).await {
                    tracing::debug!(error = %e, "send to router");
                }
            }
            Io::Frames { outgoing, .. } => {
                let _ = outgoing.send(bytes.to_vec());
            }
            Io::Failover { .. } => {
                tracing::warn!("a message for several links needs its link chosen");
            }
        }
    }
}

/// One link's receive in progress.
type Receiving<'a> = std::pin::Pin<Box<dyn std::future::Future<Output = Incoming> + Send + 'a>>;

/// The next message on any of `links` (and which); a link whose
/// receiving side ended is marked in `closed` and no longer waited on.
async fn recv_any(links: &mut [Io], closed: &mut [bool]) -> Incoming {
    use std::future::Future;
    use std::pin::Pin;
    use std::task::Poll;
    loop {
        if closed.iter().all(|c| *c) {
            return Incoming::Closed;
        }
        let mut waits: Vec<(usize, Receiving<'_>)> = links
            .iter_mut()
            .enumerate()
            .filter(|(i, _)| !closed[*i])
            .map(|(i, l)| {
                (
                    i,
                    Box::pin(l.recv_one()) as Pin<Box<dyn Future<Output = _> + Send>>,
                )
            })
            .collect();
        let (i, got) = std::future::poll_fn(|cx| {
            for (i, w) in waits.iter_mut() {
                if let Poll::Ready(got) = w.as_mut().poll(cx) {
                    return Poll::Ready((*i, got));
                }
            }
            Poll::Pending
        })
        .await;
        drop(waits);
        match got {
            Incoming::Bytes(b, _) => return Incoming::Bytes(b, i),
            Incoming::News(level, text, _) => return Incoming::News(level, text, i),
            Incoming::Ignored => return Incoming::Ignored,
            Incoming::Closed => {
                tracing::warn!(link = i, "a link closed; carrying on with the others");
                closed[i] = true;
            }
        }
    }
}

async fn next_tick(
    own: &mut Option<tokio::time::Interval>,
    shared: &mut Option<watch::Receiver<Duration>>,
    origin: Instant,
) -> Option<Duration> {
    if let Some(i) = own {
        let at = i.tick().await;
        return Some(at.saturating_duration_since(origin));
    }
    if let Some(rx) = shared {
        return match rx.changed().await {
            Ok(()) => Some(*rx.borrow_and_update()),
            Err(_) => None,
        };
    }
    std::future::pending().await
}

/// Runs `vehicle` until `shutdown` turns true (or its sender is dropped),
/// then zeroes its actuators and sends `Bye`; returns the agent's
/// counters. `origin` is agent time zero.
pub async fn drive<V: Vehicle>(
    mut vehicle: V,
    mut io: Io,
    ticker: Ticker,
    origin: Instant,
    mut shutdown: watch::Receiver<bool>,
) -> Counters {
    let (mut own, mut shared) = match ticker {
        Ticker::Own(period) => {
            let mut i = tokio::time::interval_at(origin, period);
            i.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            (Some(i), None)
        }
        Ticker::Shared(rx) => (None, Some(rx)),
    };
    let mut buf = Vec::with_capacity(512);
    loop {
        let out = tokio::select! {
            changed = shutdown.changed() => {
                if changed.is_err() || *shutdown.borrow() { break; }
                continue;
            }
            now = next_tick(&mut own, &mut shared, origin) => match now {
                Some(now) => {
                    let out = vehicle.tick(now);
                    probe(&mut vehicle, &mut io, now, &mut buf).await;
                    out
                }
                None => break,
            },
            incoming = io.recv() => {
                let now = origin.elapsed();
                match incoming {
                    Incoming::Bytes(b, link) => {
                        if let Io::Failover { choice, .. } = &mut io
                            && from_router(&b)
                        {
                            choice.heard(link, now);
                        }
                        vehicle.handle_bytes(&b, now)
                    }
                    Incoming::News(level, text, link) => {
                        // A link whose port failed is not heard from the
                        // router any more: the notice saying so (and all
                        // that follows) goes on the others at once.
                        if let Io::Failover { choice, .. } = &mut io {
                            if level == mech_proto::Level::Warn {
                                choice.down(link);
                            } else {
                                choice.up(link);
                            }
                        }
                        let code = mech_proto::NoticeCode::Text;
                        vec![vehicle.agent_mut().notice(level, code, &text, now)]
                    }
                    Incoming::Ignored => continue,
                    Incoming::Closed => break,
                }
            }
        };
        let now = origin.elapsed();
        for env in out {
            send(&mut vehicle, &mut io, env, now, &mut buf).await;
        }
    }
    let now = origin.elapsed();
    let bye = vehicle.stop(now);
    send(&mut vehicle, &mut io, bye, now, &mut buf).await;
    vehicle.counters()
}

/// Whether a message came from the router: on a shared radio a robot also
/// hears the other robots, whose messages are addressed to the router and
/// say nothing about whether the router is there.
fn from_router(bytes: &[u8]) -> bool {
    mech_proto::peek(bytes).is_ok_and(|h| h.destination != mech_proto::ROUTER)
}

/// With several links, a heartbeat on each link not in use, when due.
async fn probe<V: Vehicle>(vehicle: &mut V, io: &mut Io, now: Duration, buf: &mut Vec<u8>) {
    let Io::Failover { links, choice, .. } = io else {
        return;
    };
    for i in choice.probes_due(now) {
        let mut hb = vehicle.heartbeat(now);
        vehicle.number(&mut hb);
        buf.clear();
        if vehicle.encode(&hb, i as u8, buf).is_ok() {
            links[i].send(buf).await;
        }
    }
}

/// Numbers, encodes (and signs) one message and sends it to the router:
/// on the one link, or with several on the link in use (every link when
/// none is), each copy signed for its link, never on a link whose port is
/// down. Telemetry goes only on links whose rate cap allows it now; a
/// message no link carries is not numbered, so the router never counts it
/// as lost.
async fn send<V: Vehicle>(
    vehicle: &mut V,
    io: &mut Io,
    mut env: Envelope,
    now: Duration,
    buf: &mut Vec<u8>,
) {
    let Io::Failover { links, choice, .. } = io else {
        vehicle.number(&mut env);
        buf.clear();
        match vehicle.encode(&env, 0, buf) {
            Ok(()) => io.send(buf).await,
            Err(e) => tracing::warn!(error = %e, "cannot encode"),
        }
        return;
    };
    let telemetry = matches!(env.body, mech_proto::Body::Telemetry(_));
    let usable: Vec<usize> = choice.targets(now).filter(|&i| choice.usable(i)).collect();
    let on: Vec<usize> = usable
        .into_iter()
        .filter(|&i| !telemetry || choice.telemetry_allowed(i, now))
        .collect();
    if on.is_empty() {
        return;
    }
    vehicle.number(&mut env);
    for i in on {
        buf.clear();
        match vehicle.encode(&env, i as u8, buf) {
            Ok(()) => links[i].send(buf).await,
            Err(e) => tracing::warn!(error = %e, "cannot encode"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hal::{ErrorKind, HalError};
    use crate::machine::AgentSettings;
    use crate::platform::PlatformSpec;
    use mech_proto::{Body, Command, FailsafeState, Header, Health, Pose, Route, Twist, Welcome};

    /// Actuators that record outputs and fail while `broken`.
    #[derive(Debug, Default)]
    struct Bench {
        written: std::sync::Arc<std::sync::Mutex<Vec<Vec<f64>>>>,
        broken: std::sync::Arc<std::sync::atomic::AtomicBool>,
    }

    impl Actuators for Bench {
        fn set_outputs(&mut self, outputs: &[f64]) -> Result<(), HalError> {
            self.written.lock().unwrap().push(outputs.to_vec());
            if self.broken.load(std::sync::atomic::Ordering::SeqCst) {
                Err(HalError::new(ErrorKind::Io, "bus error"))
            } else {
                Ok(())
            }
        }
    }

    fn msg(channel: &str, body: Body) -> Envelope {
        Envelope::new(
            Header {
                destination: "r1".into(),
                channel: channel.into(),
                ..Header::default()
            },
            body,
        )
    }

    /// The router's Welcome, routing `r1` to `channel`.
    fn welcome(channel: &str) -> Envelope {
        let route = Route {
            robot: "r1".into(),
            channel: channel.into(),
            epoch: 1,
        };
        let welcome = Welcome {
            robot_id: 1,
            route,
            router_version: "t".into(),
        };
        msg("", Body::Welcome(welcome))
    }

    /// Encoders that count `per_read` edges on each wheel per reading, or
    /// fail while `broken`.
    #[derive(Debug, Default)]
    struct Odometer {
        edges: i64,
        broken: bool,
    }

    impl crate::hal::WheelEncoders for Odometer {
        fn read_all(&mut self, now: Duration) -> Result<Vec<crate::hal::EdgeCount>, HalError> {
            if self.broken {
                return Err(HalError::new(ErrorKind::NotConnected, "cable"));
            }
            self.edges += 10;
            let count = crate::hal::EdgeCount {
                edges: self.edges,
                last_edge: Some(now),
            };
            Ok(vec![count; 2])
        }
    }

    #[test]
    fn hardware_vehicle_reads_its_encoders_each_period() {
        let mut settings = AgentSettings::new("r1");
        settings.wheels = Some(crate::wheels::WheelSettings {
            counting: crate::hal::Counting::Quadrature,
            counts_per_revolution: 1000.0,
            wheel_radius: 0.1 / std::f64::consts::TAU,
            speed_loop: None,
            stall: crate::wheels::StallSettings::default(),
        });
        let agent = Agent::new(settings, PlatformSpec::diff_drive().build(), 0);
        let mut v = HardwareVehicle {
            agent,
            actuators: Box::new(Bench::default()),
            positions: None,
            encoders: Some(Box::new(Odometer::default())),
        };
        let ms = Duration::from_millis;
        v.tick(ms(0));
        v.tick(ms(20));
        // 10 edges of 0.1 mm in 20 ms on both wheels: 0.05 m/s forward.
        let t = v.agent.telemetry(ms(20));
        assert_eq!(t.velocity_source, mech_proto::VelocitySource::Measured);
        assert!((t.velocity.vx - 0.05).abs() < 1e-9, "{:?}", t.velocity);
        v.encoders = Some(Box::new(Odometer {
            edges: 0,
            broken: true,
        }));
        let out = v.tick(ms(40));
        assert!(
            out.iter()
                .any(|e| matches!(&e.body, Body::Notice(n) if n.text.contains("encoders")))
        );
        // No fresh reading for long: back to the commanded velocity.
        let t = v.agent.telemetry(ms(1000));
        assert_eq!(t.velocity_source, mech_proto::VelocitySource::Commanded);
    }

    #[test]
    fn hardware_vehicle_writes_outputs_feeds_positions_and_reports_faults() {
        let bench = Bench::default();
        let (written, broken) = (bench.written.clone(), bench.broken.clone());
        let (tx, rx) = std::sync::mpsc::channel();
        let agent = Agent::new(
            AgentSettings::new("r1"),
            PlatformSpec::diff_drive().build(),
            0,
        );
        let mut v = HardwareVehicle {
            agent,
            actuators: Box::new(bench),
            positions: Some(rx),
            encoders: None,
        };
        let ms = Duration::from_millis;
        v.handle(welcome("joy/0"), ms(0));
        tx.send(Ok(PositionSample {
            pose: Pose {
                x: 1.0,
                ..Pose::default()
            },
            stamp: ms(0),
            quality: 1.0,
            has_heading: true,
        }))
        .unwrap();
        let forward = Body::Command(Command::Twist(Twist {
            vx: 0.2,
            ..Twist::default()
        }));
        v.handle(msg("joy/0", forward), ms(10));
        v.tick(ms(20));
        assert_eq!(v.agent.estimate().map(|e| e.pose.x), Some(1.0));
        assert!(
            written
                .lock()
                .unwrap()
                .last()
                .unwrap()
                .iter()
                .all(|u| *u > 0.0)
        );

        tx.send(Err("tag unplugged".into())).unwrap();
        let out = v.tick(ms(40));
        assert!(
            out.iter()
                .any(|e| matches!(&e.body, Body::Notice(n) if n.text.contains("tag unplugged")))
        );
        assert_eq!(v.agent.telemetry(ms(40)).health, Health::Fault);

        broken.store(true, std::sync::atomic::Ordering::SeqCst);
        v.tick(ms(60));
        let last = written.lock().unwrap().last().unwrap().clone();
        assert_eq!(
            last,
            vec![0.0, 0.0],
            "zeroes what still answers after a write error"
        );
        assert_eq!(v.agent.failsafe_state(ms(60)), FailsafeState::Fault);

        let bye = v.stop(ms(80));
        assert!(matches!(bye.body, Body::Bye(_)));
        assert_eq!(written.lock().unwrap().last().unwrap(), &vec![0.0, 0.0]);
    }

    /// A telemetry sample a link's rate cap skips takes no number, so the
    /// router sees no gap: over a radio capped at 5 Hz, twenty samples a
    /// second go out as five, numbered one after another.
    #[tokio::test]
    async fn telemetry_a_capped_link_skips_is_not_numbered() {
        let router = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        router
            .set_read_timeout(Some(Duration::from_secs(5)))
            .unwrap();
        let socket = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let ms = Duration::from_millis;
        let mut io = Io::Failover {
            links: vec![Io::Udp {
                socket,
                router: router.local_addr().unwrap(),
            }],
            choice: LinkChoice::new(vec![Some(ms(200))], ms(600), ms(250)),
            closed: vec![false],
        };
        let agent = Agent::new(
            AgentSettings::new("r1"),
            PlatformSpec::diff_drive().build(),
            0,
        );
        let mut v = HardwareVehicle {
            agent,
            actuators: Box::new(Bench::default()),
            positions: None,
            encoders: None,
        };
        let mut buf = Vec::new();
        for i in 0..=20u64 {
            let body = Body::Telemetry(v.agent.telemetry(ms(50 * i)));
            let env = Envelope::new(Header::default(), body);
            send(&mut v, &mut io, env, ms(50 * i), &mut buf).await;
        }
        let bye = v.stop(ms(1_100));
        send(&mut v, &mut io, bye, ms(1_100), &mut buf).await;
        let mut seqs = Vec::new();
        let mut datagram = [0u8; 2048];
        loop {
            let n = router.recv(&mut datagram).unwrap();
            let env = mech_proto::decode(&datagram[..n]).unwrap();
            seqs.push(env.header.seq);
            if matches!(env.body, Body::Bye(_)) {
                break;
            }
        }
        assert_eq!(seqs, [1, 2, 3, 4, 5, 6, 7], "5 Hz of 20: no gaps");
    }
}
