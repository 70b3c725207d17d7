//! The Foxglove live view end to end: `mech-gcs serve --demo 2 --foxglove
//! 127.0.0.1:0` as a process, and WebSocket clients speaking
//! `foxglove.websocket.v1` as Foxglove and Lichtblick do: the channels and
//! schemas advertised are a recording's, a robot sent on a mission is seen
//! moving on its pose topic and in the scene, and clients that send
//! garbage, flood the server with requests or never read do not stop it.
//! Without the `foxglove` feature, asking for the live view is an error
//! that names the feature. Loopback only.

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
mod live {
    use std::collections::HashMap;
    use std::io::{BufRead, BufReader, Read, Write};
    use std::net::SocketAddr;
    use std::process::{Child, Command, Stdio};
    use std::time::{Duration, Instant};

    use futures::{SinkExt, StreamExt};
    use mech_core::record::schema;
    use serde_json::{Value, json};
    use tokio::net::TcpStream;
    use tokio_tungstenite::WebSocketStream;
    use tokio_tungstenite::tungstenite::Message;
    use tokio_tungstenite::tungstenite::client::IntoClientRequest;
    use tokio_tungstenite::tungstenite::http::HeaderValue;

    use super::Dir;

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

        /// Runs a script attached to the station; panics if it fails.
        fn script(&self, source: &str) {
            let mut child = Command::new(env!("CARGO_BIN_EXE_mech-gcs"))
                .arg("--attach")
                .arg(self.dir.0.join("gcs.sock"))
                .args(["--script", "-"])
                .env("XDG_STATE_HOME", &self.dir.0)
                .stdin(Stdio::piped())
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .expect("mech-gcs --attach --script starts");
            let mut stdin = child.stdin.take().expect("stdin");
            stdin.write_all(source.as_bytes()).expect("script written");
            drop(stdin);
            let out = child.wait_with_output().expect("script ends");
            assert!(
                out.status.success(),
                "{}{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
        }

        /// The station's log files, waiting (up to 20 s) until `needle`
        /// is in them.
        fn log_with(&self, needle: &str) -> String {
            let deadline = Instant::now() + Duration::from_secs(20);
            loop {
                let text: String = std::fs::read_dir(self.dir.0.join("mech"))
                    .into_iter()
                    .flatten()
                    .flatten()
                    .filter(|e| e.file_name().to_string_lossy().starts_with("mech-gcs.log"))
                    .filter_map(|e| std::fs::read_to_string(e.path()).ok())
                    .collect();
                if text.contains(needle) || Instant::now() > deadline {
                    return text;
                }
                std::thread::sleep(Duration::from_millis(200));
            }
        }

        fn alive(&mut self) -> bool {
            matches!(self.child.try_wait(), Ok(None))
        }
    }

    impl Drop for Station {
        fn drop(&mut self) {
            let _ = self.child.kill();
            let _ = self.child.wait();
        }
    }

    /// What a client got.
    #[derive(Debug)]
    enum Got {
        Text(Value),
        Data { sub: u32, ns: u64, msg: Value },
        Closed,
    }

    /// A client as Foxglove is one: advertised channels by topic.
    struct Client {
        ws: WebSocketStream<TcpStream>,
        channels: HashMap<String, Value>,
    }

    async fn handshake(
        addr: SocketAddr,
        subprotocol: bool,
    ) -> Result<WebSocketStream<TcpStream>, String> {
        let tcp = TcpStream::connect(addr).await.map_err(|e| e.to_string())?;
        let mut req = format!("ws://{addr}/")
            .into_client_request()
            .expect("request");
        if subprotocol {
            req.headers_mut().insert(
                "Sec-WebSocket-Protocol",
                HeaderValue::from_static("foxglove.websocket.v1"),
            );
        }
        let (ws, resp) = tokio_tungstenite::client_async(req, tcp)
            .await
            .map_err(|e| e.to_string())?;
        assert_eq!(
            resp.headers()
                .get("Sec-WebSocket-Protocol")
                .map(|v| v.as_bytes()),
            Some(&b"foxglove.websocket.v1"[..])
        );
        Ok(ws)
    }

    impl Client {
        async fn connect(addr: SocketAddr) -> Client {
            let ws = handshake(addr, true).await.expect("handshake");
            let mut c = Client {
                ws,
                channels: HashMap::new(),
            };
            match c.next(Duration::from_secs(10)).await {
                Some(Got::Text(v)) => assert_eq!(v["op"], "serverInfo", "{v}"),
                other => panic!("first message: {other:?}"),
            }
            c
        }

        /// The next message within `wait` (advertised channels noted).
        async fn next(&mut self, wait: Duration) -> Option<Got> {
            let m = match tokio::time::timeout(wait, self.ws.next()).await {
                Err(_) => return None,
                Ok(None | Some(Err(_))) => return Some(Got::Closed),
                Ok(Some(Ok(m))) => m,
            };
            Some(match m {
                Message::Text(t) => {
                    let v: Value = serde_json::from_str(t.as_str()).expect("JSON text");
                    if v["op"] == "advertise" {
                        for ch in v["channels"].as_array().expect("channels") {
                            let topic = ch["topic"].as_str().expect("topic").to_string();
                            self.channels.insert(topic, ch.clone());
                        }
                    }
                    Got::Text(v)
                }
                Message::Binary(b) => {
                    assert_eq!(b[0], 1, "message data");
                    let sub = u32::from_le_bytes(b[1..5].try_into().unwrap());
                    let ns = u64::from_le_bytes(b[5..13].try_into().unwrap());
                    let msg = serde_json::from_slice(&b[13..]).expect("JSON payload");
                    Got::Data { sub, ns, msg }
                }
                Message::Close(_) => Got::Closed,
                _ => Got::Text(Value::Null),
            })
        }

        /// Reads until `topic` is advertised.
        async fn channel(&mut self, topic: &str) -> Value {
            let deadline = Instant::now() + Duration::from_secs(30);
            while !self.channels.contains_key(topic) {
                assert!(Instant::now() < deadline, "{topic} never advertised");
                self.next(Duration::from_secs(1)).await;
            }
            self.channels[topic].clone()
        }

        async fn send(&mut self, v: Value) {
            self.ws
                .send(Message::Text(v.to_string().into()))
                .await
                .expect("sent");
        }

        async fn subscribe(&mut self, sub: u32, topic: &str) {
            let id = self.channel(topic).await["id"].clone();
            self.send(json!({"op": "subscribe", "subscriptions": [{"id": sub, "channelId": id}]}))
                .await;
        }
    }

    /// Each channel is a recording's: the topic, its schema name, the JSON
    /// Schema a recording holds, JSON messages.
    async fn check_channels(c: &mut Client) {
        let expected = [
            (schema::SCENE.to_string(), schema::SCENE_UPDATE),
            (schema::LOG.to_string(), schema::FOXGLOVE_LOG),
            (schema::EVENTS.to_string(), schema::MECH_EVENT),
            (schema::CLUSTERS.to_string(), schema::MECH_CLUSTERS),
            (schema::pose_topic("robot_1"), schema::POSE_IN_FRAME),
            (schema::pose_topic("robot_2"), schema::POSE_IN_FRAME),
            (schema::telemetry_topic("robot_1"), schema::MECH_TELEMETRY),
        ];
        for (topic, name) in expected {
            let ch = c.channel(&topic).await;
            assert_eq!(ch["schemaName"], name, "{topic}");
            assert_eq!(ch["encoding"], "json", "{topic}");
            assert_eq!(ch["schemaEncoding"], "jsonschema", "{topic}");
            let text = ch["schema"].as_str().expect("schema text");
            let sent: Value = serde_json::from_str(text).expect("schema is JSON");
            assert_eq!(sent, schema::schema(name), "{topic}");
        }
    }

    /// A client that sends garbage of every kind is told why and cut; a
    /// plain TCP client and a WebSocket client without the subprotocol are
    /// refused at the handshake.
    async fn garbage(addr: SocketAddr) {
        let mut raw = std::net::TcpStream::connect(addr).expect("tcp");
        raw.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
        raw.write_all(b"\x00\xffGET nonsense\r\n\r\n")
            .expect("garbage sent");
        let mut reply = Vec::new();
        let _ = raw.read_to_end(&mut reply);
        assert!(
            !String::from_utf8_lossy(&reply).contains(" 101 "),
            "no upgrade"
        );
        let Err(err) = handshake(addr, false).await else {
            panic!("a client without the subprotocol is refused")
        };
        assert!(err.contains("400"), "{err}");

        let mut c = Client::connect(addr).await;
        let big = "x".repeat(100 << 10);
        let mut warned = 0;
        for i in 0..100 {
            let m = match i % 4 {
                0 => Message::Text("not json".into()),
                1 => Message::Binary(vec![0xff; 64].into()),
                2 => Message::Text(
                    r#"{"op":"subscribe","subscriptions":[{"id":1,"channelId":9999}]}"#.into(),
                ),
                _ => Message::Text(r#"{"op":"advertise","channels":[]}"#.into()),
            };
            if c.ws.send(m).await.is_err() {
                break;
            }
        }
        let _ = c.ws.send(Message::Text(big.into())).await;
        let deadline = Instant::now() + Duration::from_secs(20);
        loop {
            assert!(Instant::now() < deadline, "the garbage client was not cut");
            match c.next(Duration::from_secs(1)).await {
                Some(Got::Closed) => break,
                Some(Got::Text(v)) if v["op"] == "status" => warned += 1,
                _ => {}
            }
        }
        assert!(warned >= 1, "the client was told why");
    }

    /// A client that floods the server with requests, then subscribes to
    /// everything and never reads again.
    async fn flood(addr: SocketAddr) -> Client {
        let mut c = Client::connect(addr).await;
        check_channels(&mut c).await;
        let ids: Vec<Value> = c.channels.values().map(|ch| ch["id"].clone()).collect();
        for round in 0..2000u32 {
            let id = &ids[round as usize % ids.len()];
            c.send(json!({"op": "subscribe", "subscriptions": [{"id": round, "channelId": id}]}))
                .await;
            c.send(json!({"op": "unsubscribe", "subscriptionIds": [round]}))
                .await;
        }
        let all: Vec<Value> = ids
            .iter()
            .enumerate()
            .map(|(i, id)| json!({"id": 100_000 + i, "channelId": id}))
            .collect();
        c.send(json!({"op": "subscribe", "subscriptions": all}))
            .await;
        c
    }

    fn position(pose: &Value) -> (f64, f64) {
        let p = &pose["pose"]["position"];
        (p["x"].as_f64().expect("x"), p["y"].as_f64().expect("y"))
    }

    fn entity_ids(scene: &Value) -> Vec<String> {
        scene["entities"]
            .as_array()
            .expect("entities")
            .iter()
            .map(|e| e["id"].as_str().expect("id").to_string())
            .collect()
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn the_live_view_shows_the_fleet_moving_and_bad_clients_do_not_hurt_it() {
        let mut station = Station::start("live");
        let mut viewer = Client::connect(station.ws).await;
        check_channels(&mut viewer).await;
        let _flooder = flood(station.ws).await;
        garbage(station.ws).await;

        viewer.subscribe(1, &schema::pose_topic("robot_1")).await;
        viewer.subscribe(2, schema::SCENE).await;
        station.script(
            "wait connected robot_1 20s\nwaypoint robot_1 3.2,2.2 0.6,2.2 0.6,0.6 3.2,0.6 loop\n\
             send robot_1\nroute robot_1 wp/gcs\nwait route robot_1 wp/gcs 20s\n",
        );

        let mut first: Option<(f64, f64)> = None;
        let mut moved = 0.0f64;
        let mut last_ns = 0;
        let mut scene_ids = Vec::new();
        let deadline = Instant::now() + Duration::from_secs(90);
        while moved < 0.5 || !scene_ids.iter().any(|i: &String| i == "mission/robot_1") {
            assert!(
                Instant::now() < deadline,
                "robot_1 moved {moved:.2} m; scene {scene_ids:?}"
            );
            match viewer.next(Duration::from_secs(5)).await {
                Some(Got::Data { sub: 1, ns, msg }) => {
                    assert_eq!(msg["frame_id"], "world");
                    assert!(ns >= last_ns, "time goes forward");
                    last_ns = ns;
                    let p = position(&msg);
                    let p0 = *first.get_or_insert(p);
                    moved = moved.max(((p.0 - p0.0).powi(2) + (p.1 - p0.1).powi(2)).sqrt());
                }
                Some(Got::Data { sub: 2, msg, .. }) => scene_ids = entity_ids(&msg),
                Some(Got::Closed) => panic!("the live view closed the viewer"),
                _ => {}
            }
        }
        assert!(scene_ids.contains(&"robot/robot_1".to_string()));
        assert!(scene_ids.contains(&"robot/robot_2".to_string()));
        assert!(station.alive(), "the station runs on");
        // The station still serves its operators.
        station.script("wait connected robot_2 20s\nstatus\n");
        // The log says who was cut and why.
        let log = station.log_with("too many bad requests");
        assert!(log.contains("Foxglove live view listening"), "{log}");
        assert!(log.contains("too many bad requests"), "{log}");
        assert!(log.contains("Foxglove handshake refused"), "{log}");
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
