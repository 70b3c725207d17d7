//! Where mission files may be. The station process reads and writes them,
//! on the station's machine, whoever typed the command. A script the
//! station runs itself (`mech-gcs --script`) is the station's owner
//! speaking: its paths are taken as given. An operator's session (a TUI, or
//! `--attach --script`, possibly over TCP from another machine with only an
//! operator key) may drive robots but has no account on the station's
//! machine: left free, `mission save` would overwrite any file the station
//! may write (its keys, its configuration) and `mission load` would quote
//! any file it may read in its errors. So an operator names a file in the
//! station's missions directory: a relative path, no `..`, and no symbolic
//! link leading out of it.

use std::path::{Component, Path, PathBuf};

/// How a session's mission file names are turned into paths.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileAccess {
    /// As given (relative to the station's working directory).
    Station,
    /// Only inside this directory (created when a file is saved).
    Confined(PathBuf),
}

impl FileAccess {
    /// The path `name` stands for, or why it may not be used. `saving`:
    /// the directories on the way are created (inside the missions
    /// directory only).
    pub fn resolve(&self, name: &str, saving: bool) -> Result<PathBuf, String> {
        let dir = match self {
            FileAccess::Station => return Ok(PathBuf::from(name)),
            FileAccess::Confined(dir) => dir,
        };
        let relative = Path::new(name);
        let plain = relative
            .components()
            .all(|c| matches!(c, Component::Normal(_) | Component::CurDir));
        if name.is_empty() || !plain {
            return Err(format!(
                "{name:?}: from an operator's session a mission file is a name in the \
                 station's missions directory {} (no absolute path, no `..`)",
                dir.display()
            ));
        }
        let path = dir.join(relative);
        let parent = path.parent().unwrap_or(dir);
        if saving {
            std::fs::create_dir_all(parent)
                .map_err(|e| format!("cannot create {}: {e}", parent.display()))?;
        }
        let inside = |p: &Path| -> Result<bool, String> {
            let real_dir = dir
                .canonicalize()
                .map_err(|e| format!("missions directory {}: {e}", dir.display()))?;
            Ok(p.canonicalize().is_ok_and(|r| r.starts_with(&real_dir)))
        };
        if !inside(parent)? {
            return Err(format!(
                "{name:?} leads out of the missions directory {}",
                dir.display()
            ));
        }
        // An existing file may itself be a link out of the directory.
        if path.symlink_metadata().is_ok() && !inside(&path)? {
            return Err(format!(
                "{name:?} leads out of the missions directory {}",
                dir.display()
            ));
        }
        Ok(path)
    }
}

/// The missions directory when the configuration names none:
/// `$XDG_DATA_HOME/mech/missions`, else `~/.local/share/mech/missions`,
/// else `missions` in the station's working directory.
pub fn default_dir() -> PathBuf {
    let data = std::env::var_os("XDG_DATA_HOME")
        .filter(|d| !d.is_empty())
        .map(PathBuf::from)
        .or_else(|| std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/share")));
    match data {
        Some(d) => d.join("mech/missions"),
        None => PathBuf::from("missions"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_operator_names_files_inside_the_missions_directory_only() {
        let dir = tempfile::tempdir().unwrap();
        let missions = dir.path().join("missions");
        let access = FileAccess::Confined(missions.clone());
        assert_eq!(
            access.resolve("lab/square.toml", true).unwrap(),
            missions.join("lab/square.toml")
        );
        assert!(missions.join("lab").is_dir(), "created on save");
        for bad in ["/etc/passwd", "../x.toml", "lab/../../x.toml", ""] {
            let e = access.resolve(bad, true).unwrap_err();
            assert!(e.contains("missions directory"), "{bad}: {e}");
        }
        let outside = dir.path().join("outside");
        std::fs::create_dir_all(&outside).unwrap();
        std::os::unix::fs::symlink(&outside, missions.join("out")).unwrap();
        let e = access.resolve("out/x.toml", true).unwrap_err();
        assert!(e.contains("leads out"), "{e}");
        std::os::unix::fs::symlink("/etc/hostname", missions.join("host.toml")).unwrap();
        let e = access.resolve("host.toml", false).unwrap_err();
        assert!(e.contains("leads out"), "{e}");
        assert_eq!(
            FileAccess::Station.resolve("/tmp/x.toml", true).unwrap(),
            PathBuf::from("/tmp/x.toml")
        );
    }
}
