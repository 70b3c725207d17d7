//! What strangers' TCP connections may cost the router: a peer that sends
//! no valid message is closed after `router.tcp_idle`; when an address's
//! share or the whole budget is taken, the oldest peer without a valid
//! message makes room for the new one; a peer that sent one is never
//! closed to make room. Real sockets on loopback (other 127.x addresses
//! stand for other machines).

#![allow(clippy::unwrap_used)]

#[path = "support/agent.rs"]
mod agent;

use std::net::SocketAddr;
use std::time::Duration;

use agent::{config, envelope};
use mech_core::Gcs;
use mech_proto::framing::{StreamDecoder, write_stream_frame};
use mech_proto::{Body, ChannelsRequest};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::net::{TcpSocket, TcpStream};

async fn gcs(max_peers: usize, per_address: usize, idle: Duration) -> Gcs {
    let mut c = config();
    c.router.tcp_max_peers = max_peers;
    c.router.tcp_peers_per_address = per_address;
    c.router.tcp_idle = idle;
    Gcs::start(c).await.unwrap()
}

/// A connection to `to` from the loopback address `127.0.0.<host>`.
async fn connect(host: u8, to: SocketAddr) -> TcpStream {
    let socket = TcpSocket::new_v4().unwrap();
    socket
        .bind(SocketAddr::from(([127, 0, 0, host], 0)))
        .unwrap();
    socket.connect(to).await.unwrap()
}

/// Waits (up to 10 s, a bound, not the condition) until the router closes
/// `stream`; true if it did.
async fn closed(stream: &mut TcpStream) -> bool {
    let mut buf = [0u8; 256];
    let read = async {
        loop {
            match stream.read(&mut buf).await {
                Ok(0) | Err(_) => return,
                Ok(_) => {}
            }
        }
    };
    tokio::time::timeout(Duration::from_secs(10), read)
        .await
        .is_ok()
}

/// Sends a valid message (a channel request; the station is
/// unauthenticated) and reads the router's answer.
async fn prove(stream: &mut TcpStream) {
    let mut frame = Vec::new();
    let request = envelope(
        "tool",
        mech_proto::ROUTER,
        "",
        1,
        Body::ChannelsRequest(ChannelsRequest {}),
    );
    write_stream_frame(&request, &mut frame).unwrap();
    stream.write_all(&frame).await.unwrap();
    let mut decoder = StreamDecoder::new();
    let mut buf = [0u8; 4096];
    loop {
        if let Some(m) = decoder.next_message() {
            assert!(matches!(m.unwrap().body, Body::Channels(_)));
            return;
        }
        let n = tokio::time::timeout(Duration::from_secs(5), stream.read(&mut buf))
            .await
            .unwrap()
            .unwrap();
        assert!(n > 0, "the router closed a peer that sent a valid message");
        decoder.push(&buf[..n]);
    }
}

#[tokio::test]
async fn a_peer_that_sends_nothing_valid_is_closed_after_tcp_idle() {
    let gcs = gcs(16, 16, Duration::from_millis(300)).await;
    let to = gcs.router().tcp_addr().unwrap();
    let mut idle = connect(1, to).await;
    let mut garbage = connect(1, to).await;
    garbage.write_all(&[0, 0, 0, 2, 0x99, 0x01]).await.unwrap();
    let mut proven = connect(1, to).await;
    prove(&mut proven).await;
    assert!(closed(&mut idle).await, "an idle peer is closed");
    assert!(closed(&mut garbage).await, "so is one that sent garbage");
    // Long after the deadline, the peer that sent a valid message is
    // still served.
    prove(&mut proven).await;
    gcs.shutdown().await;
}

#[tokio::test]
async fn a_new_peer_takes_the_place_of_the_oldest_stranger() {
    let gcs = gcs(4, 2, Duration::from_secs(60)).await;
    let to = gcs.router().tcp_addr().unwrap();
    // An address's share: the third from 127.0.0.2 closes its first.
    let mut first = connect(2, to).await;
    let mut second = connect(2, to).await;
    let mut third = connect(2, to).await;
    assert!(closed(&mut first).await);
    prove(&mut third).await;
    // The budget (4): 127.0.0.3 fills it; a controller from 127.0.0.4
    // closes the oldest stranger (127.0.0.2's second), not the proven.
    let mut a = connect(3, to).await;
    let mut b = connect(3, to).await;
    let mut controller = connect(4, to).await;
    prove(&mut controller).await;
    assert!(closed(&mut second).await);
    prove(&mut third).await;
    prove(&mut a).await;
    // Every peer proven but one: a newcomer closes that one; with all
    // four proven, the next newcomer is turned away.
    let mut d = connect(4, to).await;
    prove(&mut d).await;
    assert!(closed(&mut b).await);
    let mut turned_away = connect(5, to).await;
    assert!(closed(&mut turned_away).await);
    for p in [&mut third, &mut a, &mut controller, &mut d] {
        prove(p).await;
    }
    gcs.shutdown().await;
}

/// A peer that asks and does not read holds at most the router's byte cap
/// of answers queued (4 MiB), however few frames that is: 800 channel
/// listings of about 30 KB each (24 MB, far below the queue's 4,096
/// frames) are refused past it, counted, and the peer is still served.
#[tokio::test]
async fn a_peer_that_asks_without_reading_is_queued_a_bounded_number_of_bytes() {
    let gcs = gcs(16, 16, Duration::from_secs(60)).await;
    let router = gcs.router().clone();
    // 400 live channels with long names make each listing about 30 KB.
    let udp = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    for k in 0..400 {
        let channel = format!("ext/{k:0>40}");
        let twist = Body::Command(mech_proto::Command::Twist(mech_proto::Twist::default()));
        let m = envelope("tool", "robot_1", &channel, k, twist);
        udp.send_to(&mech_proto::encode(&m).unwrap(), router.udp_addr())
            .unwrap();
    }
    tokio::time::sleep(Duration::from_millis(300)).await;
    let mut stream = connect(6, router.tcp_addr().unwrap()).await;
    let mut frames = Vec::new();
    for seq in 0..800 {
        let request = envelope(
            "tool",
            mech_proto::ROUTER,
            "",
            seq,
            Body::ChannelsRequest(ChannelsRequest {}),
        );
        write_stream_frame(&request, &mut frames).unwrap();
    }
    stream.write_all(&frames).await.unwrap();
    // Wait (a bound, not the condition) until the router has answered or
    // refused all 800.
    let mut dropped = 0;
    for _ in 0..100 {
        dropped = router.counters().fanout_dropped;
        if dropped > 0 && router.counters().received >= 1200 {
            break;
        }
        tokio::time::sleep(Duration::from_millis(100)).await;
    }
    assert!(dropped > 0, "answers past 4 MiB are refused and counted");
    // Reading now: what was queued arrives, and the peer is still served.
    let mut buf = vec![0u8; 1 << 20];
    let mut got = 0usize;
    while let Ok(Ok(n)) =
        tokio::time::timeout(Duration::from_millis(500), stream.read(&mut buf)).await
    {
        if n == 0 {
            break;
        }
        got += n;
    }
    assert!(got > 0 && got < 24 << 20, "{got} bytes");
    prove(&mut stream).await;
    gcs.shutdown().await;
}
