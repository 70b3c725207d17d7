//! The simulated fleet API the GCS demo uses: many agents, one process,
//! real UDP sockets on loopback.
#![allow(clippy::unwrap_used)]

use std::collections::BTreeSet;
use std::time::Duration;

use mech_agent::sim::{Arena, SimFleet, SimFleetOptions};
use mech_proto::{Body, Envelope, Header, Route, Welcome};
use tokio::net::UdpSocket;

async fn recv(sock: &UdpSocket) -> (Envelope, std::net::SocketAddr) {
    let mut buf = vec![0; 65536];
    let (n, from) = tokio::time::timeout(Duration::from_secs(5), sock.recv_from(&mut buf))
        .await
        .unwrap()
        .unwrap();
    (mech_proto::decode(&buf[..n]).unwrap(), from)
}

#[tokio::test]
async fn fleet_registers_reports_and_says_bye() {
    let router = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let n = 6;
    let fleet = SimFleet::spawn(
        n,
        router.local_addr().unwrap(),
        Arena::default(),
        SimFleetOptions::default(),
    )
    .await
    .unwrap();
    let names = fleet.names();
    assert_eq!(names.len(), n);
    assert_eq!(names[0], "robot_1");

    let mut hellos = BTreeSet::new();
    let mut platforms = BTreeSet::new();
    while hellos.len() < n {
        let (env, from) = recv(&router).await;
        if let Body::Hello(h) = env.body {
            platforms.insert(h.platform.clone());
            if hellos.insert(h.name.clone()) {
                let welcome = Envelope::new(
                    Header {
                        sender: "router".into(),
                        destination: h.name.clone(),
                        ..Header::default()
                    },
                    Body::Welcome(Welcome {
                        robot_id: 1,
                        route: Route {
                            robot: h.name.clone(),
                            channel: String::new(),
                            epoch: 0,
                        },
                        router_version: "test".into(),
                    }),
                );
                router
                    .send_to(&mech_proto::encode(&welcome).unwrap(), from)
                    .await
                    .unwrap();
            }
        }
    }
    assert_eq!(
        platforms,
        ["diff-drive", "kiwi", "quadcopter"]
            .map(String::from)
            .into_iter()
            .collect()
    );

    // Registered robots report telemetry at their rate.
    let mut telemetry = BTreeSet::new();
    while telemetry.len() < n {
        let (env, _) = recv(&router).await;
        if let Body::Telemetry(_) = env.body {
            telemetry.insert(env.header.sender);
        }
    }

    fleet.shutdown().await;
    let mut byes = BTreeSet::new();
    while byes.len() < n {
        let (env, _) = recv(&router).await;
        if let Body::Bye(_) = env.body {
            byes.insert(env.header.sender);
        }
    }
}

#[test]
fn start_poses_are_inside_the_arena_and_distinct() {
    let arena = Arena {
        min_x: -2.0,
        min_y: 1.0,
        max_x: 2.0,
        max_y: 3.0,
    };
    let poses: Vec<_> = (0..50).map(|i| arena.start_pose(i, 50)).collect();
    for p in &poses {
        assert!(
            p.x > arena.min_x && p.x < arena.max_x && p.y > arena.min_y && p.y < arena.max_y,
            "{p:?}"
        );
    }
    for (i, a) in poses.iter().enumerate() {
        for b in &poses[i + 1..] {
            assert!((a.x - b.x).hypot(a.y - b.y) > 0.05);
        }
    }
}
