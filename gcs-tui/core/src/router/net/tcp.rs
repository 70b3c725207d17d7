//! TCP controllers and tools: an acceptor, and a task per peer that reads
//! length-prefixed frames and has each decided like a datagram; what the
//! router sends a peer goes through the peer's bounded queue to a writer
//! task, so a slow peer only loses its own messages.

use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::time::Duration;

use mech_proto::framing::StreamDecoder;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::mpsc;
use tokio::task::JoinSet;
use tokio::time::Instant;
use tracing::{info, warn};

use crate::router::Shared;
use crate::router::tables::{Effects, Peer};
use crate::sync::lock;

/// Accepts TCP controllers and tools, a task per peer; on stop, waits for
/// every peer task to end.
pub(super) async fn accept(shared: Arc<Shared>, listener: TcpListener) {
    let mut peers = JoinSet::new();
    let mut stop = shared.stop.subscribe();
    loop {
        let accepted = tokio::select! {
            a = listener.accept() => a,
            Some(_) = peers.join_next(), if !peers.is_empty() => continue,
            _ = stop.wait_for(|s| *s) => break,
        };
        match accepted {
            Ok((stream, addr)) => {
                let conn = shared.net.next_conn.fetch_add(1, Ordering::Relaxed);
                info!(%addr, conn, "TCP peer connected");
                peers.spawn(peer(shared.clone(), stream, conn));
            }
            Err(e) => {
                warn!(error = %e, "TCP accept failed");
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        }
    }
    drop(listener);
    while peers.join_next().await.is_some() {}
}

/// One TCP peer: frames in, dispatched like datagrams; frames out through a
/// bounded queue so a slow peer only loses its own messages.
async fn peer(shared: Arc<Shared>, stream: TcpStream, conn: u64) {
    let _ = stream.set_nodelay(true);
    let (mut rd, mut wr) = stream.into_split();
    let (tx, mut rx) = mpsc::channel::<Vec<u8>>(shared.net.peer_queue);
    lock(&shared.net.tcp_peers).insert(conn, tx);
    let writer = tokio::spawn(async move {
        while let Some(frame) = rx.recv().await {
            if wr.write_all(&frame).await.is_err() {
                break;
            }
        }
    });
    let mut decoder = StreamDecoder::new();
    let mut buf = vec![0u8; 65_536];
    let mut fx = Effects::default();
    let started = Instant::now();
    let mut stop = shared.stop.subscribe();
    let from = Peer::Tcp(conn);
    'read: loop {
        let read = tokio::select! {
            r = rd.read(&mut buf) => r,
            _ = stop.wait_for(|s| *s) => break,
        };
        let n = match read {
            Ok(0) | Err(_) => break,
            Ok(n) => n,
        };
        decoder.push(&buf[..n]);
        loop {
            let frame = match decoder.next_frame() {
                None => break,
                Some(Ok(frame)) => frame.to_vec(),
                Some(Err(e)) => {
                    // Only a bad length prefix is an error here, and it
                    // leaves the stream out of step for good.
                    warn!(conn, error = %e, "TCP stream out of step, closing it");
                    shared.count_bad(from, e.to_string());
                    break 'read;
                }
            };
            shared.dispatch(&frame, from, &mut fx).await;
        }
    }
    lock(&shared.net.tcp_peers).remove(&conn);
    lock(&shared.tables).forget_peer(from);
    writer.abort();
    let _ = writer.await;
    info!(
        conn,
        secs = started.elapsed().as_secs_f64(),
        "TCP peer disconnected"
    );
}
