//! A minimal router for measuring an agent alone: welcomes every robot that
//! says Hello (routed to no channel), sends each a heartbeat every 250 ms,
//! and prints the telemetry rate it receives every 5 s.
//!
//! `cargo run --release -p mech-agent --example tiny_router [127.0.0.1:7400]`

use std::collections::HashMap;
use std::net::{SocketAddr, UdpSocket};
use std::time::{Duration, Instant};

use mech_proto::{Body, Envelope, Header, Heartbeat, Route, Welcome};

fn main() -> std::io::Result<()> {
    let addr = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "127.0.0.1:7400".into());
    let socket = UdpSocket::bind(&addr)?;
    socket.set_read_timeout(Some(Duration::from_millis(50)))?;
    println!("tiny router on {}", socket.local_addr()?);
    let mut robots: HashMap<String, SocketAddr> = HashMap::new();
    let mut telemetry = 0u64;
    let mut buf = vec![0u8; 65536];
    let (mut next_heartbeat, mut next_report) =
        (Instant::now(), Instant::now() + Duration::from_secs(5));
    let send = |to: SocketAddr, dest: &str, body: Body| {
        let env = Envelope::new(
            Header {
                sender: "router".into(),
                destination: dest.into(),
                ..Header::default()
            },
            body,
        );
        if let Ok(bytes) = mech_proto::encode(&env) {
            let _ = socket.send_to(&bytes, to);
        }
    };
    loop {
        if let Ok((n, from)) = socket.recv_from(&mut buf) {
            match mech_proto::decode(&buf[..n]).map(|e| e.body) {
                Ok(Body::Hello(h)) => {
                    let route = Route {
                        robot: h.name.clone(),
                        channel: String::new(),
                        epoch: 0,
                    };
                    send(
                        from,
                        &h.name,
                        Body::Welcome(Welcome {
                            robot_id: robots.len() as u16,
                            route,
                            router_version: "tiny".into(),
                        }),
                    );
                    robots.insert(h.name, from);
                }
                Ok(Body::Telemetry(_)) => telemetry += 1,
                _ => {}
            }
        }
        let now = Instant::now();
        if now >= next_heartbeat {
            next_heartbeat = now + Duration::from_millis(250);
            for (name, to) in &robots {
                send(*to, name, Body::Heartbeat(Heartbeat::new(0)));
            }
        }
        if now >= next_report {
            next_report = now + Duration::from_secs(5);
            println!(
                "{} robots, {:.1} telemetry/s",
                robots.len(),
                telemetry as f64 / 5.0
            );
            telemetry = 0;
        }
    }
}
