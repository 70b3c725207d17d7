//! A robot's links and failover: the UDP address and the radio the robot
//! was last heard on, and when. Everything for a robot goes out on UDP
//! while UDP is live (heard within `link_timeout`), else on its radio
//! while that is live, else on whichever was heard last; heartbeats and
//! e-stops go out on every link, so a robot hears the router on each and
//! an e-stop takes whichever arrives first. The router tells the fleet
//! model which links are live and each radio robot's telemetry budget.

use std::net::SocketAddr;

use tokio::time::Instant;

use super::{Ctx, Peer, Tables};
use crate::event::{Event, LinkAddr, RobotLinks};
use crate::router::config::SerialEndpoint;

/// Share of a radio's bandwidth given to the robots' telemetry; the rest
/// carries commands, acknowledgements, heartbeats and retries.
const TELEMETRY_SHARE: f64 = 0.5;

/// Bytes of a telemetry frame on the radio before one is measured
/// (a signed telemetry message, its checksum and COBS framing).
const DEFAULT_TELEMETRY_FRAME: f64 = 200.0;

/// Weight of each newly measured telemetry frame in the running mean of
/// their sizes (after the first, which is taken as it is).
const FRAME_WEIGHT: f64 = 0.1;

/// Where one robot was heard, and when.
#[derive(Debug, Clone)]
pub(super) struct Links {
    udp: Option<(SocketAddr, Instant)>,
    radio: Option<(u16, Instant)>,
    /// Mean size of the robot's telemetry frames on the radio, bytes:
    /// [`DEFAULT_TELEMETRY_FRAME`] until the first is measured, which then
    /// replaces it (so the budget shown does not drift from a guess to the
    /// truth over the following minute).
    radio_frame: f64,
    frame_measured: bool,
    /// What the last [`Event::Links`] said.
    reported: RobotLinks,
}

impl Links {
    pub(super) fn new(from: Peer, now: Instant) -> Links {
        let mut links = Links {
            udp: None,
            radio: None,
            radio_frame: DEFAULT_TELEMETRY_FRAME,
            frame_measured: false,
            reported: RobotLinks::default(),
        };
        links.heard(from, now);
        links
    }

    /// Notes a message from the robot on `from`; returns the address it
    /// replaced when the robot moved (a restart, a new DHCP lease).
    pub(super) fn heard(&mut self, from: Peer, now: Instant) -> Option<Peer> {
        match from {
            Peer::Udp(addr) => {
                let old = self.udp.replace((addr, now)).map(|(a, _)| a);
                old.filter(|a| *a != addr).map(Peer::Udp)
            }
            Peer::Serial(port) => {
                let old = self.radio.replace((port, now)).map(|(p, _)| p);
                old.filter(|p| *p != port).map(Peer::Serial)
            }
            Peer::Tcp(_) | Peer::Local => None,
        }
    }

    /// The link to send on now: UDP while live, else the radio while live,
    /// else the one heard last.
    pub(super) fn target(&self, now: Instant, timeout: std::time::Duration) -> Option<Peer> {
        let live = |at: Instant| now.saturating_duration_since(at) < timeout;
        match (self.udp, self.radio) {
            (Some((a, t)), _) if live(t) => Some(Peer::Udp(a)),
            (_, Some((p, t))) if live(t) => Some(Peer::Serial(p)),
            (Some((a, ta)), Some((p, tp))) => Some(if ta >= tp {
                Peer::Udp(a)
            } else {
                Peer::Serial(p)
            }),
            (Some((a, _)), None) => Some(Peer::Udp(a)),
            (None, Some((p, _))) => Some(Peer::Serial(p)),
            (None, None) => None,
        }
    }

    /// Every link of the robot.
    pub(super) fn all(&self) -> impl Iterator<Item = Peer> + use<> {
        let udp = self.udp.map(|(a, _)| Peer::Udp(a));
        let radio = self.radio.map(|(p, _)| Peer::Serial(p));
        udp.into_iter().chain(radio)
    }

    /// The radio port the robot was heard on, if any.
    pub(super) fn radio(&self) -> Option<u16> {
        self.radio.map(|(p, _)| p)
    }

    /// Notes the size of a telemetry frame heard on the radio.
    pub(super) fn radio_telemetry(&mut self, message_len: usize) {
        // The message, its CRC, COBS overhead and two delimiters.
        let frame = (message_len + 4 + message_len / 254 + 3) as f64;
        if std::mem::replace(&mut self.frame_measured, true) {
            self.radio_frame += (frame - self.radio_frame) * FRAME_WEIGHT;
        } else {
            self.radio_frame = frame;
        }
    }
}

/// The station's radios as configured (`router.serial`), by port number:
/// how a radio is named and how its rate is shared.
#[derive(Debug, Clone, Copy)]
struct Radios<'a>(&'a [SerialEndpoint]);

impl Radios<'_> {
    fn name(&self, port: u16) -> String {
        self.0
            .get(usize::from(port))
            .map_or_else(|| format!("#{port}"), |s| s.port.clone())
    }

    /// Telemetry messages per second each of the `robots` on radio `port`
    /// may send, at `frame` bytes each: the radio's telemetry share split
    /// evenly among them.
    fn budget(&self, port: u16, robots: usize, frame: f64) -> Option<f64> {
        let baud = self.0.get(usize::from(port))?.baud;
        let hz = f64::from(baud) / 10.0 * TELEMETRY_SHARE / robots.max(1) as f64 / frame;
        // Whole messages per second once there are a few, so the budget
        // does not flicker with the frame size.
        Some(if hz >= 2.0 {
            hz.floor()
        } else {
            (hz * 10.0).floor() / 10.0
        })
    }
}

impl Links {
    /// What the links look like at `now` (live within `timeout`), as
    /// [`Event::Links`] says; `sharing` robots are on the robot's radio.
    fn report(
        &self,
        now: Instant,
        timeout: std::time::Duration,
        radios: Radios<'_>,
        sharing: usize,
    ) -> RobotLinks {
        let live = |at: Instant| now.saturating_duration_since(at) < timeout;
        let mut down = Vec::new();
        if self.udp.is_some_and(|(_, t)| !live(t)) {
            down.push("wifi".to_string());
        }
        if self.radio.is_some_and(|(_, t)| !live(t)) {
            down.push("radio".to_string());
        }
        RobotLinks {
            udp: self.udp.is_some_and(|(_, t)| live(t)),
            radio: self
                .radio
                .filter(|(_, t)| live(*t))
                .map(|(p, _)| radios.name(p)),
            active: match self.target(now, timeout) {
                Some(Peer::Udp(_)) if self.udp.is_some_and(|(_, t)| live(t)) => "udp",
                Some(Peer::Serial(_)) if self.radio.is_some_and(|(_, t)| live(t)) => "radio",
                _ => "",
            },
            radio_budget_hz: self
                .radio()
                .and_then(|p| radios.budget(p, sharing, self.radio_frame)),
            down,
        }
    }
}

impl Tables {
    /// Where to send to `robot` now.
    pub(super) fn target(&self, robot: &str, now: Instant) -> Option<Peer> {
        let timeout = self.config.link_timeout;
        self.robots.get(robot)?.links.target(now, timeout)
    }

    /// How a link is named in events and logs.
    pub(super) fn link_addr(&self, peer: Peer) -> LinkAddr {
        match peer {
            Peer::Serial(i) => LinkAddr::Radio(Radios(&self.config.serial).name(i)),
            Peer::Udp(a) => LinkAddr::Udp(a),
            Peer::Tcp(_) | Peer::Local => LinkAddr::Radio(peer.to_string()),
        }
    }

    /// Radio `port` failed (`error`) or was opened again (`None`): the
    /// operator is told (the robots on it fall silent on the radio, and
    /// their links say so, on their own).
    pub(crate) fn radio_changed(&mut self, port: u16, error: Option<String>, cx: &mut Ctx<'_>) {
        cx.event(Event::Radio {
            port: Radios(&self.config.serial).name(port),
            up: error.is_none(),
            reason: error.unwrap_or_default(),
        });
    }

    /// Reports every robot with a radio whose live links (or radio budget)
    /// changed. A robot on UDP alone has one link: its link state says it.
    pub(super) fn report_links(&mut self, cx: &mut Ctx<'_>) {
        let (radios, timeout) = (Radios(&self.config.serial), self.config.link_timeout);
        let mut changed = Vec::new();
        for (name, r) in self.robots.iter() {
            let Some(port) = r.links.radio() else {
                continue;
            };
            let sharing = self
                .robots
                .iter()
                .filter(|(_, r)| r.links.radio() == Some(port))
                .count();
            let report = r.links.report(cx.now, timeout, radios, sharing);
            if report != r.links.reported {
                changed.push((name.clone(), report));
            }
        }
        for (name, report) in changed {
            if let Some(r) = self.robots.get_mut(&name) {
                r.links.reported = report.clone();
            }
            cx.event(Event::Links {
                robot: name,
                links: report,
            });
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    #[test]
    fn udp_while_live_then_the_radio_then_udp_again() {
        let t0 = Instant::now();
        let ms = |v| t0 + Duration::from_millis(v);
        let timeout = Duration::from_millis(300);
        let wifi = Peer::Udp("10.0.0.2:5000".parse().unwrap());
        let mut l = Links::new(wifi, t0);
        assert_eq!(l.target(ms(100), timeout), Some(wifi), "UDP only");
        l.heard(Peer::Serial(0), ms(100));
        l.heard(wifi, ms(200));
        assert_eq!(l.target(ms(400), timeout), Some(wifi), "both live: UDP");
        l.heard(Peer::Serial(0), ms(400));
        assert_eq!(
            l.target(ms(500), timeout),
            Some(Peer::Serial(0)),
            "UDP silent for 300 ms: the radio"
        );
        assert_eq!(
            l.target(ms(5_000), timeout),
            Some(Peer::Serial(0)),
            "neither live: the one heard last"
        );
        l.heard(wifi, ms(5_000));
        assert_eq!(l.target(ms(5_010), timeout), Some(wifi), "back on UDP");
        assert_eq!(l.all().count(), 2);
        let moved = l.heard(Peer::Udp("10.0.0.3:5000".parse().unwrap()), ms(5_020));
        assert_eq!(moved, Some(wifi));
    }

    #[test]
    fn the_first_telemetry_frame_measured_replaces_the_guess() {
        let mut l = Links::new(Peer::Serial(0), Instant::now());
        assert_eq!(l.radio_frame, DEFAULT_TELEMETRY_FRAME);
        // A 150-byte message: 150 + CRC 4 + COBS 1 + two delimiters.
        l.radio_telemetry(150);
        assert_eq!(l.radio_frame, 157.0, "at once, not 10 % of the way");
        l.radio_telemetry(250);
        // 250 + 4 + 0 + 3 = 257 bytes, a tenth of the way from 157.
        assert!((l.radio_frame - 167.0).abs() < 1e-9, "{}", l.radio_frame);
    }
}
