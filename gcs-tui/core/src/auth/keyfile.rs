//! Key files on disk: one secret per file, readable only by its owner,
//! written by `mech-gcs keygen NAME` (the format is
//! [`mech_proto::auth::KeyText`]):
//!
//! ```toml
//! # MECH key for "robot_1" (id 1a2b3c4d). Keep it secret: whoever holds it
//! # can sign as robot_1.
//! name = "robot_1"
//! secret = "<64 hex digits>"
//! ```

use std::io::Write;
use std::path::{Path, PathBuf};

use mech_proto::auth::{KEY_LEN, Key, KeyText};

/// Why a key file could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum KeyFileError {
    #[error("cannot read the key file {path}: {source}")]
    Read {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{path}: {message}")]
    Invalid { path: PathBuf, message: String },
    #[error("{path}: {why}")]
    Exposed { path: PathBuf, why: String },
    #[error("cannot write the key file {path}: {source}")]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{0} exists; remove it first or choose another file (a key is never overwritten)")]
    Exists(PathBuf),
    #[error("the system's random source failed: {0}")]
    Random(String),
}

/// A key as read from its file.
#[derive(Clone)]
pub struct KeyFile {
    /// Who the key belongs to (a robot, controller, operator or e-stop).
    pub name: String,
    pub key: Key,
}

impl std::fmt::Debug for KeyFile {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("KeyFile")
            .field("name", &self.name)
            .field("key", &self.key)
            .finish()
    }
}

impl KeyFile {
    /// Reads a key file; refuses one that others can read.
    pub fn load(path: &Path) -> Result<KeyFile, KeyFileError> {
        check_private(path)?;
        let text = std::fs::read_to_string(path).map_err(|source| KeyFileError::Read {
            path: path.to_owned(),
            source,
        })?;
        let k = KeyText::parse(&text).map_err(|message| KeyFileError::Invalid {
            path: path.to_owned(),
            message,
        })?;
        Ok(KeyFile {
            name: k.name,
            key: k.key,
        })
    }

    /// Makes a new random key for `name` and writes it to `path` (mode
    /// 0600), never overwriting a file. Returns the key.
    pub fn generate(name: &str, path: &Path) -> Result<KeyFile, KeyFileError> {
        let mut secret = [0u8; KEY_LEN];
        getrandom::fill(&mut secret).map_err(|e| KeyFileError::Random(e.to_string()))?;
        let text = KeyText::render(name, &secret);
        KeyText::parse(&text).map_err(|message| KeyFileError::Invalid {
            path: path.to_owned(),
            message,
        })?;
        let write_err = |source| KeyFileError::Write {
            path: path.to_owned(),
            source,
        };
        let mut file = create_private(path).map_err(|e| {
            if e.kind() == std::io::ErrorKind::AlreadyExists {
                KeyFileError::Exists(path.to_owned())
            } else {
                write_err(e)
            }
        })?;
        file.write_all(text.as_bytes()).map_err(write_err)?;
        file.sync_all().map_err(write_err)?;
        Ok(KeyFile {
            name: name.to_string(),
            key: Key::new(&secret),
        })
    }
}

#[cfg(unix)]
fn create_private(path: &Path) -> std::io::Result<std::fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(path)
}

#[cfg(not(unix))]
fn create_private(path: &Path) -> std::io::Result<std::fs::File> {
    std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .open(path)
}

#[cfg(unix)]
fn check_private(path: &Path) -> Result<(), KeyFileError> {
    use std::os::unix::fs::PermissionsExt;
    let meta = std::fs::metadata(path).map_err(|source| KeyFileError::Read {
        path: path.to_owned(),
        source,
    })?;
    mech_proto::auth::private_mode(meta.permissions().mode()).map_err(|why| KeyFileError::Exposed {
        path: path.to_owned(),
        why,
    })
}

#[cfg(not(unix))]
fn check_private(_path: &Path) -> Result<(), KeyFileError> {
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generated_keys_are_private_and_read_back() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("robot_1.key");
        let made = KeyFile::generate("robot_1", &path).unwrap();
        let read = KeyFile::load(&path).unwrap();
        assert_eq!(read.name, "robot_1");
        assert_eq!(read.key.id(), made.key.id());
        assert!(matches!(
            KeyFile::generate("robot_1", &path),
            Err(KeyFileError::Exists(_))
        ));
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
            assert_eq!(mode, 0o600);
            std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
            let e = KeyFile::load(&path).unwrap_err().to_string();
            assert!(e.contains("chmod 600"), "{e}");
        }
    }

    #[test]
    fn a_bad_key_file_names_its_path() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.key");
        create_private(&path)
            .unwrap()
            .write_all(b"name = \"a\"\n")
            .unwrap();
        let e = KeyFile::load(&path).unwrap_err().to_string();
        assert!(e.contains("bad.key") && e.contains("secret"), "{e}");
    }
}
