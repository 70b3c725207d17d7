//! A station, its robots and a controller, wired for one scenario: over
//! UDP through the proxy (and, for loss, from a network namespace), or
//! over a noisy radio. Fields drop in order: agents and station are
//! killed before the proxy, radio and namespace go.

use std::net::SocketAddr;
use std::time::Duration;

use mech_e2e::harness::agent::{self, Agent};
use mech_e2e::harness::controller::Controller;
use mech_e2e::harness::netns::RobotNet;
use mech_e2e::harness::proxy::UdpProxy;
use mech_e2e::harness::radio::{PtyPair, RadioHub};
use mech_e2e::harness::station::{self, Station};

/// The channel the robots are routed to.
pub const CHANNEL: &str = "ext/f";

/// Failsafe of the robots: the defaults (0.5 s channel, 1 s router).
pub const FAILSAFE: &str = "channel_timeout = 0.5\nrouter_timeout = 1.0";

#[derive(Debug)]
pub struct Rig {
    pub agents: Vec<Agent>,
    pub ctl: Controller,
    pub station: Station,
    pub proxy: Option<UdpProxy>,
    /// Kept for its guards: the hub and the pseudo-terminals.
    pub _radio: Option<(RadioHub, Vec<PtyPair>)>,
    pub net: Option<RobotNet>,
    pub dir: tempfile::TempDir,
}

/// Waits for every robot, routes them all to [`CHANNEL`], says `routed`,
/// then keeps the station up.
pub fn drive_script(robots: &[String]) -> String {
    let mut s = String::new();
    for r in robots {
        s += &format!("wait connected {r} 30s\n");
    }
    s += &format!("route all {CHANNEL}\n");
    for r in robots {
        s += &format!("wait route {r} {CHANNEL} 20s\n");
    }
    s + "log routed\nsleep 600s\n"
}

pub fn names(n: usize) -> Vec<String> {
    (1..=n).map(|i| format!("r{i}")).collect()
}

impl Rig {
    /// `n` robots on UDP through the proxy; in a fresh network namespace
    /// when `namespace`. The station runs `script` (default: the drive
    /// script).
    pub fn udp(n: usize, namespace: bool, failsafe: &str, script: Option<&str>) -> Rig {
        let dir = tempfile::tempdir().expect("temp dir");
        let net = namespace.then(RobotNet::create);
        let port = station::free_port();
        let listen: SocketAddr = match &net {
            Some(net) => (net.host, 0).into(),
            None => ([127, 0, 0, 1], 0).into(),
        };
        let target: SocketAddr = ([127, 0, 0, 1], port).into();
        let proxy = UdpProxy::start(listen, target, u64::from(port));
        let names = names(n);
        let config = station::config(dir.path(), port, "");
        let script = script.map_or_else(|| drive_script(&names), str::to_string);
        let station = Station::start(&config, &script, dir.path());
        let link = format!("[link]\nkind = \"udp\"\nrouter = \"{}\"", proxy.addr);
        let agents = start_agents(dir.path(), &names, &link, failsafe, net.as_ref());
        let ctl = controller(port, &names);
        Rig {
            agents,
            ctl,
            station,
            proxy: Some(proxy),
            _radio: None,
            net,
            dir,
        }
    }

    /// `n` robots on one serial radio at bit error rate `ber`.
    pub fn radio(n: usize, ber: f64) -> Rig {
        let dir = tempfile::tempdir().expect("temp dir");
        let air = PtyPair::new(dir.path(), "station");
        let names = names(n);
        let pairs: Vec<PtyPair> = names.iter().map(|r| PtyPair::new(dir.path(), r)).collect();
        let ends: Vec<&std::path::Path> = pairs.iter().map(|p| p.b.as_path()).collect();
        let hub = RadioHub::start(&air.b, &ends, ber, 7);
        let port = station::free_port();
        let radio = format!(
            "[[router.serial]]\nport = \"{}\"\nbaud = 115200\n",
            air.a.display()
        );
        let config = station::config(dir.path(), port, &radio);
        let station = Station::start(&config, &drive_script(&names), dir.path());
        let mut agents = Vec::new();
        for (r, p) in names.iter().zip(&pairs) {
            let link = format!(
                "[link]\nkind = \"serial\"\nport = \"{}\"\nbaud = 115200\ntelemetry_rate_hz = 10",
                p.a.display()
            );
            let x = 0.5 + agents.len() as f64;
            let cfg = agent::config(
                dir.path(),
                r,
                x,
                &link,
                "channel_timeout = 0.5\nrouter_timeout = 2.0",
            );
            agents.push(Agent::start(r, &cfg, None));
        }
        let mut all_pairs = pairs;
        all_pairs.push(air);
        let ctl = controller(port, &names);
        Rig {
            agents,
            ctl,
            station,
            proxy: None,
            _radio: Some((hub, all_pairs)),
            net: None,
            dir,
        }
    }

    pub fn names(&self) -> Vec<String> {
        self.agents.iter().map(|a| a.name.clone()).collect()
    }

    /// Waits for the script's `log routed`.
    pub fn wait_routed(&self) {
        self.station.wait_log("routed", Duration::from_secs(60));
    }
}

fn start_agents(
    dir: &std::path::Path,
    names: &[String],
    link: &str,
    failsafe: &str,
    net: Option<&RobotNet>,
) -> Vec<Agent> {
    names
        .iter()
        .enumerate()
        .map(|(i, r)| {
            let cfg = agent::config(dir, r, 0.5 + i as f64, link, failsafe);
            Agent::start(r, &cfg, net)
        })
        .collect()
}

/// A controller publishing to every robot on [`CHANNEL`] from the start
/// (commands before routing are dropped at the station).
fn controller(port: u16, names: &[String]) -> Controller {
    let robots: Vec<&str> = names.iter().map(String::as_str).collect();
    let ctl = Controller::start(([127, 0, 0, 1], port).into(), &robots, CHANNEL, 0.05);
    ctl.publish(true);
    ctl
}
