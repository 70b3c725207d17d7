//! Soak benchmark (not run by `cargo test`): the release `mech-gcs` routes
//! 100 simulated robots for 10 minutes (telemetry at 20 Hz each, commands
//! at 20 Hz each from an external controller, an e-stop and its release
//! every minute) while the station's memory (RSS) and CPU are sampled every
//! 10 s. Prints the samples and whether memory stayed flat: RSS at the end
//! within 10% (and 4 MB) of RSS after the first minute; exits 1 if not.
//!
//! ```sh
//! cargo build --release -p mech-gcs
//! cargo bench -p mech-e2e --bench soak -- [MINUTES] [ROBOTS]
//! ```

use std::time::{Duration, Instant};

use mech_agent::sim::{Arena, SimFleet, SimFleetOptions};
use mech_e2e::harness::controller::Controller;
use mech_e2e::harness::station::{self, Station};

/// Resident memory of a process, kB.
fn rss_kb(pid: u32) -> u64 {
    let status = std::fs::read_to_string(format!("/proc/{pid}/status")).unwrap_or_default();
    status
        .lines()
        .find(|l| l.starts_with("VmRSS:"))
        .and_then(|l| l.split_whitespace().nth(1)?.parse().ok())
        .unwrap_or(0)
}

/// utime + stime of a process, clock ticks (100 per second on Linux).
fn cpu_ticks(pid: u32) -> u64 {
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).unwrap_or_default();
    let after = stat.rsplit(')').next().unwrap_or("");
    let f: Vec<&str> = after.split_whitespace().collect();
    let field = |i: usize| f.get(i).and_then(|v| v.parse::<u64>().ok()).unwrap_or(0);
    field(11) + field(12)
}

fn arg(i: usize, default: u64) -> u64 {
    std::env::args()
        .skip(1)
        .filter(|a| !a.starts_with('-'))
        .nth(i)
        .and_then(|a| a.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let (minutes, robots) = (arg(0, 10), arg(1, 100) as usize);
    let dir = tempfile::tempdir().expect("temp dir");
    let port = station::free_port();
    let config = station::config(dir.path(), port, "");
    let script = format!(
        "wait robots {robots} 120s\nroute all ext/soak\nlog routed\nsleep {}s\n",
        minutes * 60 + 120
    );
    let gcs = Station::start(&config, &script, dir.path());
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .expect("runtime");
    let addr = ([127, 0, 0, 1], port).into();
    let fleet = runtime
        .block_on(SimFleet::spawn(
            robots,
            addr,
            Arena::default(),
            SimFleetOptions::default(),
        ))
        .expect("simulated fleet starts");
    gcs.wait_log("routed", Duration::from_secs(150));
    let names = fleet.names();
    let refs: Vec<&str> = names.iter().map(String::as_str).collect();
    let ctl = Controller::new(addr, &refs, "ext/soak", 0.05, false);
    ctl.publish(true);
    let pid = gcs.pid().expect("station runs");
    println!("soak: {robots} robots, {minutes} min, station pid {pid}");
    println!("| t (s) | station RSS (MB) | station CPU (% of a core) | commands sent |");
    println!("| --- | --- | --- | --- |");
    let samples = sample(pid, &ctl, Duration::from_secs(minutes * 60));
    runtime.block_on(fleet.shutdown());
    report(&samples);
}

/// (seconds, RSS kB, CPU %) every 10 s for `length`, with an e-stop and a
/// release every minute.
fn sample(pid: u32, ctl: &Controller, length: Duration) -> Vec<(u64, u64, f64)> {
    let start = Instant::now();
    let mut out = Vec::new();
    let (mut last_t, mut last_cpu) = (Instant::now(), cpu_ticks(pid));
    while start.elapsed() < length {
        std::thread::sleep(Duration::from_secs(10));
        let s = start.elapsed().as_secs();
        if s % 60 < 10 {
            ctl.estop(true);
            std::thread::sleep(Duration::from_millis(500));
            ctl.estop(false);
        }
        let (now, cpu) = (Instant::now(), cpu_ticks(pid));
        let pct = (cpu - last_cpu) as f64 / (now - last_t).as_secs_f64();
        (last_t, last_cpu) = (now, cpu);
        let rss = rss_kb(pid);
        let sent = ctl.sent.load(std::sync::atomic::Ordering::Relaxed);
        println!("| {s} | {:.1} | {pct:.1} | {sent} |", rss as f64 / 1024.0);
        out.push((s, rss, pct));
    }
    out
}

fn report(samples: &[(u64, u64, f64)]) {
    let Some(&(_, first, _)) = samples
        .iter()
        .find(|(t, _, _)| *t >= 60)
        .or(samples.first())
    else {
        println!("no samples");
        return;
    };
    let &(_, last, _) = samples.last().expect("samples");
    let peak = samples.iter().map(|s| s.1).max().unwrap_or(0);
    let mean_cpu = samples.iter().map(|s| s.2).sum::<f64>() / samples.len() as f64;
    let growth = last as f64 - first as f64;
    let flat = growth <= (first as f64 * 0.1).max(4096.0);
    println!(
        "station RSS after 1 min {:.1} MB, at the end {:.1} MB (peak {:.1} MB, {:+.1} MB); mean CPU {mean_cpu:.1}% of a core; memory flat: {}",
        first as f64 / 1024.0,
        last as f64 / 1024.0,
        peak as f64 / 1024.0,
        growth / 1024.0,
        if flat { "yes" } else { "NO" }
    );
    if !flat {
        std::process::exit(1);
    }
}
