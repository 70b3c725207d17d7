//! The router: the heart of the ground station. It registers agents, keeps
//! the routing table (robot -> the one channel it obeys), forwards each
//! command only to robots routed to its channel, fans telemetry out to every
//! subscriber, and delivers missions, route changes and e-stops reliably
//! (repeating them until acknowledged).
//!
//! Layers, as in mini-redis: [`tables`] decides what to do with a message
//! (synchronous, under one short lock), [`net`] owns the sockets and timers
//! (a UDP receive loop per worker, a task per TCP peer, one timer task), and
//! [`RouterHandle`] is the API the rest of the GCS uses. In-process
//! publishers ([`Publisher`]) go through exactly the same decision code as
//! UDP and TCP peers.

mod batch;
mod bus;
mod config;
mod net;
mod radio;
mod rate;
mod tables;

use std::collections::HashMap;
use std::net::SocketAddr;
use std::os::fd::{AsRawFd, RawFd};
use std::sync::atomic::AtomicU64;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use mech_proto::{Body, Command, Envelope, FleetCommand, Header, Mission, RobotCommand};
use nix::sys::socket::{MsgFlags, SockaddrStorage, sendto};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;

pub use bus::Subscription;
pub use config::{RouterConfig, SerialEndpoint};
pub use tables::Delivery;
pub(crate) use tables::Peer;
pub use tables::tap::OperatorRecord;
pub(crate) use tables::tap::{Tap, Tapped, TappedMessage};

use crate::auth::{Identity, Keyring, Rejection, Role, Security};
use crate::counters::{ChannelStatus, Counters, DropReason, Rejections};
use crate::event::{Event, EventSink};
use crate::sync::lock;
use batch::{RecvBatch, SendBatch};
use bus::EventBus;
use mech_proto::auth::Tag;
use radio::RadioQueue;
use tables::{Outbox, Tables};

/// Why a router call failed.
#[derive(Debug, thiserror::Error)]
pub enum RouterError {
    #[error("cannot bind the {what} endpoint {addr}: {source}")]
    Bind {
        what: &'static str,
        addr: SocketAddr,
        source: std::io::Error,
    },
    #[error("no robot named {0:?} is registered")]
    UnknownRobot(String),
    #[error("cannot encode the message: {0}")]
    Encode(#[from] mech_proto::Error),
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error("cannot open the radio on {port}: {message}")]
    Serial { port: String, message: String },
}

/// State shared by the router's tasks and handles.
#[derive(Debug)]
struct Shared {
    tables: Mutex<Tables>,
    bus: EventBus,
    /// The socket that the timers, TCP peers and in-process publishers send
    /// from (the first of the UDP workers' group; every one has the same
    /// address).
    udp: Arc<std::net::UdpSocket>,
    udp_addr: SocketAddr,
    tcp_addr: Option<SocketAddr>,
    /// Outgoing frame queues of the TCP peers, by connection number.
    tcp_peers: Mutex<HashMap<u64, mpsc::Sender<Vec<u8>>>>,
    /// Outgoing queues of the serial radios, by place in `router.serial`.
    radios: Vec<Arc<RadioQueue>>,
    next_conn: AtomicU64,
    subscriber_queue: usize,
    /// Set once by [`Router::shutdown`]: every task watches it and stops,
    /// and nothing is routed any more, from any peer or handle.
    stop: watch::Sender<bool>,
    /// The router's sender name.
    name: String,
}

impl Shared {
    /// Runs one received message through the tables, then sends what they
    /// decided and publishes the resulting events.
    async fn dispatch(
        &self,
        bytes: &[u8],
        from: Peer,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        if self.stopped() {
            return Delivery::Dropped(DropReason::Stopped);
        }
        let delivery = self.decide(bytes, from, Instant::now(), out, events);
        self.flush(bytes, out).await;
        delivery
    }

    /// Whether the router has been shut down.
    fn stopped(&self) -> bool {
        *self.stop.borrow()
    }

    /// The synchronous half of [`Shared::dispatch`]: the tables' decision and
    /// its events, leaving the sends in `out`.
    fn decide(
        &self,
        bytes: &[u8],
        from: Peer,
        now: Instant,
        out: &mut Outbox,
        events: &mut Vec<Event>,
    ) -> Delivery {
        let mut tables = lock(&self.tables);
        let delivery = tables.handle(bytes, from, now, out, events);
        // Emitted under the table lock, so the fleet model sees events
        // in the order the tables made them (a mission is "sent" before
        // its acknowledgement, whichever worker handles the ack).
        for e in events.drain(..) {
            self.emit(&tables, e);
        }
        delivery
    }

    /// Emits an event to the fleet model and subscribers and offers it to
    /// the recorder's tap; called holding the tables (so the recording has
    /// messages and events in the order the tables made them).
    fn emit(&self, tables: &Tables, e: Event) {
        let stamped = self.bus.emit(e);
        if let Some(tap) = &tables.tap {
            tap.offer(Tapped::Event(stamped));
        }
    }

    /// Sends the outbox: `raw` targets get `raw`, `owned` ones their own
    /// bytes. The outbox keeps its allocations for the next message.
    async fn flush(&self, raw: &[u8], out: &mut Outbox) {
        if out.is_empty() {
            return;
        }
        if self.stopped() {
            out.raw.clear();
            out.owned.clear();
            return;
        }
        for i in 0..out.raw.len() {
            self.send(out.raw[i], raw).await;
        }
        out.raw.clear();
        if !out.owned.is_empty() {
            for (peer, bytes) in std::mem::take(&mut out.owned) {
                self.send(peer, &bytes).await;
            }
        }
    }

    async fn send(&self, peer: Peer, bytes: &[u8]) {
        let Peer::Udp(addr) = peer else {
            return self.send_other(peer, bytes);
        };
        // The worker threads own blocking sockets; this path must not block
        // a tokio thread, so it sends without waiting and, in the rare case
        // of a full buffer, tries again after yielding.
        let to = SockaddrStorage::from(addr);
        let fd = self.udp.as_raw_fd();
        for _ in 0..FULL_BUFFER_TRIES {
            match sendto(fd, bytes, &to, MsgFlags::MSG_DONTWAIT) {
                Ok(_) => return,
                Err(nix::errno::Errno::EAGAIN) => tokio::task::yield_now().await,
                Err(e) => {
                    tracing::debug!(%addr, error = %e, "UDP send failed");
                    break;
                }
            }
        }
        lock(&self.tables).count_send_failure(false);
    }

    /// Sends to a peer that is not a UDP address: a TCP peer gets a
    /// length-prefixed frame through its bounded queue (a full queue drops
    /// and counts, never waits), a radio gets the message in its priority
    /// queue; in-process publishers get nothing.
    fn send_other(&self, peer: Peer, bytes: &[u8]) {
        if let Peer::Serial(port) = peer {
            if let Some(q) = self.radios.get(usize::from(port)) {
                q.push(bytes);
            }
            return;
        }
        let Peer::Tcp(conn) = peer else { return };
        let tx = lock(&self.tcp_peers).get(&conn).cloned();
        let Some(tx) = tx else { return };
        let mut frame = Vec::with_capacity(bytes.len() + 4);
        frame.extend_from_slice(&(bytes.len() as u32).to_be_bytes());
        frame.extend_from_slice(bytes);
        if tx.try_send(frame).is_err() {
            lock(&self.tables).count_send_failure(true);
        }
    }

    /// Decides a batch of received datagrams under one hold of the tables'
    /// lock, in the order they arrived, emitting their events in that
    /// order; what to send is left in `decided`.
    fn decide_batch(&self, batch: &RecvBatch, n: usize, decided: &mut Decided) {
        decided.clear();
        if self.stopped() {
            return;
        }
        let now = Instant::now();
        let mut tables = lock(&self.tables);
        for i in 0..n {
            let (bytes, from) = batch.datagram(i);
            tables.handle(
                bytes,
                Peer::Udp(from),
                now,
                &mut decided.out,
                &mut decided.events,
            );
            for peer in decided.out.raw.drain(..) {
                decided.sends.push((peer, Payload::Received(i)));
            }
            for (peer, bytes) in decided.out.owned.drain(..) {
                decided
                    .sends
                    .push((peer, Payload::Owned(decided.owned.len())));
                decided.owned.push(bytes);
            }
            for e in decided.events.drain(..) {
                self.emit(&tables, e);
            }
        }
    }

    /// Sends what a batch decided, in order, from a worker's thread: UDP
    /// datagrams from its socket `fd` in batches (waiting for room when the
    /// socket's buffer is full: never dropped or reordered), frames to TCP
    /// peers through their queues.
    fn send_decided(
        &self,
        fd: RawFd,
        sender: &mut SendBatch,
        batch: &RecvBatch,
        decided: &mut Decided,
    ) {
        if decided.sends.is_empty() || self.stopped() {
            return;
        }
        let bytes = |p: &Payload| match *p {
            Payload::Received(i) => batch.datagram(i).0,
            Payload::Owned(i) => decided.owned[i].as_slice(),
        };
        let mut udp: Vec<(SocketAddr, &[u8])> = Vec::with_capacity(decided.sends.len());
        for (peer, payload) in &decided.sends {
            match peer {
                Peer::Udp(addr) => udp.push((*addr, bytes(payload))),
                other => self.send_other(*other, bytes(payload)),
            }
        }
        let sent = sender.send(fd, &udp, MsgFlags::empty());
        if sent.failed > 0 {
            let mut tables = lock(&self.tables);
            for _ in 0..sent.failed {
                tables.count_send_failure(false);
            }
        }
    }

    /// Decides one message received on a radio, from the port's reader
    /// thread, and sends what was decided without waiting (a full UDP
    /// buffer is retried briefly, then counted).
    fn decide_frame(&self, bytes: &[u8], from: Peer) {
        if self.stopped() {
            return;
        }
        let mut out = Outbox::default();
        let mut events = Vec::new();
        self.decide(bytes, from, Instant::now(), &mut out, &mut events);
        for peer in out.raw.drain(..) {
            self.send_now(peer, bytes);
        }
        for (peer, b) in std::mem::take(&mut out.owned) {
            self.send_now(peer, &b);
        }
    }

    /// Sends from a plain thread: UDP without blocking for long, others
    /// through their queues.
    fn send_now(&self, peer: Peer, bytes: &[u8]) {
        let Peer::Udp(addr) = peer else {
            return self.send_other(peer, bytes);
        };
        let to = SockaddrStorage::from(addr);
        for _ in 0..FULL_BUFFER_TRIES {
            match sendto(self.udp.as_raw_fd(), bytes, &to, MsgFlags::MSG_DONTWAIT) {
                Ok(_) => return,
                Err(nix::errno::Errno::EAGAIN) => std::thread::yield_now(),
                Err(_) => break,
            }
        }
        lock(&self.tables).count_send_failure(false);
    }

    /// Counts a frame from a radio that failed its checksum or framing.
    fn count_bad_frame(&self, from: Peer, error: String) {
        let mut events = Vec::new();
        let mut tables = lock(&self.tables);
        tables.count_bad(from, error, &mut events);
        for e in events {
            self.bus.emit(e);
        }
    }

    /// Runs a table operation that may produce messages and events.
    async fn apply<R>(
        &self,
        f: impl FnOnce(&mut Tables, Instant, &mut Outbox, &mut Vec<Event>) -> R,
    ) -> R {
        let mut out = Outbox::default();
        let mut events = Vec::new();
        let r = {
            let mut tables = lock(&self.tables);
            let r = f(&mut tables, Instant::now(), &mut out, &mut events);
            for e in events {
                self.emit(&tables, e);
            }
            r
        };
        self.flush(&[], &mut out).await;
        r
    }
}

/// Times a send from a tokio task retries a full socket buffer before the
/// datagram counts as a send failure.
const FULL_BUFFER_TRIES: usize = 1000;

/// What a UDP worker's batch decided to send: each target with the bytes it
/// gets, either a received datagram passed on unchanged or a message the
/// tables made. Kept between batches so its allocations are reused.
#[derive(Debug, Default)]
pub(super) struct Decided {
    sends: Vec<(Peer, Payload)>,
    owned: Vec<Vec<u8>>,
    out: Outbox,
    events: Vec<Event>,
}

impl Decided {
    fn clear(&mut self) {
        self.sends.clear();
        self.owned.clear();
    }
}

#[derive(Debug, Clone, Copy)]
enum Payload {
    /// Datagram `i` of the batch, as received.
    Received(usize),
    /// `Decided::owned[i]`.
    Owned(usize),
}

/// A running router: its tasks and a handle to it. Dropping it without
/// [`Router::shutdown`] leaves the tasks running until the runtime stops.
#[derive(Debug)]
pub struct Router {
    handle: RouterHandle,
    tasks: Vec<JoinHandle<()>>,
    /// The UDP workers' threads and their sockets (shut down for reading
    /// to wake them when the router stops).
    workers: Vec<(std::thread::JoinHandle<()>, Arc<std::net::UdpSocket>)>,
    /// The radios' reader and writer threads.
    radio_threads: Vec<std::thread::JoinHandle<()>>,
}

impl Router {
    /// Binds the UDP (and, if configured, TCP) endpoints and starts routing.
    /// Events go to `sink` (the fleet model) first, then to subscribers.
    pub async fn start(
        config: RouterConfig,
        auth: Option<Keyring>,
        sink: Arc<dyn EventSink>,
    ) -> Result<Router, RouterError> {
        let (mut udp, tcp) = bind(&config).await?;
        let udp_addr = local_addr("UDP", config.udp, udp[0].local_addr())?;
        let tcp_addr = match (&tcp, config.tcp) {
            (Some(l), Some(asked)) => Some(local_addr("TCP", asked, l.local_addr())?),
            _ => None,
        };
        let workers = config.udp_workers;
        let poll = config.udp_poll;
        let tick = config.tick;
        let name = config.name.clone();
        let serial = config.serial.clone();
        let ports = open_radios(&serial)?;
        let shared = Arc::new(Shared {
            radios: serial.iter().map(|_| Arc::default()).collect(),
            subscriber_queue: config.subscriber_queue,
            tables: Mutex::new(Tables::new(config, auth)),
            bus: EventBus::new(Instant::now(), sink),
            udp: udp[0].clone(),
            udp_addr,
            tcp_addr,
            tcp_peers: Mutex::new(HashMap::new()),
            next_conn: AtomicU64::new(1),
            stop: watch::Sender::new(false),
            name,
        });
        tracing::info!(udp = %udp_addr, tcp = ?tcp_addr, "router started");
        shared.bus.emit(Event::Listening {
            udp: udp_addr,
            tcp: tcp_addr,
        });
        let mut tasks = Vec::new();
        debug_assert_eq!(udp.len(), workers);
        let mut threads = Vec::new();
        for (i, socket) in udp.drain(..).enumerate() {
            let (s, sock) = (shared.clone(), socket.clone());
            let thread = std::thread::Builder::new()
                .name(format!("mech-udp-{i}"))
                .spawn(move || net::udp_worker(s, sock, poll))
                .map_err(|source| RouterError::Bind {
                    what: "UDP worker",
                    addr: udp_addr,
                    source,
                })?;
            threads.push((thread, socket));
        }
        let radio_threads = start_radios(&shared, &serial, ports)?;
        tasks.push(tokio::spawn(net::timers(shared.clone(), tick)));
        if let Some(listener) = tcp {
            tasks.push(tokio::spawn(net::tcp_accept(shared.clone(), listener)));
        }
        Ok(Router {
            handle: RouterHandle { shared },
            tasks,
            workers: threads,
            radio_threads,
        })
    }

    pub fn handle(&self) -> RouterHandle {
        self.handle.clone()
    }

    /// Stops routing and waits until every router task has ended: the UDP
    /// workers, the timers, the TCP acceptor and every TCP peer (their
    /// connections are closed), then closes subscriptions. From then on
    /// nothing is forwarded, from any peer or handle. Every registered robot
    /// is told first (`Bye`), so its failsafe stops it at once rather than
    /// after its router timeout.
    pub async fn shutdown(self) {
        let shared = &self.handle.shared;
        shared.apply(|t, _, out, _| t.farewell(out)).await;
        shared.stop.send_replace(true);
        for (thread, socket) in self.workers {
            // Wakes the worker out of its receive at once.
            let _ =
                nix::sys::socket::shutdown(socket.as_raw_fd(), nix::sys::socket::Shutdown::Read);
            if tokio::task::spawn_blocking(move || thread.join())
                .await
                .is_err()
            {
                tracing::warn!("a UDP worker ended abnormally");
            }
        }
        for t in self.tasks {
            if let Err(e) = t.await {
                tracing::warn!(error = %e, "a router task ended abnormally");
            }
        }
        for q in &shared.radios {
            q.close();
        }
        for thread in self.radio_threads {
            // Readers notice the stop within their port's read timeout.
            if tokio::task::spawn_blocking(move || thread.join())
                .await
                .is_err()
            {
                tracing::warn!("a radio thread ended abnormally");
            }
        }
        lock(&shared.tcp_peers).clear();
        shared.bus.close();
        tracing::info!("router stopped");
    }
}

/// A radio's port, opened: the reader's and the writer's handles.
type RadioPort = (
    Box<dyn std::io::Read + Send>,
    Box<dyn std::io::Write + Send>,
);

/// Opens every configured radio (before anything starts, so a missing
/// device is a clear error at startup).
#[cfg(feature = "serial")]
fn open_radios(serial: &[SerialEndpoint]) -> Result<Vec<RadioPort>, RouterError> {
    serial
        .iter()
        .map(|s| {
            let err = |e: serialport::Error| RouterError::Serial {
                port: s.port.clone(),
                message: e.to_string(),
            };
            let port = serialport::new(&s.port, s.baud)
                .timeout(Duration::from_millis(50))
                .open()
                .map_err(err)?;
            let writer = port.try_clone().map_err(err)?;
            Ok((
                Box::new(port) as Box<dyn std::io::Read + Send>,
                Box::new(writer) as _,
            ))
        })
        .collect()
}

#[cfg(not(feature = "serial"))]
fn open_radios(serial: &[SerialEndpoint]) -> Result<Vec<RadioPort>, RouterError> {
    match serial.first() {
        None => Ok(Vec::new()),
        Some(s) => Err(RouterError::Serial {
            port: s.port.clone(),
            message: "this build has no serial support (feature `serial`)".into(),
        }),
    }
}

/// Starts a reader and a writer thread per radio.
fn start_radios(
    shared: &Arc<Shared>,
    serial: &[SerialEndpoint],
    ports: Vec<RadioPort>,
) -> Result<Vec<std::thread::JoinHandle<()>>, RouterError> {
    let mut threads = Vec::new();
    for (i, ((read, write), s)) in ports.into_iter().zip(serial).enumerate() {
        let spawn_err = |source| RouterError::Serial {
            port: s.port.clone(),
            message: format!("cannot start its thread: {source}"),
        };
        let (sh, name) = (shared.clone(), s.port.clone());
        let index = i as u16;
        threads.push(
            std::thread::Builder::new()
                .name(format!("mech-radio-rx-{i}"))
                .spawn(move || radio::reader(sh, index, read, name))
                .map_err(spawn_err)?,
        );
        let (q, name, baud) = (shared.radios[i].clone(), s.port.clone(), s.baud);
        threads.push(
            std::thread::Builder::new()
                .name(format!("mech-radio-tx-{i}"))
                .spawn(move || radio::writer(q, write, baud, name))
                .map_err(spawn_err)?,
        );
        tracing::info!(port = %s.port, baud = s.baud, "radio open");
    }
    Ok(threads)
}

/// Binds the configured endpoints: one UDP socket per worker, all on the
/// same address (`SO_REUSEPORT`), and the TCP listener.
async fn bind(
    config: &RouterConfig,
) -> Result<
    (
        Vec<Arc<std::net::UdpSocket>>,
        Option<tokio::net::TcpListener>,
    ),
    RouterError,
> {
    let bind_err = |addr, source| RouterError::Bind {
        what: "UDP",
        addr,
        source,
    };
    // The group's sockets share their port with any socket that asks
    // (`SO_REUSEPORT`), a second station's included, which would then
    // receive part of this one's traffic. A plain socket binds only a free
    // port: if it cannot, another program (or station) has it. Asked for
    // port 0, the kernel would hand a socket of a new group a port an
    // existing group of the same user holds (such ports count as free to
    // share), so the port is picked by a plain socket too.
    let addr = {
        let probe = std::net::UdpSocket::bind(config.udp).map_err(|e| bind_err(config.udp, e))?;
        probe.local_addr().map_err(|e| bind_err(config.udp, e))?
    };
    let mut udp = Vec::with_capacity(config.udp_workers.max(1));
    for _ in 0..config.udp_workers.max(1) {
        let s = bind_udp(addr, config.socket_buffer).map_err(|e| bind_err(addr, e))?;
        udp.push(Arc::new(s));
    }
    let tcp = match config.tcp {
        Some(addr) => Some(
            tokio::net::TcpListener::bind(addr)
                .await
                .map_err(|source| RouterError::Bind {
                    what: "TCP",
                    addr,
                    source,
                })?,
        ),
        None => None,
    };
    Ok((udp, tcp))
}

/// The address an endpoint was bound to (the port, when 0 was asked for).
fn local_addr(
    what: &'static str,
    asked: SocketAddr,
    bound: std::io::Result<SocketAddr>,
) -> Result<SocketAddr, RouterError> {
    bound.map_err(|source| RouterError::Bind {
        what,
        addr: asked,
        source,
    })
}

/// Binds one of the router's UDP sockets, with `SO_REUSEPORT` (the kernel
/// spreads senders over the group, each sender always to the same socket)
/// and large kernel buffers (best effort: a smaller system limit is logged,
/// not fatal).
fn bind_udp(addr: SocketAddr, buffer: usize) -> std::io::Result<std::net::UdpSocket> {
    use socket2::{Domain, Protocol, Socket, Type};
    let socket = Socket::new(Domain::for_address(addr), Type::DGRAM, Some(Protocol::UDP))?;
    socket.set_reuse_port(true)?;
    if let Err(e) = socket.set_recv_buffer_size(buffer) {
        tracing::warn!(error = %e, buffer, "cannot enlarge the UDP receive buffer");
    }
    if let Err(e) = socket.set_send_buffer_size(buffer) {
        tracing::warn!(error = %e, buffer, "cannot enlarge the UDP send buffer");
    }
    // Blocking, read by its worker thread with no timeout (a timed wait
    // costs a timer per datagram); shutdown wakes it.
    socket.bind(&addr.into())?;
    Ok(socket.into())
}

/// One serial radio at the station, as [`RouterHandle::radios`] reports it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RadioStatus {
    pub port: String,
    pub baud: u32,
    /// Frames and bytes sent.
    pub frames: u64,
    pub bytes: u64,
    /// Messages replaced in the queue by a newer one (newest wins).
    pub replaced: u64,
    /// Messages dropped because the queue was full.
    pub dropped: u64,
    /// Messages waiting to be sent.
    pub waiting: usize,
}

/// A cheap, cloneable handle to a running router: publish, route, send
/// missions, e-stop, subscribe, and read channels and counters.
#[derive(Debug, Clone)]
pub struct RouterHandle {
    shared: Arc<Shared>,
}

impl RouterHandle {
    /// The bound UDP endpoint (useful when configured with port 0).
    pub fn udp_addr(&self) -> SocketAddr {
        self.shared.udp_addr
    }

    /// The bound TCP endpoint, if enabled.
    pub fn tcp_addr(&self) -> Option<SocketAddr> {
        self.shared.tcp_addr
    }

    /// An in-process publisher on `channel`, named `sender` (e.g. `gamepad`
    /// on `joy/0`). Its commands take the same routing path as UDP ones.
    pub fn publisher(&self, sender: &str, channel: &str) -> Publisher {
        Publisher {
            router: self.clone(),
            sender: sender.to_string(),
            channel: channel.to_string(),
            seq: 0,
        }
    }

    /// In-process publishers named `sender`, one per channel, made on first
    /// use.
    pub fn publishers(&self, sender: &str) -> Publishers {
        Publishers {
            router: self.clone(),
            sender: sender.to_string(),
            by_channel: HashMap::new(),
        }
    }

    /// Routes `robot` to `channel` (`None` = none). Takes effect for the very
    /// next message; the agent is told, repeatedly until it acknowledges.
    /// Returns the new route epoch.
    pub async fn set_route(&self, robot: &str, channel: Option<&str>) -> Result<u32, RouterError> {
        self.shared
            .apply(|t, now, out, ev| t.set_route(robot, channel, now, out, ev))
            .await
            .ok_or_else(|| RouterError::UnknownRobot(robot.to_string()))
    }

    /// Sends a mission to `robot` on `channel` from `sender`, with a fresh id
    /// (the id in `mission` is replaced). It is repeated until the robot
    /// acknowledges the id, or reported failed after `mission_give_up`.
    pub async fn send_mission(
        &self,
        sender: &str,
        robot: &str,
        channel: &str,
        mut mission: Mission,
    ) -> Result<u32, RouterError> {
        let known = lock(&self.shared.tables).knows_robot(robot);
        if !known {
            return Err(RouterError::UnknownRobot(robot.to_string()));
        }
        mission.id = lock(&self.shared.tables).mission_id();
        let id = mission.id;
        let env = envelope(sender, robot, channel, 0, Body::Mission(mission));
        let bytes = mech_proto::encode(&env)?;
        self.inject(&bytes).await;
        Ok(id)
    }

    /// Engages the e-stop on every robot (repeated until each acknowledges;
    /// robots registering later get it too). Returns its id.
    pub async fn estop(&self) -> u32 {
        self.shared
            .apply(|t, now, out, ev| t.start_estop(true, now, out, ev))
            .await
    }

    /// Explicitly releases the e-stop on every robot. Returns its id.
    pub async fn release(&self) -> u32 {
        self.shared
            .apply(|t, now, out, ev| t.start_estop(false, now, out, ev))
            .await
    }

    /// A subscription to router events. With `telemetry` it also gets every
    /// telemetry event (at the fleet's telemetry rate: size `capacity`
    /// accordingly) and each robot's link quality once a second. A full queue drops this subscriber's events only.
    pub fn subscribe(&self, capacity: usize, telemetry: bool) -> Subscription {
        self.shared.bus.subscribe(capacity, telemetry)
    }

    /// A subscription with the configured queue length.
    pub fn subscribe_default(&self, telemetry: bool) -> Subscription {
        self.shared
            .bus
            .subscribe(self.shared.subscriber_queue, telemetry)
    }

    /// Live channels with their publisher, rate and routed robots.
    pub fn channels(&self) -> Vec<ChannelStatus> {
        lock(&self.shared.tables).channel_status(Instant::now())
    }

    /// The router's sender name (agents check it on what they obey).
    pub fn name(&self) -> &str {
        &self.shared.name
    }

    /// Whether the router checks and signs messages (the authenticated
    /// control plane); `false` means anyone who reaches it can drive robots.
    pub fn authenticated(&self) -> bool {
        lock(&self.shared.tables).auth_on()
    }

    /// How exposed the router is: authenticated, unsigned on loopback only,
    /// or unauthenticated on the network.
    pub fn security(&self) -> Security {
        let loopback = self.shared.udp_addr.ip().is_loopback()
            && self.shared.tcp_addr.is_none_or(|a| a.ip().is_loopback());
        match (self.authenticated(), loopback) {
            (true, _) => Security::Authenticated,
            (false, true) => Security::LoopbackOnly,
            (false, false) => Security::Unauthenticated,
        }
    }

    /// Messages refused by the authenticated control plane, by reason.
    pub fn rejections(&self) -> Rejections {
        lock(&self.shared.tables).rejections()
    }

    /// Adds a key while running (simulated robots get theirs this way). Does
    /// nothing when the router runs unauthenticated.
    pub fn add_key(&self, identity: Identity) {
        lock(&self.shared.tables).add_key(identity);
    }

    /// Checks that `sender`, a name with a key in `[auth]`, may send `body`
    /// on `channel`: the gate for an in-process publisher that carries
    /// messages from beyond the station under its own name (a bridge to
    /// other stations), whose messages the router would otherwise take as
    /// the station operator's. Always `Ok` when the station runs
    /// unauthenticated. A refusal is counted and reported, as the gate's.
    pub fn permit_as(&self, sender: &str, body: &Body, channel: &str) -> Result<(), Rejection> {
        self.decide_now(|t, events| t.permit_named(sender, body, channel, events))
    }

    /// Checks a request signed with a listed key outside the message
    /// protocol (a route request from another station, received from
    /// `source`): `tag` must be a fresh tag over `region` by the key of
    /// `sender`, a key with `role`. Refused when the station runs
    /// unauthenticated. A refusal is counted and reported, as the gate's.
    pub fn verify_signed(
        &self,
        source: &str,
        sender: &str,
        region: &[u8],
        tag: Tag,
        role: Role,
    ) -> Result<(), Rejection> {
        self.decide_now(|t, events| t.verify_signed(source, sender, (region, tag), role, events))
    }

    /// Runs a table decision that sends nothing, emitting its events.
    fn decide_now<R>(&self, f: impl FnOnce(&mut Tables, &mut Vec<Event>) -> R) -> R {
        let mut events = Vec::new();
        let mut tables = lock(&self.shared.tables);
        let r = f(&mut tables, &mut events);
        for e in events {
            self.shared.bus.emit(e);
        }
        r
    }

    /// The identity a key id belongs to (`None` when unknown or when the
    /// router runs unauthenticated): the station checks an attaching
    /// operator's key with it.
    pub fn identity(&self, key_id: u32) -> Option<Identity> {
        lock(&self.shared.tables).identity(key_id)
    }

    /// Every serial radio: what it sent and what waits.
    pub fn radios(&self) -> Vec<RadioStatus> {
        use std::sync::atomic::Ordering::Relaxed;
        let config = lock(&self.shared.tables).radio_config();
        config
            .into_iter()
            .zip(&self.shared.radios)
            .map(|(s, q)| RadioStatus {
                port: s.port,
                baud: s.baud,
                frames: q.counters.frames.load(Relaxed),
                bytes: q.counters.bytes.load(Relaxed),
                replaced: q.counters.replaced.load(Relaxed),
                dropped: q.counters.dropped.load(Relaxed),
                waiting: q.len(),
            })
            .collect()
    }

    /// A copy of every counter.
    pub fn counters(&self) -> Counters {
        lock(&self.shared.tables).counters()
    }

    /// Time since the router started.
    pub fn elapsed(&self) -> Duration {
        self.shared.bus.elapsed()
    }

    /// When the router started (router time 0).
    pub(crate) fn started(&self) -> Instant {
        self.shared.bus.start()
    }

    /// Puts `tap` on the router (or takes it off with `None`, returning
    /// the one that was on). `begin` runs holding the tables, just before
    /// the tap goes on, with the count of messages received so far: what
    /// it queues comes before every message and event the tap sees.
    pub(crate) fn set_tap(&self, tap: Option<Tap>, begin: impl FnOnce(u64)) -> Option<Tap> {
        let mut tables = lock(&self.shared.tables);
        begin(tables.counters_received());
        std::mem::replace(&mut tables.tap, tap)
    }

    /// Records an operator command in the recording, if one is being made
    /// (in order with the router's messages and events).
    pub fn record_operator(&self, mut record: OperatorRecord) {
        let tables = lock(&self.shared.tables);
        if let Some(tap) = &tables.tap {
            record.at = self.shared.bus.elapsed();
            tap.offer(Tapped::Operator(record));
        }
    }

    /// Runs an encoded message through the router as if it had arrived from
    /// a peer inside the GCS process.
    pub async fn inject(&self, bytes: &[u8]) -> Delivery {
        let mut out = Outbox::default();
        let mut events = Vec::new();
        self.shared
            .dispatch(bytes, Peer::Local, &mut out, &mut events)
            .await
    }
}

fn envelope(sender: &str, destination: &str, channel: &str, seq: u32, body: Body) -> Envelope {
    Envelope::new(
        Header {
            seq,
            stamp_us: mech_proto::unix_micros(),
            sender: sender.to_string(),
            destination: destination.to_string(),
            channel: channel.to_string(),
        },
        body,
    )
}

/// An in-process controller publishing on one channel (the TUI's keyboard,
/// a gamepad, a fleet or offboard controller).
#[derive(Debug, Clone)]
pub struct Publisher {
    router: RouterHandle,
    sender: String,
    channel: String,
    seq: u32,
}

impl Publisher {
    pub fn channel(&self) -> &str {
        &self.channel
    }

    /// Publishes one command for `robot`; it is forwarded only if the robot
    /// is routed to this publisher's channel.
    pub async fn send(&mut self, robot: &str, command: Command) -> Result<Delivery, RouterError> {
        self.send_body(robot, Body::Command(command)).await
    }

    /// Publishes commands for several robots at once; each robot routed to
    /// this channel receives only its own part.
    pub async fn send_fleet(&mut self, parts: Vec<RobotCommand>) -> Result<Delivery, RouterError> {
        self.send_body(
            mech_proto::ROUTER,
            Body::FleetCommand(FleetCommand { parts }),
        )
        .await
    }

    /// Publishes any body on this channel.
    pub async fn send_body(
        &mut self,
        destination: &str,
        body: Body,
    ) -> Result<Delivery, RouterError> {
        self.seq = self.seq.wrapping_add(1);
        let env = envelope(&self.sender, destination, &self.channel, self.seq, body);
        let bytes = mech_proto::encode(&env)?;
        Ok(self.router.inject(&bytes).await)
    }
}

/// In-process publishers under one sender name, one per channel, made on
/// first use: a channel keeps one steady publisher, so its sequence numbers
/// run on and the router's per-channel rate is that publisher's.
#[derive(Debug)]
pub struct Publishers {
    router: RouterHandle,
    sender: String,
    by_channel: HashMap<String, Publisher>,
}

impl Publishers {
    /// The publisher on `channel`.
    pub fn on(&mut self, channel: &str) -> &mut Publisher {
        let (router, sender) = (&self.router, &self.sender);
        self.by_channel
            .entry(channel.to_string())
            .or_insert_with(|| router.publisher(sender, channel))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stations asking for any port get one each: a second station never
    /// joins the first one's `SO_REUSEPORT` group (it would receive part of
    /// the first one's traffic). Bound with `SO_REUSEPORT` from the start,
    /// 600 groups on one host share a port (about 6 pairs, by the birthday
    /// bound over the ephemeral range) far more often than not.
    #[tokio::test]
    async fn stations_on_port_0_never_share_a_port() {
        let config = RouterConfig {
            udp: "127.0.0.1:0".parse().unwrap(),
            tcp: None,
            udp_workers: 1,
            socket_buffer: 4096,
            ..RouterConfig::default()
        };
        let mut held = Vec::new();
        let mut ports = std::collections::HashSet::new();
        for _ in 0..600 {
            let (udp, _) = bind(&config).await.unwrap();
            let port = udp[0].local_addr().unwrap().port();
            assert!(ports.insert(port), "port {port} given to two stations");
            held.push(udp);
        }
    }
}
