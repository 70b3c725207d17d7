//! A real agent (config -> launch -> runtime -> core -> simulated vehicle)
//! against a tiny fake router written here, speaking raw mech-proto bytes:
//! over UDP on 127.0.0.1:0, and over a pseudo-terminal pair standing in for
//! a serial radio. Timeouts are real but short; the assertions are on
//! states, never on durations.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use mech_agent::config::RobotConfig;
use mech_agent::launch::{self, Overrides};
use mech_proto::{
    Body, Command, ControlMode, Envelope, FailsafeState, Header, Heartbeat, NoticeCode, Route,
    Telemetry, Twist, Welcome,
};
use tokio::sync::watch;

const NAME: &str = "e2e_bot";

fn config(link: &str) -> RobotConfig {
    let text = format!(
        "name = \"{NAME}\"\ncontrol_rate_hz = 50\ntelemetry_rate_hz = 50\n{link}\n\
         [platform]\nkind = \"diff-drive\"\ntrack_width = 0.15\nmax_wheel_speed = 0.5\n\
         [position]\nkind = \"sim\"\n[sim]\nnoise = false\n\
         [failsafe]\nchannel_timeout = 0.2\nrouter_timeout = 2.0\n"
    );
    RobotConfig::parse(&text, "e2e.toml").unwrap()
}

fn from_router(destination: &str, channel: &str, body: Body) -> Envelope {
    Envelope::new(
        Header {
            sender: "ctl".into(),
            destination: destination.into(),
            channel: channel.into(),
            ..Header::default()
        },
        body,
    )
}

fn twist(vx: f64) -> Body {
    Body::Command(Command::Twist(Twist {
        vx,
        ..Twist::default()
    }))
}

/// The fake router's side of a link.
trait RouterSide {
    async fn send(&mut self, env: &Envelope);
    /// The next message, or `None` after 100 ms of nothing.
    async fn recv(&mut self) -> Option<Envelope>;
}

/// Receives (sending router heartbeats meanwhile) until `want` matches.
async fn wait_for<R: RouterSide, T>(
    r: &mut R,
    what: &str,
    mut want: impl FnMut(&Envelope) -> Option<T>,
) -> T {
    for _ in 0..100 {
        r.send(&from_router(NAME, "", Body::Heartbeat(Heartbeat::new(0))))
            .await;
        while let Some(env) = r.recv().await {
            if let Some(t) = want(&env) {
                return t;
            }
        }
    }
    panic!("never saw {what}");
}

fn telemetry(env: &Envelope) -> Option<Telemetry> {
    match &env.body {
        Body::Telemetry(t) => Some(t.clone()),
        _ => None,
    }
}

/// Registers, routes, commands, rejects a wrong channel, stops on silence.
async fn scenario<R: RouterSide>(r: &mut R) {
    register_and_route(r).await;
    drive_on_the_route(r).await;
}

/// The robot's Hello, the router's Welcome (routed to none), then a route
/// to `joy/0`, each acknowledged.
async fn register_and_route<R: RouterSide>(r: &mut R) {
    let hello = wait_for(r, "Hello", |e| match &e.body {
        Body::Hello(h) => Some(h.clone()),
        _ => None,
    })
    .await;
    assert_eq!(
        (hello.name.as_str(), hello.platform.as_str(), hello.motors),
        (NAME, "diff-drive", 2)
    );

    let welcome = Welcome {
        robot_id: 1,
        route: Route {
            robot: NAME.into(),
            channel: String::new(),
            epoch: 0,
        },
        router_version: "fake".into(),
    };
    r.send(&from_router(NAME, "", Body::Welcome(welcome))).await;
    wait_for(r, "RouteAck 0", |e| {
        matches!(&e.body, Body::RouteAck(a) if a.epoch == 0).then_some(())
    })
    .await;

    r.send(&from_router(
        NAME,
        "",
        Body::Route(Route {
            robot: NAME.into(),
            channel: "joy/0".into(),
            epoch: 1,
        }),
    ))
    .await;
    wait_for(r, "RouteAck 1", |e| {
        matches!(&e.body, Body::RouteAck(a) if a.epoch == 1 && a.channel == "joy/0").then_some(())
    })
    .await;
}

/// Obeys `joy/0`, refuses another channel, stops on its silence, resumes.
async fn drive_on_the_route<R: RouterSide>(r: &mut R) {
    // Obeys the routed channel.
    r.send(&from_router(NAME, "joy/0", twist(0.2))).await;
    let t = wait_for(r, "driving telemetry", |e| {
        telemetry(e)
            .filter(|t| t.mode == ControlMode::Twist && t.actuators.iter().all(|u| *u > 0.0))
    })
    .await;
    assert_eq!(t.channel, "joy/0");
    assert_eq!(t.failsafe, FailsafeState::Ok);

    // Rejects another channel: a notice, and the outputs keep their sign.
    r.send(&from_router(NAME, "joy/0", twist(0.2))).await;
    r.send(&from_router(NAME, "key/0", twist(-0.4))).await;
    wait_for(r, "NotRouted notice", |e| {
        matches!(&e.body, Body::Notice(n) if n.code == NoticeCode::NotRouted).then_some(())
    })
    .await;
    r.send(&from_router(NAME, "joy/0", twist(0.2))).await;
    let t = wait_for(r, "telemetry", telemetry).await;
    assert!(
        t.actuators.iter().all(|u| *u >= 0.0),
        "wrong-channel command had an effect: {t:?}"
    );

    // Channel silence (router still alive): stops.
    let t = wait_for(r, "ChannelSilent", |e| {
        telemetry(e).filter(|t| t.failsafe == FailsafeState::ChannelSilent)
    })
    .await;
    assert!(t.actuators.iter().all(|u| *u == 0.0), "{t:?}");
    assert_eq!(t.mode, ControlMode::Idle);

    // The next accepted command resumes.
    r.send(&from_router(NAME, "joy/0", twist(0.2))).await;
    wait_for(r, "resumed", |e| {
        telemetry(e)
            .filter(|t| t.failsafe == FailsafeState::Ok && t.actuators.iter().all(|u| *u > 0.0))
    })
    .await;
}

mod udp {
    use super::*;
    use tokio::net::UdpSocket;

    struct Udp {
        socket: UdpSocket,
        agent: Option<std::net::SocketAddr>,
    }

    impl RouterSide for Udp {
        async fn send(&mut self, env: &Envelope) {
            if let Some(a) = self.agent {
                self.socket
                    .send_to(&mech_proto::encode(env).unwrap(), a)
                    .await
                    .unwrap();
            }
        }
        async fn recv(&mut self) -> Option<Envelope> {
            let mut buf = vec![0; 65536];
            let (n, from) =
                tokio::time::timeout(Duration::from_millis(100), self.socket.recv_from(&mut buf))
                    .await
                    .ok()?
                    .unwrap();
            self.agent = Some(from);
            Some(mech_proto::decode(&buf[..n]).unwrap())
        }
    }

    #[tokio::test]
    async fn agent_over_udp_registers_obeys_rejects_and_stops_on_silence() {
        let socket = UdpSocket::bind("127.0.0.1:0").await.unwrap();
        let router = socket.local_addr().unwrap();
        let (stop, shutdown) = watch::channel(false);
        let agent = tokio::spawn(launch::run(
            config(""),
            Overrides {
                sim: true,
                router: Some(router),
            },
            shutdown,
        ));
        let mut r = Udp {
            socket,
            agent: None,
        };
        scenario(&mut r).await;
        stop.send(true).unwrap();
        agent.await.unwrap().unwrap();
        wait_for(&mut r, "Bye", |e| {
            matches!(e.body, Body::Bye(_)).then_some(())
        })
        .await;
    }
}

#[cfg(feature = "serial")]
mod serial {
    use super::*;
    use std::io::{Read, Write};
    use std::process::{Child, Command as Process, Stdio};

    use mech_proto::framing::{SerialDecoder, write_serial_frame};

    struct Pty {
        writer: std::fs::File,
        rx: tokio::sync::mpsc::UnboundedReceiver<Envelope>,
        /// Every other frame gets garbage and a corrupted copy in front of it.
        sent: usize,
    }

    impl RouterSide for Pty {
        async fn send(&mut self, env: &Envelope) {
            let mut frame = Vec::new();
            write_serial_frame(env, &mut frame).unwrap();
            self.sent += 1;
            if self.sent.is_multiple_of(2) {
                let mut corrupt = frame.clone();
                corrupt[frame.len() / 2] ^= 0x5a;
                self.writer
                    .write_all(&[0x13, 0x37, 0x00, 0xde, 0xad])
                    .unwrap();
                self.writer.write_all(&[0]).unwrap();
                self.writer.write_all(&corrupt).unwrap();
            }
            self.writer.write_all(&frame).unwrap();
            self.writer.flush().unwrap();
        }
        async fn recv(&mut self) -> Option<Envelope> {
            tokio::time::timeout(Duration::from_millis(100), self.rx.recv())
                .await
                .ok()?
        }
    }

    struct Socat(Child);

    impl Drop for Socat {
        fn drop(&mut self) {
            let _ = self.0.kill();
            let _ = self.0.wait();
        }
    }

    #[tokio::test]
    async fn agent_over_serial_pty_survives_corrupt_bytes() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("agent"), dir.path().join("router"));
        let spawned = Process::new("socat")
            .arg(format!("pty,raw,echo=0,link={}", a.display()))
            .arg(format!("pty,raw,echo=0,link={}", b.display()))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn();
        let Ok(child) = spawned else {
            println!("skipping: socat is not installed (needed for the pseudo-terminal pair)");
            return;
        };
        let _socat = Socat(child);
        for _ in 0..200 {
            if a.exists() && b.exists() {
                break;
            }
            tokio::time::sleep(Duration::from_millis(10)).await;
        }
        assert!(
            a.exists() && b.exists(),
            "socat did not create the pty pair"
        );

        let port = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&b)
            .unwrap();
        let mut reader = port.try_clone().unwrap();
        let (tx, rx) = tokio::sync::mpsc::unbounded_channel();
        std::thread::spawn(move || {
            let mut decoder = SerialDecoder::new();
            let mut buf = [0u8; 512];
            while let Ok(n) = reader.read(&mut buf) {
                if n == 0 {
                    break;
                }
                decoder.push(&buf[..n]);
                while let Some(m) = decoder.next_message() {
                    if let Ok(env) = m
                        && tx.send(env).is_err()
                    {
                        return;
                    }
                }
            }
        });

        let link = format!(
            "[link]\nkind = \"serial\"\nport = \"{}\"\nbaud = 115200\n",
            a.display()
        );
        let (stop, shutdown) = watch::channel(false);
        let agent = tokio::spawn(launch::run(
            config(&link),
            Overrides {
                sim: true,
                router: None,
            },
            shutdown,
        ));
        let mut r = Pty {
            writer: port,
            rx,
            sent: 0,
        };
        scenario(&mut r).await;
        stop.send(true).unwrap();
        agent.await.unwrap().unwrap();
        wait_for(&mut r, "Bye", |e| {
            matches!(e.body, Body::Bye(_)).then_some(())
        })
        .await;
    }
}
