//! Order through the router, whatever the number of its workers.
//!
//! Commands reach a robot in the order their controller sent them: a
//! controller's datagrams are received, decided and sent on by one worker
//! (the kernel hashes each sender to one socket of the router's
//! `SO_REUSEPORT` group). Here one controller sends two hundred thousand
//! commands in bursts while other controllers keep the workers busy, and
//! the robot checks every sequence number it gets.
//!
//! Events reach the fleet model in the order the tables made them, though
//! they are delivered after the tables lock is released and several threads
//! decide at once: e-stops from many senders (spread over both workers) and
//! from the station's handle each take the next id, and the sink must see
//! the ids rising.

#![allow(clippy::unwrap_used)]

#[path = "support/agent.rs"]
mod agent;

use std::net::UdpSocket;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use agent::{Peer, envelope, twist};
use mech_core::{Event, EventSink, Gcs, Router, Stamped};
use mech_proto::{Body, EStop};

const COMMANDS: u32 = 200_000;
const BURST: u32 = 200;

/// A robot socket with a large receive buffer, read on a thread of its own:
/// returns (received, reordered, highest seq); `count` follows `received`.
fn robot_reader(
    sock: UdpSocket,
    from: &'static str,
    stop: Arc<AtomicBool>,
    count: Arc<AtomicU64>,
) -> std::thread::JoinHandle<(u64, u64, u32)> {
    std::thread::spawn(move || {
        sock.set_read_timeout(Some(Duration::from_millis(50)))
            .unwrap();
        let mut buf = vec![0u8; 2048];
        let (mut received, mut reordered, mut newest) = (0u64, 0u64, 0u32);
        loop {
            match sock.recv(&mut buf) {
                Ok(n) => {
                    let Ok(head) = mech_proto::peek(&buf[..n]) else {
                        continue;
                    };
                    if head.kind != mech_proto::COMMAND_KIND || head.sender != from {
                        continue;
                    }
                    received += 1;
                    count.store(received, Ordering::Relaxed);
                    if head.seq <= newest {
                        reordered += 1;
                    }
                    newest = newest.max(head.seq);
                }
                Err(_) if stop.load(Ordering::Relaxed) => return (received, reordered, newest),
                Err(_) => {}
            }
        }
    })
}

fn big_buffer(sock: &UdpSocket) {
    let s = socket2::SockRef::from(sock);
    let _ = s.set_recv_buffer_size(8 << 20);
    let _ = s.set_send_buffer_size(8 << 20);
}

/// Four controllers sending to `robot_2` on `ext/noise` until `stop`.
fn noise_controllers(
    router: std::net::SocketAddr,
    stop: &Arc<AtomicBool>,
) -> Vec<std::thread::JoinHandle<()>> {
    (0..4)
        .map(|i| {
            let stop = stop.clone();
            std::thread::spawn(move || {
                let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
                let name = format!("noise{i}");
                let mut seq = 0u32;
                while !stop.load(Ordering::Relaxed) {
                    for _ in 0..10 {
                        seq += 1;
                        let env = envelope(
                            &name,
                            "robot_2",
                            "ext/noise",
                            seq,
                            Body::Command(twist(0.1)),
                        );
                        let _ = sock.send_to(&mech_proto::encode(&env).unwrap(), router);
                    }
                    std::thread::sleep(Duration::from_millis(2));
                }
            })
        })
        .collect()
}

/// The ordered stream: [`COMMANDS`] commands to `robot_1` from controller
/// `burst`, numbered from 1, in bursts of [`BURST`].
fn send_in_bursts(router: std::net::SocketAddr, arrived: &AtomicU64) {
    let controller = UdpSocket::bind("127.0.0.1:0").unwrap();
    big_buffer(&controller);
    let mut seq = 0u32;
    while seq < COMMANDS {
        for _ in 0..BURST.min(COMMANDS - seq) {
            seq += 1;
            let env = envelope(
                "burst",
                "robot_1",
                "ext/burst",
                seq,
                Body::Command(twist(0.2)),
            );
            controller
                .send_to(&mech_proto::encode(&env).unwrap(), router)
                .unwrap();
        }
        // Bursts faster than the router empties them would be lost at its
        // socket (loss is not reordering, but it would leave little to
        // check): wait until the robot has most of them, or a moment.
        let waited = Instant::now();
        while u64::from(seq) - arrived.load(Ordering::Relaxed) > u64::from(2 * BURST)
            && waited.elapsed() < Duration::from_millis(20)
        {
            std::thread::sleep(Duration::from_micros(100));
        }
    }
}

#[test]
fn a_controllers_commands_arrive_in_order_with_both_workers_busy() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let mut config = agent::config();
    config.router.udp_workers = 2;
    let gcs: Gcs = rt.block_on(Gcs::start(config)).unwrap();
    let router = gcs.router().udp_addr();
    // Two robots: one for the ordered stream, one for the noise.
    let (robot, noisy) = rt.block_on(async {
        let mut robot = Peer::new("robot_1", router).await;
        robot.register().await;
        let mut noisy = Peer::new("robot_2", router).await;
        noisy.register().await;
        gcs.router()
            .set_route("robot_1", Some("ext/burst"))
            .await
            .unwrap();
        gcs.router()
            .set_route("robot_2", Some("ext/noise"))
            .await
            .unwrap();
        robot.follow_route().await;
        noisy.follow_route().await;
        (robot, noisy)
    });
    let robot_sock = robot.sock.into_std().unwrap();
    robot_sock.set_nonblocking(false).unwrap();
    big_buffer(&robot_sock);
    let stop = Arc::new(AtomicBool::new(false));
    let arrived = Arc::new(AtomicU64::new(0));
    let reader = robot_reader(robot_sock, "burst", stop.clone(), arrived.clone());
    // Other controllers keep the router's workers busy meanwhile.
    let noise = noise_controllers(router, &stop);
    let started = Instant::now();
    send_in_bursts(router, &arrived);
    std::thread::sleep(Duration::from_millis(500));
    stop.store(true, Ordering::Relaxed);
    for n in noise {
        n.join().unwrap();
    }
    let (received, reordered, newest) = reader.join().unwrap();
    eprintln!(
        "{COMMANDS} commands in {:.1} s: {received} received in order of {COMMANDS}, {reordered} reordered, newest {newest}",
        started.elapsed().as_secs_f64()
    );
    assert_eq!(reordered, 0, "commands overtook each other");
    assert!(
        received > u64::from(COMMANDS) / 2,
        "too few arrived to judge the order: {received}"
    );
    drop(noisy);
    rt.block_on(gcs.shutdown());
}

/// Records the id of every e-stop event, in the order it is applied, and
/// wakes whoever waits for a count of them.
#[derive(Debug, Default)]
struct EStopIds {
    ids: Mutex<Vec<u32>>,
    applied: Condvar,
}

impl EventSink for EStopIds {
    fn apply(&self, e: &Stamped) {
        if let Event::EStop { id, .. } = e.event {
            self.ids.lock().unwrap().push(id);
            self.applied.notify_all();
        }
    }
}

impl EStopIds {
    /// Waits (asleep, leaving the CPU to the router) until `done` holds
    /// for the number of e-stops applied; fails the test if that takes
    /// over a minute (a lost datagram: the router would never apply its
    /// e-stop).
    fn wait_until(&self, what: &str, done: impl Fn(u64) -> bool) {
        let started = Instant::now();
        let mut ids = self.ids.lock().unwrap();
        while !done(ids.len() as u64) {
            assert!(
                started.elapsed() < Duration::from_secs(60),
                "gave up waiting for {what}"
            );
            ids = self
                .applied
                .wait_timeout(ids, Duration::from_millis(100))
                .unwrap()
                .0;
        }
    }
}

const SENDERS: usize = 8;
const ESTOPS_EACH: u64 = 3_000;
const IN_FLIGHT: u64 = 64;

#[test]
fn events_reach_the_sink_in_the_order_the_tables_made_them_with_both_workers_deciding() {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let mut config = agent::config().router;
    config.udp_workers = 2;
    let sink = Arc::new(EStopIds::default());
    let router = rt
        .block_on(Router::start(config, None, sink.clone()))
        .unwrap();
    let handle = router.handle();
    let to = handle.udp_addr();
    // Each sender keeps a few e-stops in flight (so none is lost at the
    // router's socket) while the others, and the handle, send theirs.
    let senders: Vec<_> = (0..SENDERS)
        .map(|i| {
            let sink = sink.clone();
            std::thread::spawn(move || {
                let sock = UdpSocket::bind("127.0.0.1:0").unwrap();
                let name = format!("estop{i}");
                for seq in 1..=ESTOPS_EACH {
                    sink.wait_until("the router to keep up", |applied| {
                        seq <= applied / SENDERS as u64 + IN_FLIGHT
                    });
                    let body = Body::EStop(EStop {
                        engage: seq % 2 == 1,
                        id: 0,
                    });
                    let env = envelope(&name, "*", "", seq as u32, body);
                    sock.send_to(&mech_proto::encode(&env).unwrap(), to)
                        .unwrap();
                }
            })
        })
        .collect();
    let from_handle = 500;
    rt.block_on(async {
        for i in 0..from_handle {
            if i % 2 == 0 {
                handle.estop().await;
            } else {
                handle.release().await;
            }
        }
    });
    for s in senders {
        s.join().unwrap();
    }
    let total = SENDERS as u64 * ESTOPS_EACH + from_handle;
    sink.wait_until("every e-stop to be applied", |applied| applied >= total);
    rt.block_on(router.shutdown());
    let ids = sink.ids.lock().unwrap();
    let out_of_order = ids
        .windows(2)
        .filter(|w| w[1] != w[0].wrapping_add(1))
        .count();
    assert_eq!(ids.len() as u64, total);
    assert_eq!(
        out_of_order, 0,
        "e-stop ids applied out of the order the tables gave them"
    );
}
