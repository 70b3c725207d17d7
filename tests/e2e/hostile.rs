//! Availability under hostile load, end to end: strangers who send nothing
//! valid must not keep controllers or operators out of the real
//! `mech-gcs serve`.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::SocketAddr;
use std::os::unix::fs::PermissionsExt;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use mech_e2e::harness::{Killed, unix_us};
use mech_proto::auth::{Key, KeyText};
use mech_proto::{Body, ChannelsRequest, Envelope, Header};

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

fn write_key(dir: &Path, name: &str, secret: [u8; 32]) -> PathBuf {
    let path = dir.join(format!("{name}.key"));
    std::fs::write(&path, KeyText::render(name, &secret)).expect("key written");
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).expect("key mode");
    path
}

/// A controller's signed channel request, framed for TCP.
fn channels_request(key: &Key) -> Vec<u8> {
    let header = Header {
        seq: 1,
        stamp_us: unix_us(),
        sender: "ctl".into(),
        destination: mech_proto::ROUTER.into(),
        channel: String::new(),
    };
    let body = Body::ChannelsRequest(ChannelsRequest {});
    let mut msg = mech_proto::encode(&Envelope::new(header, body)).expect("encodes");
    key.seal(&mut msg, 0, unix_us()).expect("seals");
    let mut frame = (msg.len() as u32).to_be_bytes().to_vec();
    frame.extend_from_slice(&msg);
    frame
}

/// 1,100 TCP connections to `router` from 69 loopback addresses, held
/// open and silent (those that connected within 2 s each).
fn idle_connections(router: SocketAddr) -> Vec<tokio::net::TcpStream> {
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .expect("runtime");
    runtime.block_on(async {
        let mut held = Vec::new();
        for i in 0..1_100u32 {
            let host = 2 + (i % 69) as u8;
            let s = tokio::net::TcpSocket::new_v4().expect("socket");
            s.bind(SocketAddr::from(([127, 0, 0, host], 0)))
                .expect("bind");
            if let Ok(Ok(c)) = tokio::time::timeout(Duration::from_secs(2), s.connect(router)).await
            {
                held.push(c);
            }
        }
        held
    })
}

/// A controller signing with `secret` asks `router` for its channels over
/// TCP, and is answered.
fn a_signed_controller_is_answered(router: SocketAddr, secret: &[u8; 32]) {
    let mut controller = std::net::TcpStream::connect(router).expect("connects");
    controller
        .set_read_timeout(Some(Duration::from_secs(5)))
        .expect("timeout");
    controller
        .write_all(&channels_request(&Key::new(secret)))
        .expect("sent");
    let mut len = [0u8; 4];
    controller
        .read_exact(&mut len)
        .expect("the router answers the controller");
    let mut answer = vec![0; u32::from_be_bytes(len) as usize];
    controller.read_exact(&mut answer).expect("the answer");
    let answer = mech_proto::decode(&answer).expect("decodes");
    assert!(matches!(answer.body, Body::Channels(_)), "{answer:?}");
}

/// 1,100 connections that never send anything, from 69 addresses, to the
/// router's TCP endpoint of a station that may open 1,024 files (the
/// default limit of a systemd service): a signed TCP controller is still
/// answered and an operator still attaches on the control socket. Without
/// a budget, the idle connections took every descriptor.
#[test]
fn idle_tcp_connections_keep_no_controller_or_operator_out() {
    use nix::sys::resource::{Resource, getrlimit, setrlimit};
    // This test's own end of the connections needs the descriptors.
    let (soft, hard) = getrlimit(Resource::RLIMIT_NOFILE).expect("limits");
    if soft < 4096 {
        setrlimit(Resource::RLIMIT_NOFILE, hard.min(4096), hard).expect("raised");
    }
    let dir = tempfile::tempdir().expect("temp dir");
    let secret = [0x42; 32];
    let ctl = write_key(dir.path(), "ctl", secret);
    let ana = write_key(dir.path(), "ana", [0x43; 32]);
    let (udp, tcp) = (free_port(), free_port());
    let socket = dir.path().join("gcs.sock");
    let config = dir.path().join("gcs.toml");
    std::fs::write(
        &config,
        format!(
            "[router]\nudp = \"127.0.0.1:{udp}\"\ntcp = \"127.0.0.1:{tcp}\"\n\
             [station]\nsocket = {:?}\n\
             [auth]\nmode = \"required\"\n\
             [[auth.keys]]\nrole = \"controller\"\nname = \"ctl\"\nfile = {:?}\nchannels = [\"ext/*\"]\n\
             [[auth.keys]]\nrole = \"operator\"\nname = \"ana\"\nfile = {:?}\n",
            socket.display().to_string(),
            ctl.display().to_string(),
            ana.display().to_string(),
        ),
    )
    .expect("config written");
    let child = Command::new("sh")
        .arg("-c")
        .arg("ulimit -n 1024 && exec \"$0\" serve --config \"$1\"")
        .arg(mech_e2e::binary("mech-gcs"))
        .arg(&config)
        .env("XDG_STATE_HOME", dir.path())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("mech-gcs starts");
    let mut station = Killed(Some(child));
    let mut ready = String::new();
    if let Some(out) = station.0.as_mut().and_then(|c| c.stdout.take()) {
        let _ = BufReader::new(out).read_line(&mut ready);
    }
    assert!(ready.contains("serving"), "{ready:?}");
    let router: SocketAddr = ([127, 0, 0, 1], tcp).into();
    let idle = idle_connections(router);
    assert!(idle.len() >= 1_000, "{} connected", idle.len());

    a_signed_controller_is_answered(router, &secret);

    // An operator attaches on the control socket.
    let mut operator = std::os::unix::net::UnixStream::connect(&socket).expect("connects");
    operator
        .set_read_timeout(Some(Duration::from_secs(5)))
        .expect("timeout");
    operator
        .write_all(b"{\"type\":\"hello\",\"protocol\":1}\n")
        .expect("hello");
    let mut welcome = String::new();
    BufReader::new(operator)
        .read_line(&mut welcome)
        .expect("the station answers");
    assert!(welcome.contains("\"welcome\""), "{welcome}");
    drop(idle);
}
