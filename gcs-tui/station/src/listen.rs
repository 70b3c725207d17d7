//! The station's listeners: the local control socket (a Unix socket that
//! only its owner and group may open) and, when configured, TCP for
//! operators on other machines.

use std::io::ErrorKind;
use std::net::SocketAddr;
use std::os::unix::fs::{FileTypeExt, PermissionsExt};
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
/// may connect). A socket left by a station that died is replaced; one
/// that answers belongs to a running station and is left alone.
pub fn bind_unix(path: &Path, mode: u32) -> Result<UnixListener, ListenError> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        if !dir.exists() {
            let dir_mode = 0o700 | if mode & 0o060 != 0 { 0o050 } else { 0 };
            std::fs::create_dir_all(dir)
                .and_then(|()| {
                    std::fs::set_permissions(dir, std::fs::Permissions::from_mode(dir_mode))
                })
                .map_err(|source| ListenError::Dir {
                    path: dir.to_owned(),
                    source,
                })?;
        }
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
}
