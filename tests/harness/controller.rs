//! An external controller on the station's loopback: publishes a twist
//! for each robot on one channel at 20 Hz (while told to), can engage the
//! e-stop, and subscribes to the robots' telemetry, recording each with
//! the robot's own stamp (same machine, same clock) and its arrival time.

use std::net::{SocketAddr, UdpSocket};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Duration;

use mech_proto::{
    Body, Command, EStop, Envelope, FailsafeState, Header, MissionProgress, Subscribe, Twist,
};

use super::unix_us;

/// Publishing period (20 Hz, a gamepad's rate).
pub const PERIOD: Duration = Duration::from_millis(50);

/// One telemetry message as received.
#[derive(Debug, Clone)]
pub struct Sample {
    pub robot: String,
    /// The robot's stamp, µs since the Unix epoch.
    pub stamp_us: u64,
    pub failsafe: FailsafeState,
    pub moving: bool,
    pub channel: String,
    pub mission: Option<MissionProgress>,
    pub x: f64,
}

/// The controller; stops its threads when dropped.
#[derive(Debug)]
pub struct Controller {
    socket: Arc<UdpSocket>,
    router: SocketAddr,
    stop: Arc<AtomicBool>,
    publishing: Arc<AtomicBool>,
    /// Commands published, in total.
    pub sent: Arc<AtomicU64>,
    samples: Arc<Mutex<Vec<Sample>>>,
    seq: Arc<AtomicU64>,
}

fn message(seq: u32, destination: &str, channel: &str, body: Body) -> Vec<u8> {
    let header = Header {
        seq,
        stamp_us: unix_us(),
        sender: "faults".into(),
        destination: destination.into(),
        channel: channel.into(),
    };
    mech_proto::encode(&Envelope::new(header, body)).expect("encodes")
}

impl Controller {
    /// Publishes to `robots` on `channel` (once [`Controller::publish`]
    /// says so) through the station at `router`.
    pub fn start(router: SocketAddr, robots: &[&str], channel: &str, vx: f64) -> Controller {
        Controller::new(router, robots, channel, vx, true)
    }

    /// Like [`Controller::start`], without subscribing to telemetry when
    /// `subscribe` is false (a long run that only commands).
    pub fn new(
        router: SocketAddr,
        robots: &[&str],
        channel: &str,
        vx: f64,
        subscribe: bool,
    ) -> Controller {
        let socket = Arc::new(UdpSocket::bind("127.0.0.1:0").expect("controller binds"));
        socket
            .set_read_timeout(Some(Duration::from_millis(50)))
            .expect("timeout");
        let c = Controller {
            socket,
            router,
            stop: Arc::new(AtomicBool::new(false)),
            publishing: Arc::new(AtomicBool::new(false)),
            sent: Arc::new(AtomicU64::new(0)),
            samples: Arc::new(Mutex::new(Vec::new())),
            seq: Arc::new(AtomicU64::new(0)),
        };
        c.run_publisher(
            robots.iter().map(|r| r.to_string()).collect(),
            channel,
            vx,
            subscribe,
        );
        c.run_listener();
        c
    }

    fn next_seq(&self) -> u32 {
        self.seq.fetch_add(1, Ordering::Relaxed) as u32 + 1
    }

    fn run_publisher(&self, robots: Vec<String>, channel: &str, vx: f64, subscribe: bool) {
        let (socket, router, stop, publishing, sent, seq) = (
            self.socket.clone(),
            self.router,
            self.stop.clone(),
            self.publishing.clone(),
            self.sent.clone(),
            self.seq.clone(),
        );
        let channel = channel.to_string();
        std::thread::spawn(move || {
            let twist = Body::Command(Command::Twist(Twist {
                vx,
                wz: 0.1,
                ..Twist::default()
            }));
            let mut n = 0u64;
            while !stop.load(Ordering::Relaxed) {
                if subscribe && n % 40 == 0 {
                    let s = seq.fetch_add(1, Ordering::Relaxed) as u32 + 1;
                    let sub = Body::Subscribe(Subscribe { telemetry: true });
                    let _ = socket.send_to(&message(s, "router", "", sub), router);
                }
                n += 1;
                if publishing.load(Ordering::Relaxed) {
                    for r in &robots {
                        let s = seq.fetch_add(1, Ordering::Relaxed) as u32 + 1;
                        let _ = socket.send_to(&message(s, r, &channel, twist.clone()), router);
                        sent.fetch_add(1, Ordering::Relaxed);
                    }
                }
                std::thread::sleep(PERIOD);
            }
        });
    }

    fn run_listener(&self) {
        let (socket, stop, samples) =
            (self.socket.clone(), self.stop.clone(), self.samples.clone());
        std::thread::spawn(move || {
            let mut buf = vec![0u8; 65_536];
            while !stop.load(Ordering::Relaxed) {
                let Ok((n, _)) = socket.recv_from(&mut buf) else {
                    continue;
                };
                let Ok(env) = mech_proto::decode(&buf[..n]) else {
                    continue;
                };
                if let Body::Telemetry(t) = env.body {
                    let s = Sample {
                        robot: env.header.sender,
                        stamp_us: env.header.stamp_us,
                        failsafe: t.failsafe,
                        moving: t.actuators.iter().any(|u| *u != 0.0),
                        channel: t.channel,
                        mission: t.mission,
                        x: t.pose.x,
                    };
                    samples.lock().unwrap_or_else(|e| e.into_inner()).push(s);
                }
            }
        });
    }

    /// Starts or stops publishing commands.
    pub fn publish(&self, on: bool) {
        self.publishing.store(on, Ordering::SeqCst);
    }

    /// Engages (or releases) the e-stop through the router; returns when
    /// it was sent, µs since the Unix epoch.
    pub fn estop(&self, engage: bool) -> u64 {
        let at = unix_us();
        let body = Body::EStop(EStop { engage, id: 0 });
        let m = message(self.next_seq(), "router", "", body);
        let _ = self.socket.send_to(&m, self.router);
        at
    }

    /// Every telemetry sample so far.
    pub fn samples(&self) -> Vec<Sample> {
        self.samples
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// The first sample of `robot` stamped at or after `since_us` that
    /// matches `want`.
    pub fn first(
        &self,
        robot: &str,
        since_us: u64,
        want: impl Fn(&Sample) -> bool,
    ) -> Option<Sample> {
        self.samples()
            .into_iter()
            .filter(|s| s.robot == robot && s.stamp_us >= since_us && want(s))
            .min_by_key(|s| s.stamp_us)
    }
}

impl Drop for Controller {
    fn drop(&mut self) {
        self.stop.store(true, Ordering::Relaxed);
    }
}
