//! A TUI never attaches to a socket that another user could have put in
//! the station's place: the control socket's directory must be writable
//! by nobody but its owner (and the default socket's must be the user's
//! own), or attaching is refused before connecting.

use std::io::{BufRead, BufReader, Write};
use std::os::unix::fs::PermissionsExt;

use mech_station::client::{Address, AttachError, AttachOptions, attach};
use mech_station::view::Security;
use mech_station::wire::{FromStation, PROTOCOL, Welcome, to_line};

/// An impostor's socket in a world-writable directory (another user's,
/// when the test runs as root) that welcomes whoever attaches.
#[tokio::test]
async fn a_socket_in_a_directory_others_may_write_to_is_not_attached_to() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let dir = tmp.path().join("mech-0");
    std::fs::create_dir(&dir).expect("dir");
    std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o777)).expect("mode");
    if nix::unistd::geteuid().is_root() {
        let nobody = nix::unistd::User::from_name("nobody")
            .expect("users")
            .expect("nobody");
        std::os::unix::fs::chown(&dir, Some(nobody.uid.as_raw()), None).expect("chown");
    }
    let path = dir.join("gcs.sock");
    let impostor = std::os::unix::net::UnixListener::bind(&path).expect("impostor binds");
    std::thread::spawn(move || {
        for stream in impostor.incoming() {
            let Ok(mut s) = stream else { return };
            let mut hello = String::new();
            let _ = BufReader::new(&s).read_line(&mut hello);
            let welcome = FromStation::Welcome(Welcome {
                protocol: PROTOCOL,
                operator: "ana".into(),
                router: "127.0.0.1:7400".into(),
                security: Security::Authenticated,
                pads: "joy/ana".into(),
                keys: "key/ana".into(),
                arena: None,
            });
            let _ = s.write_all(to_line(&welcome).as_bytes());
        }
    });
    let r = attach(&Address::Unix(path), AttachOptions::default()).await;
    let e = r.map(|a| a.welcome).expect_err("refused");
    assert!(
        matches!(&e, AttachError::UnsafeSocket { why, .. } if why.contains("may write")),
        "{e}"
    );
}
