//! What the Foxglove live view costs and delivers: `mech-gcs serve --demo N
//! --foxglove 127.0.0.1:0` (N simulated robots in the station's process,
//! 20 Hz telemetry each), its CPU over a window with no client, then with
//! one client subscribed to every channel, and the messages and bytes a
//! second that client got, and the live view's totals as the station logs
//! them when it stops (router events dropped, client messages dropped).
//! Prints numbers; asserts nothing.
//!
//! `cargo bench -p mech-gcs --features foxglove --bench foxglove [-- ROBOTS SECONDS]`

use std::io::{BufRead, BufReader};
use std::net::SocketAddr;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use futures::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio_tungstenite::tungstenite::Message;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;
use tokio_tungstenite::tungstenite::http::HeaderValue;

/// CPU time (user + system) of process `pid` so far, in clock ticks.
fn cpu_ticks(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    // Fields after the command name (which is in parentheses).
    let rest = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<u64> = rest
        .split_whitespace()
        .map(|x| x.parse().unwrap_or(0))
        .collect();
    f.get(11).copied().unwrap_or(0) + f.get(12).copied().unwrap_or(0)
}

/// Percent of one core the process used while `wait` ran.
async fn cpu_during<T>(pid: u32, wait: impl std::future::Future<Output = T>) -> (f64, T) {
    let ticks = 100.0; // USER_HZ on Linux
    let (c0, t0) = (cpu_ticks(pid), Instant::now());
    let out = wait.await;
    let used = (cpu_ticks(pid) - c0) as f64 / ticks;
    (100.0 * used / t0.elapsed().as_secs_f64(), out)
}

fn start(robots: usize, dir: &std::path::Path) -> (Child, SocketAddr) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_mech-gcs"))
        .args([
            "serve",
            "--demo",
            &robots.to_string(),
            "--udp",
            "127.0.0.1:0",
        ])
        .args([
            "--tcp",
            "127.0.0.1:0",
            "--foxglove",
            "127.0.0.1:0",
            "--socket",
        ])
        .arg(dir.join("gcs.sock"))
        .env("XDG_STATE_HOME", dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("mech-gcs serve starts");
    let mut lines = BufReader::new(child.stdout.take().expect("stdout")).lines();
    let line = lines.next().and_then(Result::ok).expect("ready line");
    std::thread::spawn(move || for _ in lines {});
    let addr = line
        .split("Foxglove live view on ws://")
        .nth(1)
        .and_then(|a| a.trim().parse().ok())
        .expect("live view address");
    (child, addr)
}

type Ws = tokio_tungstenite::WebSocketStream<tokio::net::TcpStream>;

/// A client subscribed to every channel advertised within 3 s; with the
/// number of channels.
async fn subscribe_all(addr: SocketAddr) -> (Ws, usize) {
    let tcp = tokio::net::TcpStream::connect(addr).await.expect("connect");
    let mut req = format!("ws://{addr}/")
        .into_client_request()
        .expect("request");
    req.headers_mut().insert(
        "Sec-WebSocket-Protocol",
        HeaderValue::from_static("foxglove.websocket.v1"),
    );
    let (mut ws, _) = tokio_tungstenite::client_async(req, tcp)
        .await
        .expect("handshake");
    let mut ids = Vec::new();
    let settle = Instant::now() + Duration::from_secs(3);
    while Instant::now() < settle {
        if let Ok(Some(Ok(Message::Text(t)))) =
            tokio::time::timeout(Duration::from_millis(200), ws.next()).await
        {
            let v: Value = serde_json::from_str(t.as_str()).unwrap_or(Value::Null);
            for ch in v["channels"].as_array().into_iter().flatten() {
                ids.push(ch["id"].clone());
            }
        }
    }
    let subs: Vec<Value> = ids
        .iter()
        .enumerate()
        .map(|(i, id)| json!({"id": i, "channelId": id}))
        .collect();
    let subscribe = json!({"op": "subscribe", "subscriptions": subs}).to_string();
    ws.send(Message::Text(subscribe.into()))
        .await
        .expect("sent");
    (ws, ids.len())
}

/// Message-data frames and their bytes received during `window`.
async fn count(ws: &mut Ws, window: Duration) -> (u64, u64) {
    let (mut msgs, mut bytes) = (0u64, 0u64);
    let end = tokio::time::Instant::now() + window;
    while let Ok(Some(Ok(m))) = tokio::time::timeout_at(end, ws.next()).await {
        if let Message::Binary(b) = m {
            msgs += 1;
            bytes += b.len() as u64;
        }
    }
    (msgs, bytes)
}

/// Stops the station with SIGTERM, so it logs the live view's totals
/// (events taken and dropped, messages sent and dropped per client
/// queue), and prints them.
fn stop_and_print_totals(mut station: Child, dir: &std::path::Path) {
    let _ = Command::new("kill")
        .args(["-TERM", &station.id().to_string()])
        .status();
    let _ = station.wait();
    let logs = std::fs::read_dir(dir.join("mech"))
        .into_iter()
        .flatten()
        .flatten()
        .filter_map(|e| std::fs::read_to_string(e.path()).ok());
    for text in logs {
        for line in text.lines() {
            if line.contains("Foxglove live view stopped") {
                println!("{line}");
            }
        }
    }
}

#[tokio::main(flavor = "current_thread")]
async fn main() {
    let args: Vec<usize> = std::env::args()
        .skip(1)
        .filter_map(|a| a.parse().ok())
        .collect();
    let robots = args.first().copied().unwrap_or(100);
    let window = Duration::from_secs(args.get(1).copied().unwrap_or(10) as u64);
    let dir = std::env::temp_dir().join(format!("mech-bench-foxglove-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let (station, addr) = start(robots, &dir);
    let pid = station.id();
    // Let every robot connect and settle.
    tokio::time::sleep(Duration::from_secs(5)).await;
    let (idle, ()) = cpu_during(pid, tokio::time::sleep(window)).await;
    let (mut ws, channels) = subscribe_all(addr).await;
    let (busy, (msgs, bytes)) = cpu_during(pid, count(&mut ws, window)).await;
    let secs = window.as_secs_f64();
    println!(
        "foxglove live view, {robots} robots x 20 Hz, {channels} channels subscribed: \
         {:.0} msg/s, {:.0} KB/s to one client; station CPU {idle:.1}% of a core with no \
         client, {busy:.1}% with one",
        msgs as f64 / secs,
        bytes as f64 / secs / 1000.0
    );
    stop_and_print_totals(station, &dir);
    let _ = std::fs::remove_dir_all(&dir);
}
