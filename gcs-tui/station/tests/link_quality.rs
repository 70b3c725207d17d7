//! Link quality as the router measures it, over real loopback sockets: a
//! small userspace UDP proxy in front of one simulated robot drops a fifth
//! of what that robot sends, and the router's figure for it must read that
//! loss while the robots talking to it directly read none.
//!
//! The proxy drops in the robot -> router direction only: that is the
//! direction the router measures loss in (from the gaps in the robot's own
//! sequence numbers), so the reading can be checked against exactly what
//! was dropped. The router -> robot direction passes untouched, so the
//! robot keeps hearing the router's heartbeats and stays registered.
//!
//! It drops one datagram in every five, at a random place within each
//! block of five: exactly 20 % over any stretch of whole blocks, in no
//! fixed pattern. (Independent 20 % coin flips would scatter the count over
//! the router's five-second window by about four points either way, which a
//! check at +/- 5 points would trip on now and then.)
//!
//! The robot's message rate is checked against what the proxy passed in
//! the router's window, not against the other robots' rates: simulated
//! robots on a loaded machine each lose ticks of their own.

#![allow(clippy::unwrap_used)]

use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use mech_agent::AgentSettings;
use mech_agent::links::LinkChoice;
use mech_agent::platform::PlatformSpec;
use mech_agent::runtime::{self, Io, Ticker};
use mech_agent::sim::{Arena, SimAgent, SimFleet, SimFleetOptions};
use mech_core::{CoreConfig, Event, Gcs, LinkQuality};
use rand::Rng;
use tokio::net::UdpSocket;
use tokio::sync::watch;

/// Datagrams the proxy passed on and dropped, robot -> router.
#[derive(Debug)]
struct ProxyCounts {
    passed: AtomicU64,
    dropped: AtomicU64,
    /// When each passed datagram went on, in router time (since the
    /// router started, as its events are stamped).
    passed_at: Mutex<Vec<Duration>>,
    /// Router time 0.
    origin: tokio::time::Instant,
}

impl ProxyCounts {
    fn new(origin: tokio::time::Instant) -> ProxyCounts {
        ProxyCounts {
            passed: AtomicU64::new(0),
            dropped: AtomicU64::new(0),
            passed_at: Mutex::new(Vec::new()),
            origin,
        }
    }

    /// Datagrams passed on per second in the router-time span `(from, to]`.
    fn passed_hz(&self, from: Duration, to: Duration) -> f64 {
        let at = self.passed_at.lock().unwrap();
        let n = at
            .iter()
            .filter(|t| (from..=to).contains(*t) && **t != from);
        n.count() as f64 / (to - from).as_secs_f64()
    }
}

/// A UDP proxy between one robot and the router: the robot sends to
/// `front`, the proxy sends on from `back` (so the router sees `back` as
/// the robot's address) and relays the router's replies to the robot.
async fn lossy_proxy(
    router: SocketAddr,
    counts: Arc<ProxyCounts>,
    mut stop: watch::Receiver<bool>,
) -> SocketAddr {
    let front = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let back = UdpSocket::bind("127.0.0.1:0").await.unwrap();
    let addr = front.local_addr().unwrap();
    tokio::spawn(async move {
        let mut robot: Option<SocketAddr> = None;
        let (mut up, mut down) = (vec![0u8; 65_536], vec![0u8; 65_536]);
        let (mut in_block, mut drop_at) = (0u32, rand::rng().random_range(0..5));
        loop {
            tokio::select! {
                _ = stop.changed() => return,
                got = front.recv_from(&mut up) => {
                    let Ok((n, from)) = got else { continue };
                    robot = Some(from);
                    let drop_it = in_block == drop_at;
                    in_block += 1;
                    if in_block == 5 {
                        in_block = 0;
                        drop_at = rand::rng().random_range(0..5);
                    }
                    if drop_it {
                        counts.dropped.fetch_add(1, Ordering::Relaxed);
                    } else {
                        counts.passed.fetch_add(1, Ordering::Relaxed);
                        counts.passed_at.lock().unwrap().push(counts.origin.elapsed());
                        let _ = back.send_to(&up[..n], router).await;
                    }
                }
                got = back.recv_from(&mut down) => {
                    let (Ok((n, _)), Some(to)) = (got, robot) else { continue };
                    let _ = front.send_to(&down[..n], to).await;
                }
            }
        }
    });
    addr
}

/// One simulated diff-drive robot named `name`, talking to `router`.
async fn robot(name: &str, router: SocketAddr, stop: watch::Receiver<bool>) {
    let sim = SimAgent::new(
        AgentSettings::new(name),
        &PlatformSpec::diff_drive(),
        Arena::default().start_pose(0, 1),
        None,
        mech_proto::unix_micros(),
    );
    let io = Io::Udp {
        socket: UdpSocket::bind("127.0.0.1:0").await.unwrap(),
        router,
    };
    let origin = tokio::time::Instant::now();
    let ticker = Ticker::Own(Duration::from_millis(50));
    tokio::spawn(runtime::drive(sim, io, ticker, origin, stop));
}

fn quality(gcs: &Gcs, robot: &str) -> Option<LinkQuality> {
    gcs.with_fleet(|f| f.robot(robot).map(|r| r.quality))
}

/// `robot`'s first link-quality report whose figures cover the router's
/// full five seconds, and the router time its window ends at (the
/// report's stamp).
async fn full_window(
    gcs: &Gcs,
    events: &mut mech_core::router::Subscription,
    robot: &str,
) -> (LinkQuality, Duration) {
    tokio::time::timeout(Duration::from_secs(60), async {
        loop {
            let ev = events.recv().await.expect("the router runs");
            match &ev.event {
                Event::LinkQuality { robot: r, quality }
                    if r == robot && quality.window >= Duration::from_secs(5) =>
                {
                    break (*quality, ev.at);
                }
                _ => {}
            }
        }
    })
    .await
    .unwrap_or_else(|_| {
        panic!(
            "{robot}'s link measured over 5 s: {:?}",
            quality(gcs, robot)
        )
    })
}

/// The robots on the router directly read no loss.
fn direct_robots_read_no_loss(gcs: &Gcs, fleet: &SimFleet) {
    for name in fleet.names() {
        let q = quality(gcs, &name).expect("registered");
        let loss = q.loss.expect("it sent in the window");
        println!(
            "{name} direct: loss {:.1}%, rx {:.1}/s, rtt {}",
            loss * 100.0,
            q.rx_hz,
            q.rtt_text()
        );
        assert!(loss < 0.01, "{name} reads about 0: {q:?}");
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_robot_behind_a_lossy_proxy_reads_its_loss_the_others_none() {
    let mut config = CoreConfig::default();
    config.router.udp = SocketAddr::from(([127, 0, 0, 1], 0));
    config.router.tcp = None;
    let gcs = Gcs::start(config).await.unwrap();
    let router = gcs.router().udp_addr();
    let origin = tokio::time::Instant::now() - gcs.router().elapsed();
    let mut events = gcs.router().subscribe(100_000, true);
    let (stop, stopped) = watch::channel(false);

    let options = SimFleetOptions {
        noise: false,
        ..SimFleetOptions::default()
    };
    let fleet = SimFleet::spawn(3, router, Arena::default(), options)
        .await
        .unwrap();
    let counts = Arc::new(ProxyCounts::new(origin));
    let proxy = lossy_proxy(router, counts.clone(), stopped.clone()).await;
    robot("robot_9", proxy, stopped.clone()).await;

    let (lossy, at) = full_window(&gcs, &mut events, "robot_9").await;
    assert_eq!(events.dropped(), 0, "every report seen");
    let (passed, dropped) = (
        counts.passed.load(Ordering::Relaxed),
        counts.dropped.load(Ordering::Relaxed),
    );
    let loss = lossy.loss.expect("robot_9 sent in the window");
    println!(
        "robot_9 behind the proxy: loss {:.1}% ({dropped} of {} dropped so far), rx {:.1}/s, tx {:.1}/s, rtt {}",
        loss * 100.0,
        passed + dropped,
        lossy.rx_hz,
        lossy.tx_hz,
        lossy.rtt_text()
    );
    assert!(
        (loss - 0.20).abs() <= 0.05,
        "robot_9 reads 20 % +/- 5: {lossy:?}"
    );
    assert!(lossy.rtt.is_some(), "echoes get through: {lossy:?}");
    // Its rate is what reached the router: four fifths of what it sent,
    // the datagrams the proxy passed on in the same window. The router
    // counts a datagram when it handles it, a moment after the proxy
    // passed it: on a loaded machine one or two at each end of the window
    // fall on the other side (counting what the robot sent instead would
    // be a quarter more).
    let passed_hz = counts.passed_hz(at.saturating_sub(lossy.window), at);
    println!(
        "robot_9: {:.2}/s through the proxy in the window, {:.2}/s read",
        passed_hz, lossy.rx_hz
    );
    assert!(
        (lossy.rx_hz - passed_hz).abs() <= 3.0 / lossy.window.as_secs_f64(),
        "robot_9 {:.2}/s read, {passed_hz:.2}/s passed",
        lossy.rx_hz
    );

    direct_robots_read_no_loss(&gcs, &fleet);
    let _ = stop.send(true);
    fleet.shutdown().await;
    gcs.shutdown().await;
}

/// A robot whose only link caps its telemetry at 5 Hz (as a radio's
/// `telemetry_rate_hz` does) while it samples at 20 Hz: the samples the
/// link skips on purpose are not lost, so its loss reads 0 %, not 75 %.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_robot_whose_link_caps_its_telemetry_reads_no_loss() {
    let mut config = CoreConfig::default();
    config.router.udp = SocketAddr::from(([127, 0, 0, 1], 0));
    config.router.tcp = None;
    let gcs = Gcs::start(config).await.unwrap();
    let router = gcs.router().udp_addr();
    let (stop, stopped) = watch::channel(false);
    let sim = SimAgent::new(
        AgentSettings::new("radio_1"),
        &PlatformSpec::diff_drive(),
        Arena::default().start_pose(0, 1),
        None,
        mech_proto::unix_micros(),
    );
    let link = Io::Udp {
        socket: UdpSocket::bind("127.0.0.1:0").await.unwrap(),
        router,
    };
    let ms = Duration::from_millis;
    let io = Io::Failover {
        links: vec![link],
        choice: LinkChoice::new(vec![Some(ms(200))], ms(600), ms(250)),
        closed: vec![false],
    };
    let origin = tokio::time::Instant::now();
    tokio::spawn(runtime::drive(
        sim,
        io,
        Ticker::Own(ms(50)),
        origin,
        stopped,
    ));

    let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
    let q = loop {
        if let Some(q) = quality(&gcs, "radio_1").filter(|q| q.window >= Duration::from_secs(5)) {
            break q;
        }
        assert!(
            tokio::time::Instant::now() < deadline,
            "radio_1's link measured over 5 s: {:?}",
            quality(&gcs, "radio_1")
        );
        tokio::time::sleep(ms(100)).await;
    };
    println!(
        "radio_1 capped at 5 Hz: loss {}, rx {:.1}/s",
        q.loss_text(),
        q.rx_hz
    );
    assert_eq!(q.loss, Some(0.0), "{q:?}");
    assert_eq!(q.lost, 0, "{q:?}");
    // Telemetry at the cap and a heartbeat a second.
    assert!(q.rx_hz > 4.0 && q.rx_hz < 7.0, "{q:?}");
    let _ = stop.send(true);
    gcs.shutdown().await;
}
