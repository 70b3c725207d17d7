//! A serial radio without hardware: `socat` pseudo-terminal pairs (the
//! station's and each robot's port) joined by a [`RadioHub`] that acts as
//! the air. Like a radio in transparent mode, the hub passes whole frames
//! (split at the framing's `0x00` delimiters): what the station sends,
//! every robot hears; what a robot sends, the station and the other robots
//! hear. Every bit on the way may be flipped at a given bit error rate.

use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use rand::rngs::SmallRng;
use rand::{Rng, SeedableRng};

use super::{Killed, poll};

/// A pair of connected pseudo-terminals made by `socat`.
#[derive(Debug)]
pub struct PtyPair {
    /// The two ends: `a` for the station or robot, `b` for the hub.
    pub a: PathBuf,
    pub b: PathBuf,
    socat: Killed,
}

impl PtyPair {
    /// Makes `DIR/NAME-a` and `DIR/NAME-b`; panics with a clear message
    /// when `socat` is missing (`scripts/deps.sh` installs it).
    pub fn new(dir: &Path, name: &str) -> PtyPair {
        let (a, b) = (dir.join(format!("{name}-a")), dir.join(format!("{name}-b")));
        let child = Command::new("socat")
            .arg(format!("pty,raw,echo=0,link={}", a.display()))
            .arg(format!("pty,raw,echo=0,link={}", b.display()))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("socat runs (scripts/deps.sh installs it)");
        let socat = Killed(Some(child));
        poll(Duration::from_secs(5), || {
            (a.exists() && b.exists()).then_some(())
        })
        .expect("socat made the pseudo-terminal pair");
        PtyPair { a, b, socat }
    }

    /// Unplugs the pair: kills `socat` (SIGKILL, so nothing is flushed or
    /// closed in order) and removes both names, as a USB radio's device
    /// node goes when it is pulled out. A new [`PtyPair::new`] with the
    /// same directory and name plugs it back in.
    pub fn unplug(&mut self) {
        self.socat.kill();
        let _ = std::fs::remove_file(&self.a);
        let _ = std::fs::remove_file(&self.b);
    }
}

/// What the hub carried.
#[derive(Debug, Default)]
pub struct HubCounters {
    pub frames: AtomicU64,
    pub bytes: AtomicU64,
    pub flipped_bits: AtomicU64,
}

/// The air between a station's radio and its robots' radios.
#[derive(Debug)]
pub struct RadioHub {
    stop: Arc<AtomicBool>,
    /// Bit error rate, as parts per billion (changeable while running).
    ber_ppb: Arc<AtomicU64>,
    pub counters: Arc<HubCounters>,
}

impl RadioHub {
    /// Joins the hub ends of the station's pair and of each robot's pair.
    pub fn start(station: &Path, robots: &[&Path], ber: f64, seed: u64) -> RadioHub {
        let hub = RadioHub {
            stop: Arc::new(AtomicBool::new(false)),
            ber_ppb: Arc::new(AtomicU64::new((ber * 1e9) as u64)),
            counters: Arc::new(HubCounters::default()),
        };
        let open = |p: &Path| {
            std::fs::OpenOptions::new()
                .read(true)
                .write(true)
                .open(p)
                .unwrap_or_else(|e| panic!("cannot open {}: {e}", p.display()))
        };
        let station = open(station);
        let robot_ports: Vec<File> = robots.iter().map(|p| open(p)).collect();
        let to_robots: Vec<Arc<Mutex<File>>> = robot_ports
            .iter()
            .map(|f| Arc::new(Mutex::new(f.try_clone().expect("clone"))))
            .collect();
        let to_station = Arc::new(Mutex::new(station.try_clone().expect("clone")));
        hub.carry(station, to_robots.clone(), seed);
        for (i, port) in robot_ports.into_iter().enumerate() {
            // A robot's frame reaches the station and the other robots.
            let mut to = vec![to_station.clone()];
            to.extend(
                to_robots
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, p)| p.clone()),
            );
            hub.carry(port, to, seed + 1 + i as u64);
        }
        hub
    }

    /// Sets the bit error rate.
    pub fn set_ber(&self, ber: f64) {
        self.ber_ppb.store((ber * 1e9) as u64, Ordering::Relaxed);
    }

    /// A thread reading frames from `from` and writing each, noise added,
    /// to every port of `to`.
    fn carry(&self, mut from: File, to: Vec<Arc<Mutex<File>>>, seed: u64) {
        let (stop, ber, counters) = (
            self.stop.clone(),
            self.ber_ppb.clone(),
            self.counters.clone(),
        );
        std::thread::spawn(move || {
            let mut rng = SmallRng::seed_from_u64(seed);
            let mut frame = Vec::new();
            let mut buf = [0u8; 1024];
            while let Ok(n) = from.read(&mut buf) {
                if n == 0 || stop.load(Ordering::Relaxed) {
                    return;
                }
                for &b in &buf[..n] {
                    if b != 0 {
                        frame.push(b);
                        continue;
                    }
                    if frame.is_empty() {
                        continue;
                    }
                    let mut air = Vec::with_capacity(frame.len() + 2);
                    air.push(0);
                    air.append(&mut frame);
                    air.push(0);
                    let flipped = noise(&mut air, ber.load(Ordering::Relaxed), &mut rng);
                    counters.frames.fetch_add(1, Ordering::Relaxed);
                    counters
                        .bytes
                        .fetch_add(air.len() as u64, Ordering::Relaxed);
                    counters.flipped_bits.fetch_add(flipped, Ordering::Relaxed);
                    for port in &to {
                        let mut p = port.lock().unwrap_or_else(|e| e.into_inner());
                        let _ = p.write_all(&air).and_then(|()| p.flush());
                    }
                }
            }
        });
    }
}

impl Drop for RadioHub {
    fn drop(&mut self) {
        // The threads end when their port closes (the socat guards).
        self.stop.store(true, Ordering::Relaxed);
    }
}

/// Flips each bit with probability `ppb` / 1e9; returns how many flipped.
fn noise(bytes: &mut [u8], ppb: u64, rng: &mut SmallRng) -> u64 {
    if ppb == 0 {
        return 0;
    }
    let p = ppb as f64 / 1e9;
    let mut flipped = 0;
    for b in bytes.iter_mut() {
        for bit in 0..8 {
            if rng.random::<f64>() < p {
                *b ^= 1 << bit;
                flipped += 1;
            }
        }
    }
    flipped
}
