//! Key files: one secret per file, readable only by its owner, written by
//! `mech-gcs keygen NAME`. A key file is TOML:
//!
//! ```toml
//! # MECH key for "robot_1" (id 1a2b3c4d). Keep it secret: whoever holds it
//! # can sign as robot_1.
//! name = "robot_1"
//! secret = "<64 hex digits>"
//! ```

use std::io::Write;
use std::path::{Path, PathBuf};

use mech_proto::auth::{KEY_LEN, Key, parse_secret};
use serde::Deserialize;

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
    #[error(
        "{path} can be read by other users (mode {mode:o}); a key file must be private: chmod 600 {path}"
    )]
    Exposed { path: PathBuf, mode: u32 },
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

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Raw {
    name: String,
    secret: String,
}

impl KeyFile {
    /// Reads a key file; refuses one that others can read.
    pub fn load(path: &Path) -> Result<KeyFile, KeyFileError> {
        check_private(path)?;
        let text = std::fs::read_to_string(path).map_err(|source| KeyFileError::Read {
            path: path.to_owned(),
            source,
        })?;
        KeyFile::parse(&text).map_err(|message| KeyFileError::Invalid {
            path: path.to_owned(),
            message,
        })
    }

    /// Parses a key file's text.
    pub fn parse(text: &str) -> Result<KeyFile, String> {
        let raw: Raw = toml::from_str(text).map_err(|e| e.message().to_string())?;
        if raw.name.is_empty() || raw.name.len() > mech_proto::MAX_NAME_LEN {
            return Err(format!("name {:?} is not a MECH name", raw.name));
        }
        let secret = parse_secret(&raw.secret).map_err(|e| format!("secret: {e}"))?;
        Ok(KeyFile {
            name: raw.name,
            key: Key::new(&secret),
        })
    }

    /// Makes a new random key for `name` and writes it to `path` (mode
    /// 0600), never overwriting a file. Returns the key.
    pub fn generate(name: &str, path: &Path) -> Result<KeyFile, KeyFileError> {
        let mut secret = [0u8; KEY_LEN];
        getrandom::fill(&mut secret).map_err(|e| KeyFileError::Random(e.to_string()))?;
        let key = Key::new(&secret);
        let hex: String = secret.iter().map(|b| format!("{b:02x}")).collect();
        let text = format!(
            "# MECH key for {name:?} (id {:08x}). Keep it secret: whoever holds it\n\
             # can sign as {name}.\nname = {name:?}\nsecret = \"{hex}\"\n",
            key.id()
        );
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
            key,
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
    let mode = meta.permissions().mode() & 0o777;
    if mode & 0o077 != 0 {
        return Err(KeyFileError::Exposed {
            path: path.to_owned(),
            mode,
        });
    }
    Ok(())
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
    fn bad_key_files_say_what_is_wrong() {
        assert!(
            KeyFile::parse("name = \"a\"\nsecret = \"00\"\n")
                .unwrap_err()
                .contains("64 hex digits")
        );
        assert!(
            KeyFile::parse("name = \"a\"\n")
                .unwrap_err()
                .contains("secret")
        );
        let s = "00".repeat(32);
        assert!(KeyFile::parse(&format!("name = \"\"\nsecret = \"{s}\"\n")).is_err());
        let k = KeyFile::parse(&format!("name = \"a\"\nsecret = \"{s}\"\n")).unwrap();
        assert_eq!(k.key.id(), Key::new(&[0; 32]).id());
    }
}
