//! One live-view client after its WebSocket handshake: frames from its
//! queue out, in batches; subscribe and unsubscribe in; pings both ways;
//! and how it ends, with a close code and reason the client is sent and
//! the log is told.
//!
//! What the station holds for a client is bounded: its queue of frames
//! (`[foxglove] client_queue`), and what the WebSocket has written but
//! the kernel has not taken (a batch, or the pong owed for a ping: after
//! a client's ping the station reads nothing more from it until the pong
//! is handed to the kernel, so pongs owed to a client that never reads do
//! not pile up; its pings wait in the kernel's buffers instead).
//!
//! A client is cut when it does not read for [`STALL`]: when nothing the
//! station sends it is taken for that long, or when none of the pings the
//! station sends it every [`PING_EVERY`] has been answered for that long
//! (the kernel's buffers take megabytes before a send would block; a
//! client reads a ping only after everything sent before it, so one that
//! answers pings reads, however far behind it is).

use std::collections::VecDeque;
use std::time::Duration;

use futures::{SinkExt, StreamExt};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio::time::{Instant, MissedTickBehavior};
use tokio_tungstenite::WebSocketStream;
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::error::{CapacityError, Error as WsError};
use tokio_tungstenite::tungstenite::protocol::CloseFrame;
use tokio_tungstenite::tungstenite::protocol::frame::coding::CloseCode;

use super::hub::{Cut, Hub, Out};
use super::protocol::{self, Level, Request as ClientRequest};

/// Largest message a client may send (requests are small).
pub(super) const MAX_REQUEST: usize = 64 << 10;

/// Time a client may go without reading before it is cut (it would hold
/// a place among the clients, and its queue, for nothing).
pub(super) const STALL: Duration = Duration::from_secs(10);

/// How often the station pings each client (and looks whether it has
/// stalled): a client that stops reading is cut between [`STALL`] and
/// `STALL` + 2 `PING_EVERY` later.
const PING_EVERY: Duration = Duration::from_secs(1);

/// Pings awaiting their pong that are remembered (a client that far
/// behind still answers the later ones).
const PINGS_REMEMBERED: usize = 64;

/// Frames sent before one flush.
const SEND_BATCH: usize = 64;

/// Time the closing frames have to reach a client, and then the client to
/// close its side, before the socket is dropped.
const CLOSE_GRACE: Duration = Duration::from_secs(10);

/// How a connection ended.
#[derive(Debug)]
pub(super) struct End {
    /// The close code the client is sent; `None` when it closed, or the
    /// connection failed, and there is nothing to tell it.
    pub(super) code: Option<CloseCode>,
    /// Why, for the log and the close frame.
    pub(super) why: String,
}

impl End {
    fn quiet(why: impl Into<String>) -> End {
        End {
            code: None,
            why: why.into(),
        }
    }

    pub(super) fn coded(code: CloseCode, why: impl Into<String>) -> End {
        End {
            code: Some(code),
            why: why.into(),
        }
    }

    fn stalled(how: &str) -> End {
        End::coded(
            CloseCode::Policy,
            format!("did not read for {} s ({how})", STALL.as_secs()),
        )
    }
}

/// The pings sent to a client and the last time it answered one.
#[derive(Debug)]
struct Liveness {
    next: u64,
    /// Pings not answered yet, oldest first: number and when sent.
    waiting: VecDeque<(u64, Instant)>,
    last_answer: Instant,
}

impl Liveness {
    fn new(now: Instant) -> Liveness {
        Liveness {
            next: 0,
            waiting: VecDeque::new(),
            last_answer: now,
        }
    }

    /// Whether the client has read nothing for [`STALL`]: a ping has
    /// waited that long and no answer came in that time.
    fn stalled(&self, now: Instant) -> bool {
        self.waiting
            .front()
            .is_some_and(|&(_, sent)| now - sent >= STALL && now - self.last_answer >= STALL)
    }

    /// The payload of a new ping, remembered as sent `now`.
    fn ping(&mut self, now: Instant) -> Vec<u8> {
        self.next += 1;
        if self.waiting.len() >= PINGS_REMEMBERED {
            self.waiting.pop_front();
        }
        self.waiting.push_back((self.next, now));
        self.next.to_be_bytes().to_vec()
    }

    /// A pong: it answers the ping whose number it carries (and every
    /// earlier one); anything else (a pong the station did not ask for)
    /// proves nothing.
    fn pong(&mut self, payload: &[u8], now: Instant) {
        let Ok(bytes) = <[u8; 8]>::try_from(payload) else {
            return;
        };
        let n = u64::from_be_bytes(bytes);
        if !self.waiting.iter().any(|&(p, _)| p == n) {
            return;
        }
        while self.waiting.front().is_some_and(|&(p, _)| p <= n) {
            self.waiting.pop_front();
        }
        self.last_answer = now;
    }
}

/// Runs a connection until it ends; says why.
pub(super) async fn serve(
    ws: &mut WebSocketStream<TcpStream>,
    mut rx: mpsc::Receiver<Out>,
    hub: &Hub,
    id: u64,
) -> End {
    let mut pings = tokio::time::interval(PING_EVERY);
    pings.set_missed_tick_behavior(MissedTickBehavior::Delay);
    let mut alive = Liveness::new(Instant::now());
    loop {
        tokio::select! {
            out = rx.recv() => {
                let Some(out) = out else { return cut_by_hub(hub, id) };
                match tokio::time::timeout(STALL, send_batch(ws, out, &mut rx)).await {
                    Ok(Ok(())) => {}
                    Ok(Err(e)) => return End::quiet(format!("send failed: {e}")),
                    Err(_) => return End::stalled("nothing sent was taken"),
                }
            }
            _ = pings.tick() => {
                let now = Instant::now();
                if alive.stalled(now) {
                    return End::stalled("no ping answered");
                }
                let ping = Message::Ping(alive.ping(now).into());
                match tokio::time::timeout(STALL, ws.send(ping)).await {
                    Ok(Ok(())) => {}
                    Ok(Err(e)) => return End::quiet(format!("send failed: {e}")),
                    Err(_) => return End::stalled("nothing sent was taken"),
                }
            }
            msg = ws.next() => match msg {
                None => return End::quiet("closed"),
                Some(Err(e)) => return read_failed(e, hub, id),
                Some(Ok(Message::Ping(_))) => {
                    // The pong is owed: hand it to the kernel before
                    // reading on, so pongs never pile up here.
                    match tokio::time::timeout(STALL, ws.flush()).await {
                        Ok(Ok(())) => {}
                        Ok(Err(e)) => return End::quiet(format!("send failed: {e}")),
                        Err(_) => return End::stalled("its pongs were not taken"),
                    }
                }
                Some(Ok(Message::Pong(p))) => alive.pong(&p, Instant::now()),
                Some(Ok(m)) => {
                    if let Some(end) = request(m, hub, id) {
                        return end;
                    }
                }
            },
        }
    }
}

/// The hub let go of the client (its queue is closed): why.
fn cut_by_hub(hub: &Hub, id: u64) -> End {
    match hub.cut(id) {
        Some(Cut::Stopping) => End::coded(CloseCode::Away, "the station is stopping"),
        Some(Cut::NoRoomForChannel) => End::coded(
            CloseCode::Policy,
            "too slow: its queue had no room for a new channel",
        ),
        None => End::coded(CloseCode::Away, "cut by the station"),
    }
}

/// A read failed: a message over [`MAX_REQUEST`] or one that breaks the
/// protocol is counted and gets a close code saying so; a failed socket
/// just ends.
fn read_failed(e: WsError, hub: &Hub, id: u64) -> End {
    let end = match &e {
        WsError::Capacity(CapacityError::MessageTooLong { size, max_size }) => End::coded(
            CloseCode::Size,
            format!(
                "message too big: {size} bytes, over the {} KiB a request may be",
                max_size >> 10
            ),
        ),
        WsError::Capacity(c) => End::coded(CloseCode::Size, format!("message too big: {c}")),
        WsError::Utf8(_) => End::coded(CloseCode::Invalid, "text that is not UTF-8"),
        WsError::Protocol(p) => End::coded(CloseCode::Protocol, format!("protocol error: {p}")),
        _ => return End::quiet(format!("error: {e}")),
    };
    hub.count_bad(id);
    end
}

/// Sends `first` and what else is queued (up to a batch), then flushes.
async fn send_batch(
    ws: &mut WebSocketStream<TcpStream>,
    first: Out,
    rx: &mut mpsc::Receiver<Out>,
) -> Result<(), WsError> {
    ws.feed(message(first)).await?;
    for _ in 0..SEND_BATCH {
        match rx.try_recv() {
            Ok(out) => ws.feed(message(out)).await?,
            Err(_) => break,
        }
    }
    ws.flush().await
}

fn message(out: Out) -> Message {
    match out {
        Out::Text(t) => Message::Text(t.into()),
        Out::Binary(b) => Message::Binary(b.into()),
    }
}

/// Handles one message from the client; `Some` ends the connection.
fn request(m: Message, hub: &Hub, id: u64) -> Option<End> {
    let refused = match m {
        Message::Text(t) => match protocol::request(t.as_str()) {
            Ok(ClientRequest::Subscribe { subscriptions }) => {
                hub.subscribe(id, &subscriptions).err()
            }
            Ok(ClientRequest::Unsubscribe { subscription_ids }) => {
                hub.unsubscribe(id, &subscription_ids);
                None
            }
            Err(why) => Some(why),
        },
        Message::Binary(_) => {
            Some("binary messages are not served: the live view only shows the fleet".into())
        }
        Message::Close(_) => return Some(End::quiet("closed")),
        Message::Ping(_) | Message::Pong(_) | Message::Frame(_) => None,
    };
    let why = refused?;
    if hub.refuse(id, &why) {
        None
    } else {
        Some(End::coded(
            CloseCode::Policy,
            format!("too many bad requests (last: {why})"),
        ))
    }
}

/// Ends the connection: a client the station cut is told why (a status
/// message, then a close frame with the code and reason), if it takes
/// them within [`CLOSE_GRACE`]; then what it still sends is read and
/// discarded until it closes its side (or the grace ends), so the socket
/// closes with a FIN and the close frame is not lost to a reset (which is
/// what closing a socket with unread bytes sends). When too many are
/// closing already, it is dropped at once.
pub(super) async fn close(ws: &mut WebSocketStream<TcpStream>, end: &End, hub: &Hub) {
    let Ok(_place) = hub.closing.try_acquire() else {
        return;
    };
    let deadline = Instant::now() + CLOSE_GRACE;
    if let Some(code) = end.code {
        let frame = CloseFrame {
            code,
            reason: close_reason(&end.why).into(),
        };
        let status = Message::Text(protocol::status(Level::Error, &end.why).into());
        let told = tokio::time::timeout_at(deadline, async {
            ws.feed(status).await?;
            ws.close(Some(frame)).await
        })
        .await;
        if !matches!(told, Ok(Ok(()))) {
            return;
        }
    } else {
        let _ = tokio::time::timeout_at(deadline, ws.close(None)).await;
    }
    let tcp = ws.get_mut();
    let _ = tcp.shutdown().await;
    let mut buf = vec![0u8; 16 << 10];
    while let Ok(Ok(1..)) = tokio::time::timeout_at(deadline, tcp.read(&mut buf)).await {}
}

/// A close frame's reason holds 123 bytes at most: `why`, cut at a
/// character boundary.
fn close_reason(why: &str) -> String {
    const MAX: usize = 123;
    if why.len() <= MAX {
        return why.to_string();
    }
    let mut end = MAX;
    while !why.is_char_boundary(end) {
        end -= 1;
    }
    why[..end].to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_client_is_stalled_only_when_a_ping_waited_and_nothing_was_answered_for_the_stall() {
        let t0 = Instant::now();
        let mut alive = Liveness::new(t0);
        assert!(!alive.stalled(t0 + STALL * 5), "no ping, no verdict");
        let first = alive.ping(t0);
        assert!(!alive.stalled(t0 + STALL - Duration::from_millis(1)));
        assert!(alive.stalled(t0 + STALL));
        // A client far behind still answers: each answer counts, late or
        // not, and answers every earlier ping.
        let second = alive.ping(t0 + PING_EVERY);
        alive.pong(&second, t0 + STALL + PING_EVERY);
        assert!(alive.waiting.is_empty(), "{first:?} answered by {second:?}");
        assert!(!alive.stalled(t0 + STALL * 2));
        // Pongs the station did not ask for prove nothing.
        let t1 = t0 + STALL * 3;
        alive.ping(t1);
        alive.pong(b"nonsense", t1 + STALL);
        alive.pong(&999u64.to_be_bytes(), t1 + STALL);
        assert!(alive.stalled(t1 + STALL));
    }

    #[test]
    fn pings_remembered_are_bounded() {
        let t0 = Instant::now();
        let mut alive = Liveness::new(t0);
        for _ in 0..PINGS_REMEMBERED * 3 {
            alive.ping(t0);
        }
        assert_eq!(alive.waiting.len(), PINGS_REMEMBERED);
    }

    #[test]
    fn close_reasons_fit_a_close_frame() {
        assert_eq!(close_reason("short"), "short");
        let long = "é".repeat(100);
        let cut = close_reason(&long);
        assert!(cut.len() <= 123 && long.starts_with(&cut), "{cut}");
    }
}
