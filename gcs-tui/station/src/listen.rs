//! The station's listeners: the local control socket (a Unix socket that
//! only its owner and group may open, in a directory only the station's
//! user may write to) and, when configured, TCP for operators on other
//! machines.
//!
//! Whoever may write to the socket's directory may put a socket of their
//! own in the station's place, and a TUI would attach to it. So the
//! directory must be the station's user's and writable by nobody else
//! ([`check_socket_dir`]), or the station refuses to start; one it
//! creates is made that way (`mkdir` with mode 0700, then checked without
//! following a symbolic link); and a client checks the directory before
//! it attaches (`crate::client`).

use std::io::ErrorKind;
use std::net::SocketAddr;
use std::os::unix::fs::{DirBuilderExt, FileTypeExt, MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};

use tokio::net::{TcpListener, UnixListener};

use crate::server::{Station, Via};

/// Why a listener could not start.
#[derive(Debug, thiserror::Error)]
pub enum ListenError {
    #[error("a station is already running at {0} (attach to it with `mech-gcs`)")]
    Running(PathBuf),
    #[error("{0} exists and is not a socket; remove it or set [station] socket")]
    NotASocket(PathBuf),
    #[error("cannot create the socket directory {path}: {source}")]
    Dir {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(
        "the control socket's directory {path} is not safe: {why}. Whoever may write there can \
         put their own socket in the station's place, and a TUI would attach to it. Remove it \
         (the station makes it afresh), or set [station] socket in a directory only you may \
         write to"
    )]
    UnsafeDir { path: PathBuf, why: String },
    #[error("cannot listen on {what}: {source}")]
    Bind {
        what: String,
        source: std::io::Error,
    },
    #[error(
        "[station] tcp = {0} lets operators attach over the network, which needs the station's [auth] keys (an operator key per person); none are loaded"
    )]
    NoKeys(SocketAddr),
}

/// Binds the control socket at `path` with permission bits `mode`. Its
/// directory is made if missing (owner, plus group search when the group
/// may connect) and must belong to this process's user and be writable by
/// nobody else ([`check_socket_dir`]). A socket left by a station that
/// died is replaced; one that answers belongs to a running station and is
/// left alone.
pub fn bind_unix(path: &Path, mode: u32) -> Result<UnixListener, ListenError> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        let dir_mode = 0o700 | if mode & 0o060 != 0 { 0o050 } else { 0 };
        make_socket_dir(dir, dir_mode)?;
        let me = nix::unistd::geteuid().as_raw();
        check_socket_dir(dir, Some(me)).map_err(|why| ListenError::UnsafeDir {
            path: dir.to_owned(),
            why,
        })?;
    }
    match std::fs::symlink_metadata(path) {
        Ok(m) if !m.file_type().is_socket() => return Err(ListenError::NotASocket(path.into())),
        Ok(_) => {
            if std::os::unix::net::UnixStream::connect(path).is_ok() {
                return Err(ListenError::Running(path.into()));
            }
            let _ = std::fs::remove_file(path);
        }
        Err(e) if e.kind() == ErrorKind::NotFound => {}
        Err(source) => {
            return Err(ListenError::Bind {
                what: path.display().to_string(),
                source,
            });
        }
    }
    let bind_err = |source| ListenError::Bind {
        what: path.display().to_string(),
        source,
    };
    let listener = UnixListener::bind(path).map_err(bind_err)?;
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(mode)).map_err(bind_err)?;
    Ok(listener)
}

/// Makes the socket's directory if it is missing: its parents as usual,
/// itself with `mkdir` mode 0700 (someone else's made meanwhile is left
/// for [`check_socket_dir`] to judge), then `mode`.
fn make_socket_dir(dir: &Path, mode: u32) -> Result<(), ListenError> {
    let err = |source| ListenError::Dir {
        path: dir.to_owned(),
        source,
    };
    if std::fs::symlink_metadata(dir).is_ok() {
        return Ok(());
    }
    if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(err)?;
    }
    match std::fs::DirBuilder::new().mode(0o700).create(dir) {
        Ok(()) => std::fs::set_permissions(dir, std::fs::Permissions::from_mode(mode)).map_err(err),
        Err(e) if e.kind() == ErrorKind::AlreadyExists => Ok(()),
        Err(e) => Err(err(e)),
    }
}

/// Checks that `dir`, a control socket's directory, is a directory (not a
/// symbolic link to one), belongs to the user `owner` when given, and that
/// neither its group nor others may write to it. Says what is wrong.
pub(crate) fn check_socket_dir(dir: &Path, owner: Option<u32>) -> Result<(), String> {
    let m = std::fs::symlink_metadata(dir).map_err(|e| format!("cannot read it: {e}"))?;
    if m.file_type().is_symlink() {
        return Err("it is a symbolic link".into());
    }
    if !m.is_dir() {
        return Err("it is not a directory".into());
    }
    if let Some(uid) = owner.filter(|u| *u != m.uid()) {
        return Err(format!(
            "it belongs to {}, not to {}",
            user_label(m.uid()),
            user_label(uid)
        ));
    }
    let mode = m.mode() & 0o7777;
    if mode & 0o022 != 0 {
        let who = match (mode & 0o020 != 0, mode & 0o002 != 0) {
            (true, true) => "its group and every user",
            (true, false) => "its group",
            _ => "every user",
        };
        return Err(format!("{who} may write to it (mode {mode:o})"));
    }
    Ok(())
}

/// Binds TCP for remote operators; refused without keys to check them.
pub async fn bind_tcp(station: &Station, addr: SocketAddr) -> Result<TcpListener, ListenError> {
    if !station.gcs().router().authenticated() {
        return Err(ListenError::NoKeys(addr));
    }
    TcpListener::bind(addr)
        .await
        .map_err(|source| ListenError::Bind {
            what: format!("TCP {addr}"),
            source,
        })
}

impl Station {
    /// Serves clients of the control socket until the station stops.
    pub fn listen_unix(&self, listener: UnixListener) {
        let station = self.clone();
        self.add_listener(tokio::spawn(async move {
            loop {
                match listener.accept().await {
                    Ok((stream, _)) => {
                        let user = stream
                            .peer_cred()
                            .map_or_else(|_| "unknown".into(), |c| user_name(c.uid()));
                        station.spawn_session(stream, Via::Unix { user });
                    }
                    Err(e) => accept_failed(e).await,
                }
            }
        }));
    }

    /// Serves remote operators over TCP until the station stops.
    pub fn listen_tcp(&self, listener: TcpListener) {
        let station = self.clone();
        self.add_listener(tokio::spawn(async move {
            loop {
                match listener.accept().await {
                    Ok((stream, peer)) => {
                        let _ = stream.set_nodelay(true);
                        station.spawn_session(stream, Via::Tcp { peer });
                    }
                    Err(e) => accept_failed(e).await,
                }
            }
        }));
    }
}

/// An accept error (out of file descriptors, say) is logged and waited
/// out rather than spun on.
async fn accept_failed(e: std::io::Error) {
    tracing::warn!(error = %e, "cannot accept a client");
    tokio::time::sleep(std::time::Duration::from_millis(100)).await;
}

/// The login name of a Unix user id, or `uidN`.
fn user_name(uid: u32) -> String {
    let uid = nix::unistd::Uid::from_raw(uid);
    nix::unistd::User::from_uid(uid)
        .ok()
        .flatten()
        .map_or_else(|| format!("uid{uid}"), |u| u.name)
}

/// A Unix user as a message names it: `nobody (uid 65534)`.
fn user_label(uid: u32) -> String {
    format!("{} (uid {uid})", user_name(uid))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[tokio::test]
    async fn the_socket_is_private_and_a_dead_one_is_replaced() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("run/gcs.sock");
        let l = bind_unix(&path, 0o660).unwrap();
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o660);
        let dir_mode = std::fs::metadata(path.parent().unwrap())
            .unwrap()
            .permissions()
            .mode()
            & 0o777;
        assert_eq!(dir_mode, 0o750);
        // A second station finds the first one running.
        assert!(matches!(
            bind_unix(&path, 0o660),
            Err(ListenError::Running(_))
        ));
        // A station that died left its socket behind: it is replaced.
        drop(l);
        assert!(bind_unix(&path, 0o600).is_ok());
        let file = dir.path().join("plain");
        std::fs::write(&file, "x").unwrap();
        assert!(matches!(
            bind_unix(&file, 0o600),
            Err(ListenError::NotASocket(_))
        ));
    }

    /// A directory another user prepared (world-writable, as anyone can
    /// make the fallback `/tmp/mech-UID` in advance) is refused, saying
    /// why; so is one of ours that others may write to, and a symbolic
    /// link to a good one. Taking another user's directory needs root.
    #[tokio::test]
    async fn a_socket_directory_others_may_write_to_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let theirs = tmp.path().join("mech-0");
        std::fs::create_dir(&theirs).unwrap();
        std::fs::set_permissions(&theirs, std::fs::Permissions::from_mode(0o777)).unwrap();
        if nix::unistd::geteuid().is_root() {
            let nobody = nix::unistd::User::from_name("nobody").unwrap().unwrap();
            std::os::unix::fs::chown(&theirs, Some(nobody.uid.as_raw()), None).unwrap();
            let e = bind_unix(&theirs.join("gcs.sock"), 0o660).unwrap_err();
            let text = e.to_string();
            assert!(
                text.contains("belongs to nobody") && text.contains("own socket"),
                "{text}"
            );
            // Even closed to others, it is still not ours.
            std::fs::set_permissions(&theirs, std::fs::Permissions::from_mode(0o755)).unwrap();
            let e = bind_unix(&theirs.join("gcs.sock"), 0o660).unwrap_err();
            assert!(e.to_string().contains("belongs to nobody"), "{e}");
        } else {
            eprintln!("not root: another user's directory is not tried");
        }
        let ours = tmp.path().join("open");
        std::fs::create_dir(&ours).unwrap();
        std::fs::set_permissions(&ours, std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = bind_unix(&ours.join("gcs.sock"), 0o660).unwrap_err();
        assert!(e.to_string().contains("every user may write"), "{e}");
        std::fs::set_permissions(&ours, std::fs::Permissions::from_mode(0o770)).unwrap();
        let e = bind_unix(&ours.join("gcs.sock"), 0o660).unwrap_err();
        assert!(e.to_string().contains("its group may write"), "{e}");
        let good = tmp.path().join("good");
        std::fs::create_dir(&good).unwrap();
        std::fs::set_permissions(&good, std::fs::Permissions::from_mode(0o700)).unwrap();
        let link = tmp.path().join("link");
        std::os::unix::fs::symlink(&good, &link).unwrap();
        let e = bind_unix(&link.join("gcs.sock"), 0o660).unwrap_err();
        assert!(e.to_string().contains("symbolic link"), "{e}");
        assert!(bind_unix(&good.join("gcs.sock"), 0o660).is_ok());
    }

    /// A missing directory is made private (`mkdir` 0700, then the group
    /// may search it when it may connect), deeper ones too.
    #[tokio::test]
    async fn a_missing_socket_directory_is_made_safely() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("a/b/mech-1000");
        let _l = bind_unix(&dir.join("gcs.sock"), 0o600).unwrap();
        let m = std::fs::symlink_metadata(&dir).unwrap();
        assert!(m.is_dir());
        assert_eq!(m.permissions().mode() & 0o777, 0o700);
        assert_eq!(m.uid(), nix::unistd::geteuid().as_raw());
    }
}
