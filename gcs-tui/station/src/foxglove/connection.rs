//! One live-view client after its WebSocket handshake: frames from its
//! queue out, in batches; subscribe and unsubscribe in; and how it ends,
//! with a close code and reason the client is sent and the log is told.
//! A client that takes nothing sent for [`STALL`] is cut.

use std::time::Duration;

use futures::{SinkExt, StreamExt};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::TcpStream;
use tokio::sync::mpsc;
use tokio::time::Instant;
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

/// Runs a connection until it ends; says why.
pub(super) async fn serve(
    ws: &mut WebSocketStream<TcpStream>,
    mut rx: mpsc::Receiver<Out>,
    hub: &Hub,
    id: u64,
) -> End {
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
            msg = ws.next() => match msg {
                None => return End::quiet("closed"),
                Some(Err(e)) => return read_failed(e, hub, id),
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
    fn close_reasons_fit_a_close_frame() {
        assert_eq!(close_reason("short"), "short");
        let long = "é".repeat(100);
        let cut = close_reason(&long);
        assert!(cut.len() <= 123 && long.starts_with(&cut), "{cut}");
    }
}
