//! A minimal agent and controller speaking raw mech-proto datagrams, so the
//! router is tested over real loopback sockets without the real agent.

#![allow(dead_code)]

use std::net::SocketAddr;
use std::time::Duration;

use mech_core::CoreConfig;
use mech_proto::auth::{Key, Stamper};
use mech_proto::{
    Body, Command, CommandKind, Computation, ControlMode, Envelope, FailsafeState, Header, Health,
    Hello, MissionProgress, Pose, RouteAck, Telemetry, Twist, Velocity,
};
use tokio::net::UdpSocket;

/// A router config bound to loopback ephemeral ports, without file logs.
pub fn config() -> CoreConfig {
    let mut c = CoreConfig::default();
    c.router.udp = "127.0.0.1:0".parse().unwrap();
    c.router.tcp = Some("127.0.0.1:0".parse().unwrap());
    c
}

/// One peer of the router: a robot or a controller, with its own socket.
#[derive(Debug)]
pub struct Peer {
    pub name: String,
    pub sock: UdpSocket,
    pub router: SocketAddr,
    seq: u32,
    /// Route the agent applied (from Welcome or Route).
    pub route: String,
    pub epoch: u32,
    /// Signs what it sends when set.
    pub key: Option<Key>,
    stamper: Stamper,
}

pub fn envelope(sender: &str, destination: &str, channel: &str, seq: u32, body: Body) -> Envelope {
    Envelope::new(
        Header {
            seq,
            stamp_us: 0,
            sender: sender.into(),
            destination: destination.into(),
            channel: channel.into(),
        },
        body,
    )
}

pub fn twist(vx: f64) -> Command {
    Command::Twist(Twist {
        vx,
        vy: 0.0,
        vz: 0.0,
        wz: 0.0,
    })
}

pub fn telemetry(x: f64, y: f64, channel: &str, mission: Option<MissionProgress>) -> Telemetry {
    Telemetry {
        pose: Pose {
            x,
            y,
            z: 0.0,
            heading: 0.0,
        },
        velocity: Velocity::default(),
        mode: ControlMode::Idle,
        channel: channel.into(),
        computation: Computation::Onboard,
        failsafe: FailsafeState::Ok,
        health: Health::Ok,
        battery: Some(0.9),
        position_quality: 1.0,
        actuators: vec![0.0, 0.0],
        mission,
        stale: 0,
        velocity_source: mech_proto::VelocitySource::Commanded,
        safety: None,
    }
}

impl Peer {
    pub async fn new(name: &str, router: SocketAddr) -> Peer {
        let sock = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        Peer {
            name: name.into(),
            sock,
            router,
            seq: 0,
            route: String::new(),
            epoch: 0,
            key: None,
            stamper: Stamper::default(),
        }
    }

    /// A peer that signs everything with `key` (stamps from the wall clock,
    /// as a machine with network time does).
    pub async fn signed(name: &str, router: SocketAddr, key: Key) -> Peer {
        let mut p = Peer::new(name, router).await;
        p.key = Some(key);
        p
    }

    /// Encodes a message as this peer sends it (signed if it has a key).
    pub fn encode(&mut self, destination: &str, channel: &str, seq: u32, body: Body) -> Vec<u8> {
        let mut bytes =
            mech_proto::encode(&envelope(&self.name, destination, channel, seq, body)).unwrap();
        if let Some(key) = &self.key {
            let stamp = self.stamper.next(mech_proto::unix_micros());
            key.seal(&mut bytes, 0, stamp).unwrap();
        }
        bytes
    }

    pub fn addr(&self) -> SocketAddr {
        self.sock.local_addr().unwrap()
    }

    /// Sends a message; returns its sequence number.
    pub async fn send(&mut self, destination: &str, channel: &str, body: Body) -> u32 {
        self.seq += 1;
        let bytes = self.encode(destination, channel, self.seq, body);
        self.sock.send_to(&bytes, self.router).await.unwrap();
        self.seq
    }

    pub async fn send_raw(&self, bytes: &[u8]) {
        self.sock.send_to(bytes, self.router).await.unwrap();
    }

    /// A command on `channel` for `robot`; returns its sequence number.
    pub async fn command(&mut self, robot: &str, channel: &str, vx: f64) -> u32 {
        self.send(robot, channel, Body::Command(twist(vx))).await
    }

    pub async fn hello(&mut self) {
        let hello = Hello {
            name: self.name.clone(),
            platform: "diff-drive".into(),
            capabilities: vec![
                CommandKind::Twist,
                CommandKind::VelocityHeading,
                CommandKind::Waypoints,
                CommandKind::Stop,
            ],
            motors: 2,
            max_speed: 1.0,
            max_yaw_rate: 2.0,
            agent_version: "test".into(),
        };
        self.send(mech_proto::ROUTER, "", Body::Hello(hello)).await;
    }

    /// Next message, within `limit` (tokio time).
    pub async fn recv_within(&self, limit: Duration) -> Option<Envelope> {
        let mut buf = vec![0u8; 65_536];
        let (n, _) = tokio::time::timeout(limit, self.sock.recv_from(&mut buf))
            .await
            .ok()?
            .unwrap();
        Some(mech_proto::decode(&buf[..n]).unwrap())
    }

    pub async fn recv(&self) -> Envelope {
        self.recv_within(Duration::from_secs(3))
            .await
            .expect("a message from the router")
    }

    /// Next message that is not a heartbeat (route/e-stop repeats included).
    pub async fn recv_skip_heartbeats(&self) -> Envelope {
        loop {
            let env = self.recv().await;
            if !matches!(env.body, Body::Heartbeat(_)) {
                return env;
            }
        }
    }

    /// Next message matching `pred`, skipping others.
    pub async fn recv_matching(&self, pred: impl Fn(&Envelope) -> bool) -> Envelope {
        loop {
            let env = self.recv().await;
            if pred(&env) {
                return env;
            }
        }
    }

    /// Messages already queued, without waiting.
    pub fn drain(&self) -> Vec<Envelope> {
        let mut out = Vec::new();
        let mut buf = vec![0u8; 65_536];
        while let Ok((n, _)) = self.sock.try_recv_from(&mut buf) {
            out.push(mech_proto::decode(&buf[..n]).unwrap());
        }
        out
    }

    /// Hello, wait for Welcome, apply and acknowledge its route.
    pub async fn register(&mut self) {
        self.hello().await;
        let env = self
            .recv_matching(|e| matches!(e.body, Body::Welcome(_)))
            .await;
        let Body::Welcome(w) = env.body else {
            unreachable!()
        };
        self.ack_route(&w.route.channel, w.route.epoch).await;
    }

    pub async fn ack_route(&mut self, channel: &str, epoch: u32) {
        self.route = channel.into();
        self.epoch = epoch;
        let ack = RouteAck {
            robot: self.name.clone(),
            channel: channel.into(),
            epoch,
        };
        self.send(mech_proto::ROUTER, "", Body::RouteAck(ack)).await;
    }

    /// Waits for a Route message and acknowledges it.
    pub async fn follow_route(&mut self) -> String {
        let env = self
            .recv_matching(|e| matches!(e.body, Body::Route(_)))
            .await;
        let Body::Route(r) = env.body else {
            unreachable!()
        };
        self.ack_route(&r.channel, r.epoch).await;
        r.channel
    }

    pub async fn send_telemetry(&mut self, t: Telemetry) {
        self.send(mech_proto::ROUTER, "", Body::Telemetry(t)).await;
    }
}

/// Polls `f` (every 5 ms of tokio time) until it returns true or `limit`
/// passes.
pub async fn eventually(limit: Duration, mut f: impl FnMut() -> bool) -> bool {
    let deadline = tokio::time::Instant::now() + limit;
    while tokio::time::Instant::now() < deadline {
        if f() {
            return true;
        }
        tokio::time::sleep(Duration::from_millis(5)).await;
    }
    f()
}
