//! Running the real station and agents under faults: loss and partitions
//! in network namespaces ([`netns`]), delay and jitter through a userspace
//! UDP proxy ([`proxy`]), noisy serial radios over pseudo-terminal pairs
//! ([`radio`]), the station ([`station`]) and agents ([`agent`]) as
//! processes that can be killed and restarted, and a controller that
//! commands the robots and watches their telemetry ([`controller`]).
//!
//! Every resource is a guard: processes are killed and namespaces deleted
//! when the guard drops, also when a test fails.

pub mod agent;
pub mod controller;
pub mod netns;
pub mod proxy;
pub mod radio;
pub mod station;

use std::process::Child;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

/// Microseconds since the Unix epoch (the protocol's stamps).
pub fn unix_us() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_micros() as u64)
}

/// A child process killed (SIGKILL) and reaped when dropped.
#[derive(Debug)]
pub struct Killed(pub Option<Child>);

impl Killed {
    /// Kills it now (SIGKILL, as `kill -9`).
    pub fn kill(&mut self) {
        if let Some(mut c) = self.0.take() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }

    /// Whether it still runs, or how it ended (for failure messages).
    pub fn state(&mut self) -> String {
        match self.0.as_mut().map(Child::try_wait) {
            None => "killed".into(),
            Some(Ok(None)) => "running".into(),
            Some(Ok(Some(status))) => format!("exited: {status}"),
            Some(Err(e)) => format!("unknown: {e}"),
        }
    }

    /// The process id, while it runs.
    pub fn pid(&self) -> Option<u32> {
        self.0.as_ref().map(Child::id)
    }
}

impl Drop for Killed {
    fn drop(&mut self) {
        self.kill();
    }
}

/// Whether a command runs (`socat -V`, `nft -v`...).
pub fn have(program: &str, arg: &str) -> bool {
    std::process::Command::new(program)
        .arg(arg)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Polls `f` every 10 ms until it returns `Some`, or `None` after `timeout`.
pub fn poll<T>(timeout: Duration, mut f: impl FnMut() -> Option<T>) -> Option<T> {
    let end = Instant::now() + timeout;
    loop {
        if let Some(t) = f() {
            return Some(t);
        }
        if Instant::now() >= end {
            return None;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}
