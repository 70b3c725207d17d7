//! Attaching over TCP: only with an operator key the station lists, proved
//! by signing a fresh challenge; the key names the operator.

use std::net::SocketAddr;
use std::time::Duration;

use mech_core::auth::{AuthConfig, AuthMode, KeyEntry, KeyFile, Role};
use mech_core::{CoreConfig, Gcs};
use mech_station::client::{Address, AttachError, AttachOptions, KeyFileRef, attach};
use mech_station::wire::{
    FromStation, MAX_LINE, PROTOCOL, ToStation, challenge_region, hex, read_message, to_line, unhex,
};
use mech_station::{ListenError, Station, StationConfig, bind_tcp};
use tempfile::TempDir;
use tokio::io::{AsyncBufReadExt, AsyncWriteExt, BufReader};

struct Keyed {
    station: Station,
    addr: SocketAddr,
    dir: TempDir,
}

impl Keyed {
    /// An authenticating station with an operator key (`ana`) and a robot
    /// key (`robot_1`), listening for operators over TCP on loopback.
    async fn start() -> Keyed {
        let dir = tempfile::tempdir().expect("temp dir");
        let mut auth = AuthConfig {
            mode: Some(AuthMode::Required),
            ..AuthConfig::default()
        };
        for (role, name) in [(Role::Operator, "ana"), (Role::Robot, "robot_1")] {
            let file = dir.path().join(format!("{name}.key"));
            KeyFile::generate(name, &file).expect("key written");
            auth.keys.push(KeyEntry {
                role,
                name: name.into(),
                file,
                channels: Vec::new(),
            });
        }
        let mut config = CoreConfig {
            auth,
            ..CoreConfig::default()
        };
        config.router.udp = SocketAddr::from(([127, 0, 0, 1], 0));
        config.router.tcp = None;
        let gcs = Gcs::start(config).await.expect("station starts");
        let station = Station::start(gcs, &[], None, &StationConfig::default());
        let listener = bind_tcp(&station, SocketAddr::from(([127, 0, 0, 1], 0)))
            .await
            .expect("TCP for operators");
        let addr = listener.local_addr().expect("bound");
        station.listen_tcp(listener);
        Keyed { station, addr, dir }
    }

    fn key(&self, name: &str) -> KeyFileRef {
        KeyFile::load(&self.dir.path().join(format!("{name}.key")))
            .expect("key read")
            .into()
    }

    async fn attach_as(
        &self,
        key: Option<KeyFileRef>,
        operator: Option<&str>,
    ) -> Result<String, AttachError> {
        let opts = AttachOptions {
            key,
            operator: operator.map(str::to_string),
            ..AttachOptions::default()
        };
        attach(&Address::Tcp(self.addr.to_string()), opts)
            .await
            .map(|a| format!("{} {}", a.welcome.operator, a.welcome.pads))
    }
}

#[tokio::test]
async fn an_operator_key_attaches_and_names_the_operator() {
    let k = Keyed::start().await;
    let who = k
        .attach_as(Some(k.key("ana")), None)
        .await
        .expect("attached");
    assert_eq!(who, "ana joy/ana", "the key's name, and pads of her own");
    k.station.shutdown().await;
}

#[tokio::test]
async fn no_key_a_robot_key_or_a_false_name_is_refused() {
    let k = Keyed::start().await;
    assert!(matches!(
        k.attach_as(None, None).await,
        Err(AttachError::NeedKey)
    ));
    let robot = k.attach_as(Some(k.key("robot_1")), None).await;
    assert!(
        matches!(&robot, Err(AttachError::Refused(r)) if r.contains("operator key")),
        "{robot:?}"
    );
    let liar = k.attach_as(Some(k.key("ana")), Some("bob")).await;
    assert!(
        matches!(&liar, Err(AttachError::Refused(r)) if r.contains("not \"bob\"")),
        "{liar:?}"
    );
    // A key the station does not list.
    let dir = tempfile::tempdir().expect("temp dir");
    let stranger = KeyFile::generate("ana", &dir.path().join("x.key")).expect("key");
    let r = k.attach_as(Some(stranger.into()), None).await;
    assert!(
        matches!(&r, Err(AttachError::Refused(m)) if m.contains("not listed")),
        "{r:?}"
    );
    // Each refusal is in the event log (the keyless client hung up at the
    // challenge).
    let refusals = k.station.gcs().with_fleet(|f| {
        f.log
            .iter()
            .filter(|e| e.text.starts_with("attach refused"))
            .count()
    });
    assert_eq!(refusals, 4);
    k.station.shutdown().await;
}

#[tokio::test]
async fn an_answer_to_another_challenge_does_not_attach() {
    let k = Keyed::start().await;
    let ana = k.key("ana");
    // A tag an eavesdropper saw, for some earlier challenge.
    let old_tag = ana.key.sign(&challenge_region(&[7u8; 32], "ana"), 0, 0);
    let stream = tokio::net::TcpStream::connect(k.addr)
        .await
        .expect("connect");
    let (rd, mut wr) = tokio::io::split(stream);
    let mut rd = BufReader::new(rd);
    let hello = ToStation::Hello {
        protocol: PROTOCOL,
        operator: None,
        stream: Default::default(),
    };
    wr.write_all(to_line(&hello).as_bytes())
        .await
        .expect("hello");
    let mut buf = Vec::new();
    let challenge = read_message::<FromStation>(&mut rd, &mut buf, MAX_LINE)
        .await
        .expect("readable")
        .expect("a challenge");
    let FromStation::Challenge { nonce } = challenge else {
        panic!("expected a challenge, got {challenge:?}");
    };
    assert_eq!(unhex(&nonce).map(|n| n.len()), Some(32));
    let replay = ToStation::Auth { tag: hex(&old_tag) };
    wr.write_all(to_line(&replay).as_bytes())
        .await
        .expect("auth");
    let answer = tokio::time::timeout(
        Duration::from_secs(5),
        read_message::<FromStation>(&mut rd, &mut buf, MAX_LINE),
    )
    .await
    .expect("answered")
    .expect("readable");
    assert!(
        matches!(&answer, Some(FromStation::Bye { reason }) if reason.contains("does not verify")),
        "{answer:?}"
    );
    k.station.shutdown().await;
}

#[tokio::test]
async fn an_unauthenticated_station_does_not_listen_for_operators() {
    let mut config = CoreConfig::default();
    config.router.udp = SocketAddr::from(([127, 0, 0, 1], 0));
    config.router.tcp = None;
    let gcs = Gcs::start(config).await.expect("station starts");
    let station = Station::start(gcs, &[], None, &StationConfig::default());
    let r = bind_tcp(&station, SocketAddr::from(([127, 0, 0, 1], 0))).await;
    assert!(matches!(r, Err(ListenError::NoKeys(_))), "{r:?}");
    station.shutdown().await;
}

#[tokio::test]
async fn garbage_from_a_client_is_refused_and_a_flood_of_it_hangs_up() {
    let mut config = CoreConfig::default();
    config.router.udp = SocketAddr::from(([127, 0, 0, 1], 0));
    config.router.tcp = None;
    let gcs = Gcs::start(config).await.expect("station starts");
    let station = Station::start(gcs, &[], None, &StationConfig::default());
    let (rd, mut wr) = tokio::io::split(station.attach_local());
    let mut rd = BufReader::new(rd);
    let mut buf = Vec::new();
    let mut next = async |rd: &mut BufReader<_>| {
        tokio::time::timeout(
            Duration::from_secs(5),
            read_message::<FromStation>(rd, &mut buf, MAX_LINE),
        )
        .await
        .expect("answered")
        .expect("readable")
        .expect("open")
    };
    let hello = ToStation::Hello {
        protocol: PROTOCOL,
        operator: Some("ana".into()),
        stream: Default::default(),
    };
    wr.write_all(to_line(&hello).as_bytes()).await.unwrap();
    assert!(matches!(next(&mut rd).await, FromStation::Welcome(_)));
    // Not JSON, a message of no known type, a bad command: each refused
    // with a reason, and the session goes on.
    wr.write_all(b"\xff\xfe not json\n").await.unwrap();
    let m = next(&mut rd).await;
    assert!(
        matches!(&m, FromStation::Refused { reason } if reason.contains("bad message")),
        "{m:?}"
    );
    tokio::time::sleep(Duration::from_millis(1100)).await;
    let nan = r#"{"type":"publish","channel":"joy/0","robots":["r"],"command":[4,{"vx":NaN,"vy":0,"vz":0,"wz":0}]}"#;
    wr.write_all(format!("{nan}\n").as_bytes()).await.unwrap();
    let m = next(&mut rd).await;
    assert!(matches!(&m, FromStation::Refused { .. }), "{m:?}");
    let line = ToStation::Line {
        id: 1,
        text: "status".into(),
    };
    wr.write_all(to_line(&line).as_bytes()).await.unwrap();
    let m = next(&mut rd).await;
    assert!(
        matches!(&m, FromStation::Result(r) if r.id == 1 && r.ok),
        "{m:?}"
    );
    // A flood of garbage ends the session.
    let flood = "garbage\n".repeat(200);
    wr.write_all(flood.as_bytes()).await.unwrap();
    let bye = loop {
        match next(&mut rd).await {
            FromStation::Bye { reason } => break reason,
            FromStation::Refused { .. } => {}
            other => panic!("{other:?}"),
        }
    };
    assert!(bye.contains("bad messages"), "{bye}");
    station.shutdown().await;
}

/// The documented Python client (docs/examples/attach.py) proves its
/// operator key over TCP and runs a line; its tag function is the one
/// docs/control-protocol.md shows.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_documented_python_client_attaches_with_its_key() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let example = root.join("docs/examples/attach.py");
    let doc = std::fs::read_to_string(root.join("docs/control-protocol.md")).expect("doc");
    let code = std::fs::read_to_string(&example).expect("example");
    let snippet = doc
        .split("```python\n")
        .nth(1)
        .and_then(|s| s.split("```").next())
        .expect("a python block in the doc");
    let body = snippet.trim_start_matches("import hashlib, hmac, struct\n");
    assert!(
        code.contains(body),
        "docs/control-protocol.md and attach.py differ:\n{body}"
    );
    if std::process::Command::new("python3")
        .arg("-V")
        .output()
        .is_err()
    {
        println!("skipped: python3 is not installed");
        return;
    }
    let k = Keyed::start().await;
    let key = k.dir.path().join("ana.key");
    let addr = k.addr.to_string();
    let out = tokio::task::spawn_blocking(move || {
        std::process::Command::new("python3")
            .arg(&example)
            .args(["--tcp", &addr, "--key"])
            .arg(&key)
            .arg("status")
            .output()
    })
    .await
    .expect("joined")
    .expect("python3 runs");
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("attached as ana"), "{text}");
    assert!(text.contains("status: 0 robots"), "{text}");
    k.station.shutdown().await;
}

/// Idle connections to the attach port (64, from 16 addresses, never
/// saying hello) keep nobody out: an operator still attaches on the
/// control socket, and one with a key over TCP.
#[tokio::test]
async fn idle_connections_to_the_attach_port_keep_no_operator_out() {
    let k = Keyed::start().await;
    let path = k.dir.path().join("gcs.sock");
    k.station
        .listen_unix(mech_station::bind_unix(&path, 0o600).expect("control socket"));
    let mut idle = Vec::new();
    for i in 0..64u8 {
        let s = tokio::net::TcpSocket::new_v4().expect("socket");
        s.bind(SocketAddr::from(([127, 0, 0, 10 + i / 4], 0)))
            .expect("bind");
        idle.push(s.connect(k.addr).await.expect("connects"));
    }
    // Each new one took the place of the one attaching longest: the first
    // 48 are told so.
    for (i, c) in idle.iter_mut().take(48).enumerate() {
        let mut line = String::new();
        let mut rd = BufReader::new(c);
        let _ = tokio::time::timeout(Duration::from_secs(5), rd.read_line(&mut line)).await;
        assert!(line.contains("waited longest"), "{i}: {line:?}");
    }
    let local = tokio::time::timeout(
        Duration::from_secs(5),
        attach(&Address::Unix(path), AttachOptions::default()),
    )
    .await
    .expect("answered");
    assert!(local.is_ok(), "{local:?}");
    let who = tokio::time::timeout(
        Duration::from_secs(5),
        k.attach_as(Some(k.key("ana")), None),
    )
    .await
    .expect("answered");
    assert_eq!(who.expect("attached over TCP"), "ana joy/ana");
    drop(idle);
    k.station.shutdown().await;
}

/// A client that fails its handshake is answered a second later (guessing
/// keys is slow), but keeps its place among those attaching meanwhile: a
/// newer client from the same address takes the place and ends the wait.
/// So a flood of failing clients holds no more connections open than the
/// address's places (4), where each used to be held for a whole second.
#[tokio::test]
async fn failing_clients_wait_for_their_answer_only_while_they_hold_a_place() {
    let k = Keyed::start().await;
    let n = 20;
    let mut waits = Vec::new();
    for _ in 0..n {
        let mut c = tokio::net::TcpStream::connect(k.addr)
            .await
            .expect("connects");
        c.write_all(b"garbage\n").await.expect("sent");
        let started = tokio::time::Instant::now();
        waits.push(tokio::spawn(async move {
            let mut rest = Vec::new();
            let read = tokio::io::AsyncReadExt::read_to_end(&mut c, &mut rest);
            let _ = tokio::time::timeout(Duration::from_secs(5), read).await;
            (
                started.elapsed(),
                String::from_utf8_lossy(&rest).into_owned(),
            )
        }));
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let mut answered_early = 0;
    for w in waits {
        let (waited, said) = w.await.expect("reader");
        assert!(said.contains("bye"), "{said:?}");
        if waited < Duration::from_millis(500) {
            answered_early += 1;
        }
    }
    // All but the newest 4 were answered when a newer client took their
    // place, long before their second was up.
    assert!(answered_early >= n - 4, "{answered_early} of {n}");
    k.station.shutdown().await;
}
