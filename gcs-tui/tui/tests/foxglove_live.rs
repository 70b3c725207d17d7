//! The Foxglove live view of the `mech-gcs` binary (built with the
//! `foxglove` feature, which turns on mech-station's): `mech-gcs serve
//! --demo 2 --foxglove 127.0.0.1:0` names the view in its ready line and a
//! viewer speaking `foxglove.websocket.v1` gets a recording's channels
//! from it; the TUI's own station (`mech-gcs --demo 2 --foxglove ADDR` in
//! a terminal) and a script's (`--script` without `--attach`) serve it too. Without the feature, asking for the live
//! view is an error that names the feature. The live view itself (moving
//! robots, bad clients) is tested in mech-station. Loopback only.

use std::path::PathBuf;

/// A scratch directory (state, logs, socket), removed on drop.
struct Dir(PathBuf);

impl Dir {
    fn new(tag: &str) -> Dir {
        let dir = std::env::temp_dir().join(format!("mech-foxglove-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        Dir(dir)
    }
}

impl Drop for Dir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[cfg(not(feature = "foxglove"))]
#[test]
fn without_the_feature_asking_for_the_live_view_is_an_error_naming_it() {
    use std::process::{Command, Stdio};
    let dir = Dir::new("off");
    let out = Command::new(env!("CARGO_BIN_EXE_mech-gcs"))
        .args(["serve", "--udp", "127.0.0.1:0", "--tcp", "127.0.0.1:0"])
        .args(["--foxglove", "127.0.0.1:0"])
        .arg("--socket")
        .arg(dir.0.join("gcs.sock"))
        .env("XDG_STATE_HOME", &dir.0)
        .stdin(Stdio::null())
        .output()
        .expect("mech-gcs runs");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("feature `foxglove`"), "{stderr}");
    assert!(out.stdout.is_empty(), "no station started");
}

#[cfg(feature = "foxglove")]
#[allow(dead_code)]
#[path = "../../station/tests/support/foxglove.rs"]
mod foxglove;

#[cfg(feature = "foxglove")]
mod live {
    use std::io::{BufRead, BufReader};
    use std::net::SocketAddr;
    use std::process::{Child, Command, Stdio};
    use std::time::{Duration, Instant};

    use mech_core::record::schema;

    use super::Dir;
    use futures::SinkExt;
    use serde_json::json;
    use tokio_tungstenite::tungstenite::Message;

    use super::foxglove::{Client, Got, check_channels, handshake, handshake_over};

    /// The log line of a client the station cut.
    const CUT: &str = "Foxglove client cut:";

    /// A client that sends a million WebSocket pings and never reads is
    /// cut, and is told why: the station reads nothing more from it while
    /// the pong it owes is not taken, so pongs never pile up in the
    /// station (they did: about 124 bytes each, 1,000,000 pings grew it
    /// by 120 MB, and it was never cut), and it answers none of the
    /// station's pings. When the log says it was cut, the pinger reads at
    /// last: the pongs the kernel held, a status message and a close frame
    /// (1008, policy) with the reason.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_client_that_pings_and_never_reads_is_cut_and_told_why() {
        let station = Station::start("pinger");
        let mut pinger = Client::connect(station.ws).await;
        let ping = Message::Ping(vec![0x5a; 120].into());
        let mut sent = 0u32;
        let deadline = Instant::now() + Duration::from_secs(120);
        while !station.log().contains(CUT) {
            assert!(
                Instant::now() < deadline,
                "the pinger ({sent} pings sent) was not cut: {}",
                station.log()
            );
            if sent >= 1_000_000 {
                tokio::time::sleep(Duration::from_millis(200)).await;
                continue;
            }
            // A burst, then a look at the log; a burst the station does
            // not take (it stopped reading) is left to the kernel.
            let burst = async {
                for _ in 0..1000 {
                    pinger.ws.feed(ping.clone()).await?;
                }
                pinger.ws.flush().await
            };
            match tokio::time::timeout(Duration::from_millis(500), burst).await {
                Ok(Ok(())) => sent += 1000,
                Ok(Err(_)) => break,
                Err(_) => {}
            }
        }
        let closing = pinger.closing(Duration::from_secs(60)).await;
        assert_eq!(closing.code, Some(1008), "{closing:?}");
        assert!(closing.reason.contains("did not read"), "{closing:?}");
        assert!(
            closing.statuses.iter().any(|s| s.contains("did not read")),
            "{closing:?}"
        );
        let log = station.log();
        assert!(log.contains("did not read for 10 s"), "{log}");
    }

    /// A viewer subscribed to every channel that stops reading is cut
    /// within the documented 10 s of not reading (the test allows 60),
    /// although its kernel holds megabytes before the station's sends
    /// would block (its receive buffer is set large here, as a viewer's
    /// grows while it reads fast): the station pings every client, and
    /// one that answers none for 10 s does not read. Then it is told why,
    /// as the pinger is.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_viewer_that_stops_reading_is_cut_within_the_documented_time_and_told_why() {
        let station = Station::start("stalled");
        let socket = tokio::net::TcpSocket::new_v4().expect("socket");
        socket
            .set_recv_buffer_size(4 << 20)
            .expect("receive buffer");
        let tcp = socket.connect(station.ws).await.expect("connected");
        let ws = handshake_over(tcp, station.ws, true)
            .await
            .expect("handshake");
        let mut viewer = Client::over(ws).await;
        check_channels(&mut viewer).await;
        let all: Vec<serde_json::Value> = viewer
            .channels
            .values()
            .enumerate()
            .map(|(i, ch)| json!({"id": i, "channelId": ch["id"]}))
            .collect();
        viewer
            .send(json!({"op": "subscribe", "subscriptions": all}))
            .await;
        // It gets data, then reads no more.
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            assert!(Instant::now() < deadline, "no data");
            if let Some(Got::Data { .. }) = viewer.next(Duration::from_secs(5)).await {
                break;
            }
        }
        let stopped = Instant::now();
        assert!(
            station.logged(CUT, Duration::from_secs(60)).await,
            "the viewer was not cut 60 s after it stopped reading: {}",
            station.log()
        );
        // For the record (docs/recording.md), not a limit.
        println!(
            "cut {:.1} s after it stopped reading",
            stopped.elapsed().as_secs_f64()
        );
        let closing = viewer.closing(Duration::from_secs(60)).await;
        assert_eq!(closing.code, Some(1008), "{closing:?}");
        assert!(closing.reason.contains("did not read"), "{closing:?}");
        assert!(station.log().contains("did not read for 10 s"));
    }

    /// A message over the 64 KiB a request may be is counted and closes
    /// the connection with a status message and close code 1009 (message
    /// too big) with the reason, as the docs say; the log says so too.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_message_over_64_kib_closes_with_1009_and_a_reason() {
        let station = Station::start("big");
        let mut c = Client::connect(station.ws).await;
        let big = json!({"op": "subscribe", "subscriptions": [], "pad": "x".repeat(70 << 10)});
        c.ws.send(Message::Text(big.to_string().into()))
            .await
            .expect("sent");
        let closing = c.closing(Duration::from_secs(60)).await;
        assert_eq!(closing.code, Some(1009), "{closing:?}");
        assert!(closing.reason.contains("64 KiB"), "{closing:?}");
        assert!(
            closing.statuses.iter().any(|s| s.contains("64 KiB")),
            "{closing:?}"
        );
        assert!(
            station
                .logged("message too big", Duration::from_secs(20))
                .await,
            "{}",
            station.log()
        );
        // The station still serves viewers.
        let mut viewer = Client::connect(station.ws).await;
        check_channels(&mut viewer).await;
    }

    /// `mech-gcs serve --demo 2 --foxglove 127.0.0.1:0`, killed on drop.
    struct Station {
        child: Child,
        ws: SocketAddr,
        dir: Dir,
    }

    impl Station {
        fn start(tag: &str) -> Station {
            let dir = Dir::new(tag);
            let stderr = std::fs::File::create(dir.0.join("stderr.log")).expect("log");
            let mut child = Command::new(env!("CARGO_BIN_EXE_mech-gcs"))
                .args([
                    "serve",
                    "--demo",
                    "2",
                    "--udp",
                    "127.0.0.1:0",
                    "--tcp",
                    "127.0.0.1:0",
                ])
                .args(["--foxglove", "127.0.0.1:0", "--socket"])
                .arg(dir.0.join("gcs.sock"))
                .env("XDG_STATE_HOME", &dir.0)
                .stdin(Stdio::null())
                .stdout(Stdio::piped())
                .stderr(stderr)
                .spawn()
                .expect("mech-gcs serve starts");
            let out = child.stdout.take().expect("stdout piped");
            let mut lines = BufReader::new(out).lines();
            let line = lines.next().and_then(Result::ok).unwrap_or_else(|| {
                let _ = child.kill();
                let _ = child.wait();
                let err = std::fs::read_to_string(dir.0.join("stderr.log")).unwrap_or_default();
                panic!("mech-gcs serve printed no ready line: {err}")
            });
            // Keep draining stdout so the station never blocks on it.
            std::thread::spawn(move || for _ in lines {});
            let ws = line
                .split("Foxglove live view on ws://")
                .nth(1)
                .and_then(|a| a.trim().parse().ok())
                .unwrap_or_else(|| panic!("no live view address in {line:?}"));
            Station { child, ws, dir }
        }
    }

    impl Station {
        /// What the station logged so far (its log files and stderr).
        fn log(&self) -> String {
            let logs = self.dir.0.join("mech");
            let mut text: String = std::fs::read_dir(&logs)
                .into_iter()
                .flatten()
                .flatten()
                .filter(|e| e.file_name().to_string_lossy().starts_with("mech-gcs.log"))
                .filter_map(|e| std::fs::read_to_string(e.path()).ok())
                .collect();
            text += &std::fs::read_to_string(self.dir.0.join("stderr.log")).unwrap_or_default();
            text
        }

        /// Waits (up to `wait`) until the log holds `needle`.
        async fn logged(&self, needle: &str, wait: Duration) -> bool {
            let deadline = Instant::now() + wait;
            while Instant::now() < deadline {
                if self.log().contains(needle) {
                    return true;
                }
                tokio::time::sleep(Duration::from_millis(200)).await;
            }
            false
        }
    }

    impl Drop for Station {
        fn drop(&mut self) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn the_served_station_names_its_live_view_in_the_ready_line() {
        let station = Station::start("served");
        let mut viewer = Client::connect(station.ws).await;
        check_channels(&mut viewer).await;
        assert!(
            station.dir.0.join("gcs.sock").exists(),
            "it serves its operators"
        );
    }

    /// `mech-gcs --demo 2 --foxglove ADDR --script FILE` serves the live
    /// view for as long as its script runs, naming it on stderr; with
    /// `--attach` the flag is refused, since an attached station serves its
    /// own.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_script_run_serves_the_live_view_and_an_attached_one_says_it_cannot() {
        let dir = Dir::new("script");
        let script = dir.0.join("hold.mech");
        std::fs::write(&script, "sleep 60s\n").expect("script");
        let mut child = Command::new(env!("CARGO_BIN_EXE_mech-gcs"))
            .args([
                "--demo",
                "2",
                "--udp",
                "127.0.0.1:0",
                "--tcp",
                "127.0.0.1:0",
            ])
            .args(["--foxglove", "127.0.0.1:0", "--script"])
            .arg(&script)
            .env("XDG_STATE_HOME", &dir.0)
            .stdin(Stdio::null())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("mech-gcs --script starts");
        let err = child.stderr.take().expect("stderr piped");
        let mut lines = BufReader::new(err).lines();
        let mut said = Vec::new();
        let ws: Option<SocketAddr> = loop {
            let Some(Ok(line)) = lines.next() else {
                break None;
            };
            if let Some(a) = line.split("Foxglove live view on ws://").nth(1) {
                break a.trim().parse().ok();
            }
            said.push(line);
        };
        std::thread::spawn(move || for _ in lines {});
        let Some(ws) = ws else {
            let _ = child.kill();
            let _ = child.wait();
            panic!("the script run named no live view: {said:?}");
        };
        let mut viewer = Client::connect(ws).await;
        check_channels(&mut viewer).await;
        let _ = child.kill();
        let _ = child.wait();

        let out = Command::new(env!("CARGO_BIN_EXE_mech-gcs"))
            .arg("--attach")
            .arg(dir.0.join("nobody.sock"))
            .args(["--foxglove", "127.0.0.1:0", "--script"])
            .arg(&script)
            .env("XDG_STATE_HOME", &dir.0)
            .stdin(Stdio::null())
            .output()
            .expect("mech-gcs runs");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_ne!(out.status.code(), Some(0), "{stderr}");
        assert!(stderr.contains("serves its own"), "{stderr}");
    }

    /// A tmux server, killed on drop.
    struct Tmux(String);

    impl Drop for Tmux {
        fn drop(&mut self) {
            let _ = Command::new("tmux")
                .args(["-L", &self.0, "kill-server"])
                .output();
        }
    }

    /// The TUI's own station (`mech-gcs --demo 2 --foxglove ADDR` in a
    /// terminal) serves the live view too.
    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn the_tuis_own_station_serves_the_live_view() {
        if Command::new("tmux").arg("-V").output().is_err() {
            println!("skipped: tmux is not installed");
            return;
        }
        let dir = Dir::new("tui");
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .expect("a free port")
            .port();
        let cmd = format!(
            "exec env XDG_STATE_HOME={} {} --demo 2 --no-mouse --udp 127.0.0.1:0 --tcp 127.0.0.1:0 \
             --foxglove 127.0.0.1:{port} 2>{}/tui.err",
            dir.0.display(),
            env!("CARGO_BIN_EXE_mech-gcs"),
            dir.0.display()
        );
        let tmux = Tmux(format!("mech-foxglove-tui-{}", std::process::id()));
        let started = Command::new("tmux")
            .args([
                "-L",
                &tmux.0,
                "new-session",
                "-d",
                "-s",
                "tui",
                "-x",
                "120",
                "-y",
                "40",
                &cmd,
            ])
            .output()
            .expect("tmux runs");
        assert!(started.status.success(), "{started:?}");
        let addr = SocketAddr::from(([127, 0, 0, 1], port));
        let deadline = Instant::now() + Duration::from_secs(30);
        let mut viewer = loop {
            if handshake(addr, true).await.is_ok() {
                break Client::connect(addr).await;
            }
            if Instant::now() > deadline {
                let screen = Command::new("tmux")
                    .args(["-L", &tmux.0, "capture-pane", "-p", "-t", "tui"])
                    .output()
                    .map(|o| String::from_utf8_lossy(&o.stdout).into_owned());
                let err = std::fs::read_to_string(dir.0.join("tui.err"));
                panic!("the TUI's live view never listened: {screen:?} {err:?}");
            }
            tokio::time::sleep(Duration::from_millis(200)).await;
        };
        viewer.subscribe(1, &schema::pose_topic("robot_2")).await;
        let deadline = Instant::now() + Duration::from_secs(30);
        loop {
            assert!(Instant::now() < deadline, "no pose of robot_2");
            if let Some(Got::Data { sub: 1, msg, .. }) = viewer.next(Duration::from_secs(5)).await {
                assert_eq!(msg["frame_id"], "world");
                break;
            }
        }
    }
}
