//! Shared helpers for the end-to-end and fault-injection tests: where the
//! built binaries are, and the [`harness`] that runs them under faults.

pub mod harness;

use std::ffi::OsStr;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};

/// Path of a workspace binary (`mech-gcs`, `mech-agent`) next to the test
/// executable's target directory. The test command builds the binaries first.
pub fn binary(name: &str) -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    // target/<profile>/deps/e2e-xxxx -> target/<profile>/<name>
    let profile_dir = exe
        .parent()
        .and_then(|deps| deps.parent())
        .expect("test executable lives in target/<profile>/deps");
    profile_dir.join(name)
}

/// The first ```LANG block after the heading `section` of the page at
/// `page` (relative to the repository): the documented example the tests
/// compare with the file they run.
pub fn doc_block(page: &str, section: &str, lang: &str) -> String {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    let text = std::fs::read_to_string(root.join(page)).expect("the page");
    let at = text.find(section).expect("the section");
    let section = &text[at..];
    let fence = format!("```{lang}\n");
    let start = section.find(&fence).expect("a code block") + fence.len();
    let end = start + section[start..].find("```").expect("the block's end");
    section[start..end].to_string()
}

/// Starts `mech-gcs ARGS` logging into `state`, with `stdin` written to its
/// standard input (then closed) and its output piped.
pub fn spawn_mech_gcs<A: AsRef<OsStr>>(args: &[A], stdin: &str, state: &Path) -> Child {
    let mut child = Command::new(binary("mech-gcs"))
        .args(args)
        .env("XDG_STATE_HOME", state)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mech-gcs starts (the test command builds it first)");
    child
        .stdin
        .take()
        .expect("stdin")
        .write_all(stdin.as_bytes())
        .expect("stdin written");
    child
}

/// Runs `mech-gcs ARGS` as [`spawn_mech_gcs`] starts it, to the end.
pub fn mech_gcs<A: AsRef<OsStr>>(args: &[A], stdin: &str, state: &Path) -> Output {
    spawn_mech_gcs(args, stdin, state)
        .wait_with_output()
        .expect("mech-gcs finishes")
}

/// `mech-gcs ARGS --script -` with the script `source` on its standard
/// input, as [`mech_gcs`] runs it: whether it passed, and its standard
/// output followed by its standard error.
pub fn run_script<A: AsRef<OsStr>>(args: &[A], source: &str, state: &Path) -> (bool, String) {
    let mut all: Vec<&OsStr> = args.iter().map(AsRef::as_ref).collect();
    all.extend([OsStr::new("--script"), OsStr::new("-")]);
    let out = mech_gcs(&all, source, state);
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    (out.status.success(), text)
}
