//! One attached client, from its Hello to its last message. A session has
//! three parts: the reader (this task: checks every message, acts on
//! teleop and e-stops at once, queues command lines), the executor (runs
//! the lines one after another, as the TUI command line always has), and
//! the writer (results, events, snapshots and log lines, in that order of
//! urgency). When the client goes, for whatever reason, only its session
//! ends: routes, missions and controllers stay as they are.

use std::sync::Arc;
use std::time::{Duration, Instant};

use mech_control::lang::{Executor, LangError, Outcome, parse_line};
use mech_control::script::{event_json, execute_with_events, secs};
use mech_core::Stamped;
use mech_core::fleet::Severity;
use mech_core::router::{Publishers, Subscription};
use mech_core::sync::lock;
use mech_proto::auth::Tag;
use serde_json::Value;
use tokio::io::{AsyncRead, AsyncWrite, AsyncWriteExt, BufReader, ReadHalf, WriteHalf};
use tokio::sync::{mpsc, watch};

use crate::admission::{Attaching, Door, HANDSHAKE, Seat};
use crate::feed::{LOG_HISTORY, LogCursor};
use crate::operator::{check_operator, login_name};
use crate::server::{Station, Via};
use crate::wire::{
    FromStation, LineResult, MAX_CLIENT_LINE, PROTOCOL, ReadError, Streams, ToStation, Welcome,
    challenge_region, hex, read_message, to_line, unhex,
};
use mech_core::auth::Role;

/// Time a write may take before the client counts as gone (it stopped
/// reading).
const WRITE_TIMEOUT: Duration = Duration::from_secs(10);

/// Lines a client may queue behind the one running.
const LINE_QUEUE: usize = 64;

/// Results and events waiting for the writer.
const OUT_QUEUE: usize = 4096;

/// Bad messages a client may send before the station hangs up.
const MAX_BAD: u32 = 100;

impl Station {
    /// A client end in this process (the embedded station's TUI): the
    /// same protocol as a socket, over an in-memory pipe.
    pub fn attach_local(&self) -> tokio::io::DuplexStream {
        let (client, station) = tokio::io::duplex(1 << 20);
        self.spawn_session(station, Via::Local);
        client
    }

    /// Serves one client on `stream` until it leaves or the station stops.
    pub(crate) fn spawn_session<S>(&self, stream: S, via: Via)
    where
        S: AsyncRead + AsyncWrite + Send + 'static,
    {
        let door = match &via {
            Via::Local => Door::Local,
            Via::Unix { .. } => Door::Unix,
            Via::Tcp { peer } => Door::Tcp(peer.ip()),
        };
        let place = self.inner.admission.attaching(door);
        let mut sessions = lock(&self.inner.sessions);
        // Reap the finished ones so the set holds only live sessions.
        while sessions.try_join_next().is_some() {}
        let station = self.clone();
        sessions.spawn(run(station, stream, via, place));
    }
}

/// Serves one client (see the module docs), from a place among the
/// clients attaching (`crate::admission`).
async fn run<S>(station: Station, stream: S, via: Via, place: Attaching)
where
    S: AsyncRead + AsyncWrite + Send + 'static,
{
    let (rd, mut wr) = tokio::io::split(stream);
    let mut rd = BufReader::new(rd);
    let attempt = tokio::select! {
        r = tokio::time::timeout(HANDSHAKE, handshake(&station, &mut rd, &mut wr, &via)) => {
            match r {
                Ok(Ok(h)) => Ok(h),
                Ok(Err(reason)) => Err((reason, true)),
                Err(_) => Err(("no hello within 10 s".to_string(), false)),
            }
        }
        () = place.evicted() => Err((
            "too many clients are attaching at once; this one waited longest".to_string(),
            false,
        )),
    };
    let hello = match attempt {
        Ok(hello) => hello,
        Err((reason, pause)) => {
            // The place is kept through the pause, so a client paying for
            // a failed handshake still counts among those attaching (and
            // one attaching after it may take its place, ending the pause).
            refuse_attach(&station, &via, &mut wr, &reason, pause.then_some(&place)).await;
            return;
        }
    };
    let (hello, _seat) = match seated(place, hello) {
        Ok(attached) => attached,
        Err((reason, _)) => {
            refuse_attach(&station, &via, &mut wr, &reason, None).await;
            return;
        }
    };
    let welcome = to_line(&FromStation::Welcome(hello.welcome.clone()));
    if send(&mut wr, &welcome).await.is_err() {
        return;
    }
    let operator = hello.operator.clone();
    station.log(Severity::Info, format!("{operator} attached ({via})"));
    tracing::info!(%operator, %via, "operator attached");
    let reason = serve(&station, rd, wr, hello).await;
    station.log(Severity::Info, format!("{operator} detached: {reason}"));
    tracing::info!(%operator, %reason, "operator detached");
}

/// A session place for a client whose handshake succeeded, or why there
/// is none (no pause: it did nothing wrong).
fn seated(place: Attaching, hello: Attached) -> Result<(Attached, Seat), (String, bool)> {
    place
        .seat()
        .map(|seat| (hello, seat))
        .map_err(|r| (r, false))
}

/// Who attached and what they want.
struct Attached {
    operator: String,
    stream: Streams,
    welcome: Welcome,
}

/// Reads the Hello (and over TCP checks the operator key); the welcome is
/// sent once the client has a place.
async fn handshake<R, W>(
    station: &Station,
    rd: &mut BufReader<R>,
    wr: &mut W,
    via: &Via,
) -> Result<Attached, String>
where
    R: AsyncRead + Unpin,
    W: AsyncWrite + Unpin,
{
    let mut buf = Vec::new();
    let first = read_message::<ToStation>(rd, &mut buf, MAX_CLIENT_LINE).await;
    let Ok(Some(ToStation::Hello {
        protocol,
        operator,
        stream,
    })) = first
    else {
        return Err("the first message must be a hello".into());
    };
    if protocol != PROTOCOL {
        return Err(format!(
            "protocol {protocol} is not spoken here (this station speaks {PROTOCOL})"
        ));
    }
    let operator = match via {
        Via::Local => operator.unwrap_or_else(login_name),
        Via::Unix { user } => operator.unwrap_or_else(|| user.clone()),
        Via::Tcp { .. } => prove_key(station, rd, wr, operator).await?,
    };
    check_operator(&operator)?;
    let welcome = welcome(station, &operator, via);
    Ok(Attached {
        operator,
        stream,
        welcome,
    })
}

/// Over TCP: challenges the client to sign a fresh nonce with an operator
/// key the station lists; the key's name is the operator.
async fn prove_key<R, W>(
    station: &Station,
    rd: &mut BufReader<R>,
    wr: &mut W,
    claimed: Option<String>,
) -> Result<String, String>
where
    R: AsyncRead + Unpin,
    W: AsyncWrite + Unpin,
{
    let mut nonce = [0u8; 32];
    getrandom::fill(&mut nonce).map_err(|e| format!("no randomness for a challenge: {e}"))?;
    let challenge = to_line(&FromStation::Challenge { nonce: hex(&nonce) });
    write(wr, &challenge).await.map_err(|e| e.to_string())?;
    let mut buf = Vec::new();
    let Ok(Some(ToStation::Auth { tag })) =
        read_message::<ToStation>(rd, &mut buf, MAX_CLIENT_LINE).await
    else {
        return Err("expected the answer to the challenge".into());
    };
    let tag = unhex(&tag)
        .and_then(|b| Tag::parse(&b).ok())
        .ok_or("the answer is not a 29-byte tag in hex")?;
    let identity = station
        .gcs()
        .router()
        .identity(tag.key_id)
        .ok_or_else(|| format!("key {:08x} is not listed at this station", tag.key_id))?;
    if identity.role != Role::Operator {
        return Err(format!(
            "key {:08x} is a {} key; attaching needs an operator key",
            tag.key_id,
            identity.role.as_str()
        ));
    }
    if !identity
        .key
        .verify(&challenge_region(&nonce, &identity.name), &tag)
    {
        return Err("the answer does not verify".into());
    }
    match claimed {
        Some(c) if c != identity.name => {
            Err(format!("the key is {:?}'s, not {c:?}'s", identity.name))
        }
        _ => Ok(identity.name),
    }
}

fn welcome(station: &Station, operator: &str, via: &Via) -> Welcome {
    let router = station.gcs().router();
    // The embedded station's own TUI keeps the plain channel names; each
    // attached operator's pads and keys are theirs alone.
    let (pads, keys) = match via {
        Via::Local => ("joy".to_string(), "key/0".to_string()),
        _ => (format!("joy/{operator}"), format!("key/{operator}")),
    };
    Welcome {
        protocol: PROTOCOL,
        operator: operator.to_string(),
        router: router.udp_addr().to_string(),
        security: router.security(),
        pads,
        keys,
        arena: *lock(&station.inner.arena),
    }
}

/// Logs (a few a second; the rest counted, see `crate::admission`) and
/// answers a failed attach; with `pause`, the client's place among those
/// attaching, a failed handshake over TCP (a wrong key) costs the client a
/// second, so guessing is slow, unless another client takes the place
/// meanwhile: the connections held for the pause are bounded by the places.
async fn refuse_attach<W: AsyncWrite + Unpin>(
    station: &Station,
    via: &Via,
    wr: &mut W,
    reason: &str,
    pause: Option<&Attaching>,
) {
    if station
        .inner
        .admission
        .log_refusal(tokio::time::Instant::now())
    {
        station.log(Severity::Warn, format!("attach refused ({via}): {reason}"));
        tracing::warn!(%via, %reason, "attach refused");
    }
    if let (Some(place), Via::Tcp { .. }) = (pause, via) {
        tokio::select! {
            () = tokio::time::sleep(Duration::from_secs(1)) => {}
            () = place.evicted() => {}
        }
    }
    bye(wr, reason).await;
}

async fn bye<W: AsyncWrite + Unpin>(wr: &mut W, reason: &str) {
    let line = to_line(&FromStation::Bye {
        reason: reason.to_string(),
    });
    let _ = tokio::time::timeout(WRITE_TIMEOUT, write(wr, &line)).await;
    let _ = wr.shutdown().await;
}

async fn write<W: AsyncWrite + Unpin>(wr: &mut W, line: &str) -> std::io::Result<()> {
    wr.write_all(line.as_bytes()).await?;
    wr.flush().await
}

/// The attached part of a session; returns why it ended.
async fn serve<S>(
    station: &Station,
    mut rd: BufReader<ReadHalf<S>>,
    wr: WriteHalf<S>,
    hello: Attached,
) -> String
where
    S: AsyncRead + AsyncWrite + Send + 'static,
{
    let (out_tx, out_rx) = mpsc::channel::<Arc<str>>(OUT_QUEUE);
    let writer = tokio::spawn(write_loop(wr, out_rx, feeds(station, hello.stream)));
    let (line_tx, line_rx) = mpsc::channel(LINE_QUEUE);
    let executor = executor(station, &hello.operator);
    let events = hello
        .stream
        .events
        .then(|| station.gcs().router().subscribe_default(false));
    let exec = tokio::spawn(exec_loop(executor, line_rx, out_tx.clone(), events));
    let mut reader = Reader {
        station: station.clone(),
        operator: hello.operator,
        publishers: station.gcs().router().publishers(&hello.welcome.operator),
        lines: line_tx,
        out: out_tx,
        bad: 0,
        refusals: Refusals::default(),
    };
    let mut closing = station.inner.closing.subscribe();
    let reason = tokio::select! {
        r = reader.read_all(&mut rd) => r,
        _ = closing.wait_for(|c| *c) => "the station is stopping".to_string(),
    };
    // A line still running has nobody to report to; what it started (a
    // mission, a route) goes on without it.
    exec.abort();
    let _ = reader.out.try_send(
        to_line(&FromStation::Bye {
            reason: reason.clone(),
        })
        .into(),
    );
    drop(reader);
    let _ = tokio::time::timeout(Duration::from_secs(1), writer).await;
    reason
}

/// This session's executor: the station's controllers and simulator, and
/// the operator as the sender of everything it publishes and the source of
/// its commands in recordings.
fn executor(station: &Station, operator: &str) -> Executor {
    let mut e = Executor::new(station.gcs().clone())
        .with_control(station.control().clone())
        .with_sender(operator)
        .with_source(operator);
    if let Some(s) = &station.inner.spawner {
        e = e.with_spawner(Box::new(s.clone()));
    }
    if let Some(dir) = lock(&station.inner.record_dir).clone() {
        e = e.with_record_dir(dir);
    }
    if let Some(routes) = lock(&station.inner.remote_routes).clone() {
        e = e.with_remote_routes(routes);
    }
    e
}

/// The feeds a client asked for.
struct Feeds {
    gcs: mech_core::Gcs,
    snapshots: Option<watch::Receiver<Arc<str>>>,
    /// Where the client is in the event log, and the feed's word that it
    /// grew.
    log: Option<(LogCursor, watch::Receiver<u64>)>,
}

impl Feeds {
    /// Event-log lines the client has not had yet.
    fn new_log_lines(&mut self) -> Vec<String> {
        match self.log.as_mut() {
            Some((cursor, _)) => self.gcs.with_fleet(|f| cursor.take(f)),
            None => Vec::new(),
        }
    }
}

fn feeds(station: &Station, s: Streams) -> Feeds {
    let feed = &station.inner.feed;
    let gcs = station.gcs().clone();
    // Watch first, so no line falls between the cursor and the watch.
    let log = s.log.then(|| {
        let grew = feed.log_seq();
        (gcs.with_fleet(|f| LogCursor::recent(f, LOG_HISTORY)), grew)
    });
    Feeds {
        gcs,
        snapshots: s.snapshots.then(|| feed.snapshots()),
        log,
    }
}

/// Writes everything bound for the client until the session ends or the
/// client stops reading for [`WRITE_TIMEOUT`]. Event-log lines go before
/// whatever comes next, so a command's result follows what it logged.
async fn write_loop<W: AsyncWrite + Unpin>(
    mut wr: W,
    mut out: mpsc::Receiver<Arc<str>>,
    mut feeds: Feeds,
) {
    loop {
        let next: Option<Arc<str>> = tokio::select! {
            biased;
            m = out.recv() => match m {
                Some(line) => Some(line),
                None => break,
            },
            () = log_grew(&mut feeds.log), if feeds.log.is_some() => None,
            line = next_snapshot(&mut feeds.snapshots), if feeds.snapshots.is_some() => {
                line.filter(|l| !l.is_empty())
            }
        };
        for line in feeds.new_log_lines() {
            if send(&mut wr, &line).await.is_err() {
                return;
            }
        }
        if let Some(line) = next {
            if send(&mut wr, &line).await.is_err() {
                return;
            }
        }
    }
    let _ = wr.shutdown().await;
}

/// Returns when the event log grew (never, once the feed has stopped).
async fn log_grew(log: &mut Option<(LogCursor, watch::Receiver<u64>)>) {
    let Some((_, grew)) = log.as_mut() else {
        return std::future::pending().await;
    };
    if grew.changed().await.is_err() {
        std::future::pending::<()>().await;
    }
}

async fn send<W: AsyncWrite + Unpin>(wr: &mut W, line: &str) -> Result<(), ()> {
    match tokio::time::timeout(WRITE_TIMEOUT, write(wr, line)).await {
        Ok(Ok(())) => Ok(()),
        _ => Err(()),
    }
}

/// The newest snapshot once it changes.
async fn next_snapshot(snaps: &mut Option<watch::Receiver<Arc<str>>>) -> Option<Arc<str>> {
    let rx = snaps.as_mut()?;
    if rx.changed().await.is_err() {
        *snaps = None;
        return None;
    }
    Some(rx.borrow_and_update().clone())
}

/// Runs queued lines one after another, sending each result (and, for a
/// client that asked, every router event) back.
async fn exec_loop(
    mut executor: Executor,
    mut lines: mpsc::Receiver<(u64, String)>,
    out: mpsc::Sender<Arc<str>>,
    mut events: Option<Subscription>,
) {
    let elapsed = {
        let router = executor.gcs().router().clone();
        move || secs(router.elapsed())
    };
    loop {
        let (id, text) = tokio::select! {
            l = lines.recv() => match l {
                Some(l) => l,
                None => break,
            },
            Some(ev) = next_event(&mut events) => {
                forward_event(&out, &ev);
                continue;
            }
        };
        let result = match parse_line(&text) {
            Ok(Some(stmt)) => match events.as_mut() {
                Some(ev) => {
                    execute_with_events(&mut executor, &stmt, ev, |e| forward_event(&out, e)).await
                }
                None => executor.execute(&stmt).await,
            },
            Ok(None) => Ok(Outcome::default()),
            Err(e) => Err(e),
        };
        let line = to_line(&FromStation::Result(line_result(id, elapsed(), result)));
        if out.send(line.into()).await.is_err() {
            break;
        }
    }
}

async fn next_event(events: &mut Option<Subscription>) -> Option<Arc<Stamped>> {
    match events.as_mut() {
        Some(e) => e.recv().await,
        None => std::future::pending().await,
    }
}

/// An event as `--script` prints it. A client too slow for the events
/// loses some (the result lines still arrive).
fn forward_event(out: &mpsc::Sender<Arc<str>>, ev: &Stamped) {
    if let Value::Object(mut m) = event_json(ev) {
        m.remove("type");
        let _ = out.try_send(to_line(&FromStation::Event(m)).into());
    }
}

fn line_result(id: u64, t: f64, result: Result<Outcome, LangError>) -> LineResult {
    match result {
        Ok(o) => LineResult {
            id,
            t,
            ok: true,
            summary: o.summary,
            details: o.details,
            error: None,
            column: None,
        },
        Err(e) => LineResult {
            id,
            t,
            ok: false,
            summary: String::new(),
            details: Vec::new(),
            error: Some(e.message),
            column: Some(e.span.column),
        },
    }
}

/// At most one refusal a second is sent; the rest are counted into it.
#[derive(Debug, Default)]
struct Refusals {
    last: Option<Instant>,
    held: u64,
}

/// The reading side of a session.
struct Reader {
    station: Station,
    operator: String,
    /// This operator's teleop publishers, one per channel.
    publishers: Publishers,
    lines: mpsc::Sender<(u64, String)>,
    out: mpsc::Sender<Arc<str>>,
    bad: u32,
    refusals: Refusals,
}

impl Reader {
    /// Handles messages until the client leaves; returns why.
    async fn read_all<R: AsyncRead + Unpin>(&mut self, rd: &mut BufReader<R>) -> String {
        let mut buf = Vec::new();
        loop {
            match read_message::<ToStation>(rd, &mut buf, MAX_CLIENT_LINE).await {
                Ok(None) => return "the connection closed".into(),
                Ok(Some(ToStation::Bye)) => return "said bye".into(),
                Ok(Some(m)) => self.handle(m).await,
                Err(ReadError::Io(e)) => return format!("connection error: {e}"),
                Err(e) => {
                    self.bad += 1;
                    self.refuse(format!("bad message: {e}"));
                    if self.bad >= MAX_BAD {
                        return format!("{MAX_BAD} bad messages");
                    }
                }
            }
        }
    }

    async fn handle(&mut self, m: ToStation) {
        match m {
            ToStation::Line { id, text } => self.line(id, text).await,
            ToStation::Publish {
                channel,
                robots,
                command,
            } => self.publish(&channel, robots, command).await,
            ToStation::DriveCluster { cluster, velocity } => {
                if let Err(e) = self.station.control().drive_cluster(&cluster, velocity) {
                    self.refuse(format!("{cluster}: {e}"));
                }
            }
            ToStation::Hello { .. } | ToStation::Auth { .. } => {
                self.refuse("already attached".into());
            }
            ToStation::Bye => {}
        }
    }

    /// Logs the line under the operator's name, then runs it: `estop` and
    /// `release` at once (lines queued before them may be waiting), the
    /// rest in order.
    async fn line(&mut self, id: u64, text: String) {
        let op = &self.operator;
        self.station
            .log(Severity::Info, format!("{op}> {}", text.trim()));
        tracing::info!(operator = %op, line = %text.trim(), "command");
        if let Some(engage) = estop_line(&text) {
            let router = self.station.gcs().router();
            let rid = if engage {
                router.estop().await
            } else {
                router.release().await
            };
            let what = if engage {
                "E-STOP engaged"
            } else {
                "e-stop released"
            };
            let summary = format!("{what} (id {rid})");
            router.record_operator(mech_core::router::OperatorRecord {
                at: std::time::Duration::ZERO,
                source: op.clone(),
                line: 0,
                text: text.trim().to_string(),
                ok: true,
                summary: summary.clone(),
            });
            let result = Ok(Outcome::new(summary));
            let t = secs(router.elapsed());
            self.send(to_line(&FromStation::Result(line_result(id, t, result))));
            return;
        }
        if let Err(e) = self.lines.try_send((id, text)) {
            let message = match e {
                mpsc::error::TrySendError::Full(_) => {
                    format!("{LINE_QUEUE} lines are already waiting; this one was not run")
                }
                mpsc::error::TrySendError::Closed(_) => "the command language stopped".into(),
            };
            let t = secs(self.station.gcs().router().elapsed());
            let result = LineResult {
                id,
                t,
                ok: false,
                summary: String::new(),
                details: Vec::new(),
                error: Some(message),
                column: None,
            };
            self.send(to_line(&FromStation::Result(result)));
        }
    }

    /// A teleop command for each robot, on the operator's publisher.
    async fn publish(&mut self, channel: &str, robots: Vec<String>, command: mech_proto::Command) {
        if !mech_core::config::is_channel_name(channel) {
            return self.refuse(format!("{channel:?} is not a channel name"));
        }
        if let Err(e) = command.validate() {
            return self.refuse(format!("bad command for {channel}: {e}"));
        }
        let p = self.publishers.on(channel);
        let mut failed = None;
        for robot in robots.iter().take(mech_proto::MAX_FLEET_PARTS) {
            if let Err(e) = p.send(robot, command.clone()).await {
                failed = Some(format!("{channel} -> {robot}: {e}"));
            }
        }
        if let Some(reason) = failed {
            self.refuse(reason);
        }
    }

    fn send(&self, line: String) {
        let _ = self.out.try_send(line.into());
    }

    /// Tells the client what was refused, at most once a second.
    fn refuse(&mut self, reason: String) {
        let now = Instant::now();
        if self
            .refusals
            .last
            .is_some_and(|t| now.duration_since(t) < Duration::from_secs(1))
        {
            self.refusals.held += 1;
            return;
        }
        let reason = match std::mem::take(&mut self.refusals.held) {
            0 => reason,
            n => format!("{reason} (and {n} more refused in the last second)"),
        };
        self.refusals.last = Some(now);
        self.send(to_line(&FromStation::Refused { reason }));
    }
}

/// `Some(true)` for a line that is `estop`, `Some(false)` for `release`.
fn estop_line(line: &str) -> Option<bool> {
    let statement = parse_line(line).ok().flatten()?;
    match statement.command {
        mech_control::lang::Command::EStop => Some(true),
        mech_control::lang::Command::Release => Some(false),
        _ => None,
    }
}
