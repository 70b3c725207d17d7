//! Where the files a command names may be: mission files (`mission save`,
//! `mission load`), arena files (`arena load`) and recordings (`record
//! start FILE`). The station process reads and writes them, on the
//! station's machine, whoever typed the command. A script the station runs
//! itself (`mech-gcs --script`) is the station's owner speaking: its paths
//! are taken as given. An operator's session (any TUI, its own station's
//! included, or `--attach --script`, over the local socket or over TCP from
//! another machine with only an operator key) may drive robots but has no
//! account on the station's machine: left free, `mission save` or `record
//! start` would overwrite any file the station may write (its keys, its
//! configuration) and `mission load` or `arena load` would quote any file
//! it may read in its errors. So an operator names a file inside the
//! directory for its kind (mission and arena files: the missions
//! directory; recordings: the recording directory): a relative name, or an
//! absolute path inside that directory; no `..`, and no symbolic link
//! leading out of it.

use std::path::{Component, Path, PathBuf};

/// How a session's file names are turned into paths.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FileAccess {
    /// As given (relative to the station's working directory).
    Station,
    /// An operator's session: mission and arena files only inside this
    /// directory, the missions directory (created when a file is saved);
    /// recordings only inside the recording directory
    /// ([`FileAccess::recording`]).
    Confined(PathBuf),
}

impl FileAccess {
    /// The path of the mission or arena file `name`, or why it may not be
    /// used. `saving`: the directories on the way are created (inside the
    /// missions directory only).
    pub fn resolve(&self, name: &str, saving: bool) -> Result<PathBuf, String> {
        match self {
            FileAccess::Station => Ok(PathBuf::from(name)),
            FileAccess::Confined(dir) => confine(dir, "missions directory", name, saving),
        }
    }

    /// The path of the recording `name`, or why it may not be used: as
    /// given for the station's own script; for an operator, inside
    /// `record_dir` (the recording directory; the directories on the way
    /// are created), and refused when the station has none.
    pub fn recording(&self, name: &str, record_dir: Option<&Path>) -> Result<PathBuf, String> {
        match (self, record_dir) {
            (FileAccess::Station, _) => Ok(PathBuf::from(name)),
            (FileAccess::Confined(_), Some(dir)) => confine(dir, "recording directory", name, true),
            (FileAccess::Confined(_), None) => Err(format!(
                "{name:?}: from an operator's session a recording is a name in the station's \
                 recording directory, and this station has none (`[record] dir`)"
            )),
        }
    }
}

/// `name` as a path inside `dir` (called `what` in messages), or why it is
/// not one: a relative path of plain names, or an absolute path that lies
/// inside `dir`; no `..`; neither its directory nor (when it exists) the
/// file itself a symbolic link leading out of `dir`. `create`: the
/// directories on the way are created first.
pub fn confine(dir: &Path, what: &str, name: &str, create: bool) -> Result<PathBuf, String> {
    let refused = || {
        format!(
            "{name:?}: from an operator's session a file is a name in the station's \
             {what} {} (no `..`, no absolute path outside it)",
            dir.display()
        )
    };
    let given = Path::new(name);
    let relative = if given.is_absolute() {
        inside_lexically(dir, given).ok_or_else(refused)?
    } else {
        given
    };
    let plain = relative
        .components()
        .all(|c| matches!(c, Component::Normal(_) | Component::CurDir));
    if relative.file_name().is_none() || !plain {
        return Err(refused());
    }
    let path = dir.join(relative);
    let parent = path.parent().unwrap_or(dir);
    let create_all = |d: &Path| {
        std::fs::create_dir_all(d).map_err(|e| format!("cannot create {}: {e}", d.display()))
    };
    if create {
        create_all(dir)?;
    }
    let real_dir = dir
        .canonicalize()
        .map_err(|e| format!("{what} {}: {e}", dir.display()))?;
    let inside = |p: &Path| p.canonicalize().is_ok_and(|r| r.starts_with(&real_dir));
    let leads_out = || format!("{name:?} leads out of the {what} {}", dir.display());
    // Nothing is created outside: the nearest part of the way that exists
    // (a directory, or a link) must already lead inside.
    let existing = parent
        .ancestors()
        .find(|a| a.symlink_metadata().is_ok())
        .unwrap_or(dir);
    if !inside(existing) {
        return Err(leads_out());
    }
    if create {
        create_all(parent)?;
        if !inside(parent) {
            return Err(leads_out());
        }
    }
    // An existing file may itself be a link out of the directory.
    if path.symlink_metadata().is_ok() && !inside(&path) {
        return Err(leads_out());
    }
    Ok(path)
}

/// What follows `dir` in the absolute path `path`: `dir` as configured, as
/// an absolute path, or with its links resolved.
fn inside_lexically<'a>(dir: &Path, path: &'a Path) -> Option<&'a Path> {
    let forms = [
        Some(dir.to_path_buf()),
        std::path::absolute(dir).ok(),
        dir.canonicalize().ok(),
    ];
    forms
        .into_iter()
        .flatten()
        .find_map(|d| path.strip_prefix(d).ok())
}

/// The text of a file a command reads (a mission or an arena file): at
/// most `max` bytes, so naming a device or a huge file costs no more than
/// reading `max` bytes of it.
pub async fn read_text(path: &Path, max: u64) -> Result<String, String> {
    use tokio::io::AsyncReadExt;
    let file = tokio::fs::File::open(path)
        .await
        .map_err(|e| e.to_string())?;
    let mut bytes = Vec::new();
    file.take(max.saturating_add(1))
        .read_to_end(&mut bytes)
        .await
        .map_err(|e| e.to_string())?;
    if bytes.len() as u64 > max {
        return Err(format!(
            "more than {max} bytes: larger than any mission or arena file"
        ));
    }
    String::from_utf8(bytes).map_err(|_| "not UTF-8 text".to_string())
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
        for bad in ["/etc/passwd", "../x.toml", "lab/../../x.toml", "", ".", "/"] {
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

    #[test]
    fn an_absolute_path_is_taken_only_inside_the_directory() {
        let dir = tempfile::tempdir().unwrap();
        let missions = dir.path().join("missions");
        let access = FileAccess::Confined(missions.clone());
        let inside = missions.join("lab/a.toml");
        assert_eq!(
            access.resolve(inside.to_str().unwrap(), true).unwrap(),
            inside
        );
        let sibling = dir.path().join("missions-old/a.toml");
        let e = access.resolve(sibling.to_str().unwrap(), true).unwrap_err();
        assert!(e.contains("missions directory"), "{e}");
        let climbing = missions.join("../a.toml");
        let e = access
            .resolve(climbing.to_str().unwrap(), true)
            .unwrap_err();
        assert!(e.contains("missions directory"), "{e}");
        let the_dir = access
            .resolve(missions.to_str().unwrap(), true)
            .unwrap_err();
        assert!(the_dir.contains("missions directory"), "{the_dir}");
    }

    #[test]
    fn an_operator_names_recordings_inside_the_recording_directory_only() {
        let dir = tempfile::tempdir().unwrap();
        let recordings = dir.path().join("rec");
        let access = FileAccess::Confined(dir.path().join("missions"));
        assert_eq!(
            access.recording("run.mcap", Some(&recordings)).unwrap(),
            recordings.join("run.mcap")
        );
        for bad in ["/etc/x.mcap", "../run.mcap", "a/../../run.mcap"] {
            let e = access.recording(bad, Some(&recordings)).unwrap_err();
            assert!(e.contains("recording directory"), "{bad}: {e}");
        }
        std::os::unix::fs::symlink(dir.path(), recordings.join("up")).unwrap();
        for through_link in ["up/run.mcap", "up/new/run.mcap"] {
            let e = access
                .recording(through_link, Some(&recordings))
                .unwrap_err();
            assert!(e.contains("leads out of the recording directory"), "{e}");
        }
        assert!(!dir.path().join("new").exists(), "nothing created outside");
        let elsewhere = dir.path().join("elsewhere.mcap");
        std::fs::write(&elsewhere, "").unwrap();
        std::os::unix::fs::symlink(&elsewhere, recordings.join("link.mcap")).unwrap();
        let e = access
            .recording("link.mcap", Some(&recordings))
            .unwrap_err();
        assert!(e.contains("leads out"), "{e}");
        let e = access.recording("run.mcap", None).unwrap_err();
        assert!(e.contains("has none"), "{e}");
        assert_eq!(
            FileAccess::Station
                .recording("../run.mcap", Some(&recordings))
                .unwrap(),
            PathBuf::from("../run.mcap")
        );
    }
}
