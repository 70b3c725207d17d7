//! A userspace UDP proxy between agents and the station: each agent (each
//! source address) gets its own upstream socket, so the station sees one
//! address per agent, as without the proxy. Datagrams in either direction
//! can be delayed (a base delay plus uniform jitter, so they may overtake
//! each other), dropped at random, or all blocked (Wi-Fi gone).

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap};
use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex};
use std::time::{Duration, Instant};

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

/// What the proxy does to datagrams now (changeable while it runs).
#[derive(Debug, Default)]
pub struct Faults {
    pub blocked: AtomicBool,
    /// Base delay and jitter, µs: each datagram waits base ± jitter.
    pub delay_us: AtomicU64,
    pub jitter_us: AtomicU64,
    /// Drop probability, parts per million.
    pub loss_ppm: AtomicU64,
    /// Datagrams passed and dropped.
    pub passed: AtomicU64,
    pub dropped: AtomicU64,
}

impl Faults {
    pub fn block(&self, on: bool) {
        self.blocked.store(on, Ordering::SeqCst);
    }

    pub fn delay(&self, base: Duration, jitter: Duration) {
        self.delay_us
            .store(base.as_micros() as u64, Ordering::SeqCst);
        self.jitter_us
            .store(jitter.as_micros() as u64, Ordering::SeqCst);
    }
}

/// A datagram waiting for its time.
struct Due {
    at: Instant,
    n: u64,
    socket: Arc<UdpSocket>,
    to: SocketAddr,
    bytes: Vec<u8>,
}

impl PartialEq for Due {
    fn eq(&self, o: &Self) -> bool {
        (self.at, self.n) == (o.at, o.n)
    }
}
impl Eq for Due {}
impl PartialOrd for Due {
    fn partial_cmp(&self, o: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Due {
    fn cmp(&self, o: &Self) -> std::cmp::Ordering {
        (self.at, self.n).cmp(&(o.at, o.n))
    }
}

#[derive(Default)]
struct Schedule {
    heap: Mutex<BinaryHeap<Reverse<Due>>>,
    wake: Condvar,
    next: AtomicU64,
}

/// A running proxy; stops when dropped.
pub struct UdpProxy {
    /// Where agents send (the station's address as they know it).
    pub addr: SocketAddr,
    pub faults: Arc<Faults>,
    stop: Arc<AtomicBool>,
    schedule: Arc<Schedule>,
}

impl std::fmt::Debug for UdpProxy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("UdpProxy")
            .field("addr", &self.addr)
            .finish()
    }
}

impl UdpProxy {
    /// Listens on `listen` (port 0 picks one) and relays to `target`.
    pub fn start(listen: SocketAddr, target: SocketAddr, seed: u64) -> UdpProxy {
        let front = Arc::new(UdpSocket::bind(listen).expect("proxy binds"));
        front
            .set_read_timeout(Some(Duration::from_millis(50)))
            .expect("timeout");
        let proxy = UdpProxy {
            addr: front.local_addr().expect("proxy address"),
            faults: Arc::new(Faults::default()),
            stop: Arc::new(AtomicBool::new(false)),
            schedule: Arc::new(Schedule::default()),
        };
        proxy.run_sender();
        proxy.run_front(front, target, seed);
        proxy
    }

    /// Sends scheduled datagrams when due.
    fn run_sender(&self) {
        let (stop, sched) = (self.stop.clone(), self.schedule.clone());
        std::thread::spawn(move || {
            let mut heap = sched.heap.lock().unwrap_or_else(|e| e.into_inner());
            while !stop.load(Ordering::Relaxed) {
                let now = Instant::now();
                let wait = match heap.peek() {
                    Some(Reverse(d)) if d.at <= now => {
                        if let Some(Reverse(d)) = heap.pop() {
                            let _ = d.socket.send_to(&d.bytes, d.to);
                        }
                        continue;
                    }
                    Some(Reverse(d)) => d.at - now,
                    None => Duration::from_millis(50),
                };
                heap = sched
                    .wake
                    .wait_timeout(heap, wait)
                    .unwrap_or_else(|e| e.into_inner())
                    .0;
            }
        });
    }

    /// Receives from agents; makes an upstream socket (and its reader) per
    /// agent.
    fn run_front(&self, front: Arc<UdpSocket>, target: SocketAddr, seed: u64) {
        let (stop, faults, sched) = (
            self.stop.clone(),
            self.faults.clone(),
            self.schedule.clone(),
        );
        std::thread::spawn(move || {
            let mut rng = SmallRng::seed_from_u64(seed);
            let mut upstream: HashMap<SocketAddr, Arc<UdpSocket>> = HashMap::new();
            let mut buf = vec![0u8; 65_536];
            let local = SocketAddr::new(target.ip(), 0);
            while !stop.load(Ordering::Relaxed) {
                let Ok((n, agent)) = front.recv_from(&mut buf) else {
                    continue;
                };
                let up = upstream.entry(agent).or_insert_with(|| {
                    let s = Arc::new(UdpSocket::bind(local).expect("upstream binds"));
                    s.set_read_timeout(Some(Duration::from_millis(50)))
                        .expect("timeout");
                    back(
                        s.clone(),
                        front.clone(),
                        agent,
                        &stop,
                        &faults,
                        &sched,
                        seed,
                    );
                    s
                });
                pass(&faults, &sched, &mut rng, up.clone(), target, &buf[..n]);
            }
        });
    }
}

/// Relays the station's answers to one agent.
fn back(
    up: Arc<UdpSocket>,
    front: Arc<UdpSocket>,
    agent: SocketAddr,
    stop: &Arc<AtomicBool>,
    faults: &Arc<Faults>,
    sched: &Arc<Schedule>,
    seed: u64,
) {
    let (stop, faults, sched) = (stop.clone(), faults.clone(), sched.clone());
    std::thread::spawn(move || {
        let mut rng = SmallRng::seed_from_u64(seed ^ u64::from(agent.port()));
        let mut buf = vec![0u8; 65_536];
        while !stop.load(Ordering::Relaxed) {
            if let Ok((n, _)) = up.recv_from(&mut buf) {
                pass(&faults, &sched, &mut rng, front.clone(), agent, &buf[..n]);
            }
        }
    });
}

/// Drops, or schedules for sending after the delay.
fn pass(
    faults: &Faults,
    sched: &Schedule,
    rng: &mut SmallRng,
    socket: Arc<UdpSocket>,
    to: SocketAddr,
    bytes: &[u8],
) {
    let loss = faults.loss_ppm.load(Ordering::Relaxed);
    if faults.blocked.load(Ordering::Relaxed) || (loss > 0 && rng.random_range(0..1_000_000) < loss)
    {
        faults.dropped.fetch_add(1, Ordering::Relaxed);
        return;
    }
    faults.passed.fetch_add(1, Ordering::Relaxed);
    let base = faults.delay_us.load(Ordering::Relaxed) as i64;
    let jitter = faults.jitter_us.load(Ordering::Relaxed) as i64;
    let wait = if jitter > 0 {
        base + rng.random_range(-jitter..=jitter)
    } else {
        base
    };
    if wait <= 0 {
        let _ = socket.send_to(bytes, to);
        return;
    }
    let due = Due {
        at: Instant::now() + Duration::from_micros(wait as u64),
        n: sched.next.fetch_add(1, Ordering::Relaxed),
        socket,
        to,
        bytes: bytes.to_vec(),
    };
    sched
        .heap
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push(Reverse(due));
    sched.wake.notify_one();
}

impl Drop for UdpProxy {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
        self.schedule.wake.notify_all();
    }
}
