//! A network namespace for the robots, joined to this one by a veth pair,
//! with random loss (or a full partition) made by an nftables rule inside
//! the namespace: the kernel drops the datagrams, in both directions.
//!
//! Names are unique per test process and namespace (`mechf-PID-N`), and
//! the namespace, with its veth pair and nftables table, is deleted when
//! the guard drops, also when a test fails. Namespaces left by a process
//! that died are swept when the next one is made.

use std::net::Ipv4Addr;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};

static NEXT: AtomicU32 = AtomicU32::new(0);

const PREFIX: &str = "mechf-";

/// The robots' namespace and the addresses on either side of its veth.
#[derive(Debug)]
pub struct RobotNet {
    pub name: String,
    /// This side's veth (in the test's namespace).
    host_if: String,
    /// The address of this side (where robots send), and of theirs.
    pub host: Ipv4Addr,
    pub robots: Ipv4Addr,
}

/// Runs `ip ARGS` (or any program), panicking with its error output.
fn run(program: &str, args: &[&str]) {
    let out = Command::new(program)
        .args(args)
        .stdin(Stdio::null())
        .output()
        .unwrap_or_else(|e| panic!("{program} runs: {e}"));
    assert!(
        out.status.success(),
        "{program} {}: {}",
        args.join(" "),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Whether this machine lets the tests make namespaces and nftables rules
/// (root, `ip`, `nft`).
pub fn available() -> Result<(), String> {
    let root = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("Uid:"))
                .map(|l| l.split_whitespace().nth(1) == Some("0"))
        })
        .unwrap_or(false);
    if !root {
        return Err("not root (network namespaces need it)".into());
    }
    for (p, a) in [("ip", "-V"), ("nft", "-v")] {
        if !super::have(p, a) {
            return Err(format!("`{p}` is missing (scripts/deps.sh installs it)"));
        }
    }
    Ok(())
}

impl RobotNet {
    /// Makes the namespace, its veth pair and addresses.
    pub fn create() -> RobotNet {
        sweep();
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let pid = std::process::id();
        let name = format!("{PREFIX}{pid}-{n}");
        // Interface names are at most 15 bytes.
        let tag = format!("{:x}{n}", pid % 0xfffff);
        let (host_if, ns_if) = (format!("mfh{tag}"), format!("mfn{tag}"));
        let subnet = (pid.wrapping_mul(7).wrapping_add(n) % 250) as u8 + 1;
        let (host, robots) = (
            Ipv4Addr::new(10, 213, subnet, 1),
            Ipv4Addr::new(10, 213, subnet, 2),
        );
        run("ip", &["netns", "add", &name]);
        let net = RobotNet {
            name,
            host_if,
            host,
            robots,
        };
        let (h, r) = (format!("{host}/30"), format!("{robots}/30"));
        run(
            "ip",
            &[
                "link",
                "add",
                &net.host_if,
                "type",
                "veth",
                "peer",
                "name",
                &ns_if,
            ],
        );
        run("ip", &["link", "set", &ns_if, "netns", &net.name]);
        run("ip", &["addr", "add", &h, "dev", &net.host_if]);
        run("ip", &["link", "set", &net.host_if, "up"]);
        run("ip", &["-n", &net.name, "addr", "add", &r, "dev", &ns_if]);
        run("ip", &["-n", &net.name, "link", "set", &ns_if, "up"]);
        run("ip", &["-n", &net.name, "link", "set", "lo", "up"]);
        net
    }

    /// A command run inside the namespace.
    pub fn command(&self, program: &std::path::Path) -> Command {
        let mut c = Command::new("ip");
        c.args(["netns", "exec", &self.name]).arg(program);
        c
    }

    /// Drops `percent` of UDP datagrams at random, each way (0 heals,
    /// 100 partitions).
    pub fn set_loss(&self, percent: u32) {
        let rules = if percent == 0 {
            String::new()
        } else if percent >= 100 {
            "meta l4proto udp counter drop".to_string()
        } else {
            format!("meta l4proto udp numgen random mod 100 < {percent} counter drop")
        };
        let chain = |hook: &str| {
            format!(
                "  chain {hook} {{\n    type filter hook {hook} priority 0; policy accept;\n    {rules}\n  }}\n"
            )
        };
        let ruleset = format!(
            "table inet mechfault\ndelete table inet mechfault\ntable inet mechfault {{\n{}{}}}\n",
            chain("input"),
            chain("output")
        );
        let mut child = Command::new("ip")
            .args(["netns", "exec", &self.name, "nft", "-f", "-"])
            .stdin(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("nft runs");
        use std::io::Write;
        child
            .stdin
            .take()
            .expect("stdin")
            .write_all(ruleset.as_bytes())
            .expect("ruleset written");
        let out = child.wait_with_output().expect("nft ends");
        assert!(
            out.status.success(),
            "nft: {}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

impl Drop for RobotNet {
    fn drop(&mut self) {
        let quiet = |args: &[&str]| {
            let _ = Command::new("ip")
                .args(args)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status();
        };
        quiet(&["netns", "del", &self.name]);
        quiet(&["link", "del", &self.host_if]);
    }
}

/// Deletes namespaces (and their host-side veths) left by test processes
/// that no longer run.
fn sweep() {
    let Ok(out) = Command::new("ip").args(["netns", "list"]).output() else {
        return;
    };
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        let Some(name) = line.split_whitespace().next() else {
            continue;
        };
        let Some(pid) = name
            .strip_prefix(PREFIX)
            .and_then(|r| r.split('-').next())
            .and_then(|p| p.parse::<u32>().ok())
        else {
            continue;
        };
        if !std::path::Path::new(&format!("/proc/{pid}")).exists() {
            let _ = Command::new("ip").args(["netns", "del", name]).status();
        }
    }
}
