//! Rotating recordings: files named `mech-YYYYMMDD-HHMMSS.mcap` (UTC, with
//! `-N` if that name is taken) in one directory; when there are more than
//! `keep`, the oldest are deleted. Only files with exactly that shape of
//! name are ever deleted.

use std::path::{Path, PathBuf};

/// A name for a new recording in `dir`, begun at `unix_secs`.
pub(super) fn next_name(dir: &Path, unix_secs: u64) -> PathBuf {
    let stem = format!("mech-{}", utc_stamp(unix_secs));
    let first = dir.join(format!("{stem}.mcap"));
    if !first.exists() {
        return first;
    }
    (1..)
        .map(|n| dir.join(format!("{stem}-{n}.mcap")))
        .find(|p| !p.exists())
        .unwrap_or(first)
}

/// Whether `name` is one this module gives.
pub(super) fn is_recording_name(name: &str) -> bool {
    let Some(stem) = name
        .strip_prefix("mech-")
        .and_then(|s| s.strip_suffix(".mcap"))
    else {
        return false;
    };
    let b = stem.as_bytes();
    let digits =
        |r: std::ops::Range<usize>| b.get(r).is_some_and(|d| d.iter().all(u8::is_ascii_digit));
    let stamp = b.len() >= 15 && digits(0..8) && b[8] == b'-' && digits(9..15);
    let suffix = &b[15.min(b.len())..];
    stamp
        && (suffix.is_empty()
            || (suffix.len() > 1
                && suffix[0] == b'-'
                && suffix[1..].iter().all(u8::is_ascii_digit)))
}

/// Recordings in `dir`, oldest first (the names sort by time).
pub(super) fn recordings(dir: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let mut files: Vec<(u64, u64, PathBuf)> = entries
        .flatten()
        .filter(|e| e.file_name().to_str().is_some_and(is_recording_name))
        .map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let (stamp, n) = order_key(&name);
            (stamp, n, e.path())
        })
        .collect();
    files.sort();
    files.into_iter().map(|(_, _, p)| p).collect()
}

/// `(YYYYMMDDHHMMSS, N)` of a recording name, for sorting `-10` after `-9`.
fn order_key(name: &str) -> (u64, u64) {
    let digits: String = name[5..20].chars().filter(char::is_ascii_digit).collect();
    let n = name[20..]
        .trim_start_matches('-')
        .trim_end_matches(".mcap")
        .parse()
        .unwrap_or(0);
    (digits.parse().unwrap_or(0), n)
}

/// Deletes the oldest recordings in `dir` beyond `keep`; returns how many.
/// A file that cannot be deleted is logged and left.
pub(super) fn prune(dir: &Path, keep: usize) -> usize {
    let files = recordings(dir);
    let excess = files.len().saturating_sub(keep);
    let mut deleted = 0;
    for f in files.into_iter().take(excess) {
        match std::fs::remove_file(&f) {
            Ok(()) => deleted += 1,
            Err(e) => {
                tracing::warn!(file = %f.display(), error = %e, "cannot delete an old recording")
            }
        }
    }
    deleted
}

/// `YYYYMMDD-HHMMSS` in UTC.
fn utc_stamp(unix_secs: u64) -> String {
    let days = (unix_secs / 86_400) as i64;
    let rem = unix_secs % 86_400;
    let (y, m, d) = civil_from_days(days);
    format!(
        "{y:04}{m:02}{d:02}-{:02}{:02}{:02}",
        rem / 3600,
        rem / 60 % 60,
        rem % 60
    )
}

/// The proleptic Gregorian date of a day count since 1970-01-01 (Howard
/// Hinnant's `civil_from_days`).
fn civil_from_days(z: i64) -> (i64, u32, u32) {
    let z = z + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z.rem_euclid(146_097);
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let m = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let y = yoe + era * 400 + i64::from(m <= 2);
    (y, m, d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_carry_the_utc_time_and_sort_in_order() {
        assert_eq!(utc_stamp(0), "19700101-000000");
        // 2024-02-29 23:59:59 UTC.
        assert_eq!(utc_stamp(1_709_251_199), "20240229-235959");
        assert!(is_recording_name("mech-20240229-235959.mcap"));
        assert!(is_recording_name("mech-20240229-235959-12.mcap"));
        for other in [
            "mech-2024-235959.mcap",
            "mech-20240229-235959-.mcap",
            "mech-20240229-235959.mcap.bak",
            "notes.mcap",
            "mech-20240229-235959-x.mcap",
        ] {
            assert!(!is_recording_name(other), "{other}");
        }
    }

    #[test]
    fn pruning_keeps_the_newest_and_touches_nothing_else() {
        let dir = tempfile::tempdir().unwrap();
        let names = [
            "mech-20240101-000000.mcap",
            "mech-20240101-000000-1.mcap",
            "mech-20240101-000000-10.mcap",
            "mech-20240101-000000-9.mcap",
            "mech-20240102-000000.mcap",
            "mine.mcap",
        ];
        for n in names {
            std::fs::write(dir.path().join(n), b"x").unwrap();
        }
        assert_eq!(prune(dir.path(), 2), 3);
        let mut left: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(
            left,
            [
                "mech-20240101-000000-10.mcap",
                "mech-20240102-000000.mcap",
                "mine.mcap"
            ]
        );
        let next = next_name(dir.path(), 1_704_153_600); // 2024-01-02 00:00:00
        assert_eq!(next, dir.path().join("mech-20240102-000000-1.mcap"));
    }
}
