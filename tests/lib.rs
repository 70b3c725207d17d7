//! Shared helpers for the end-to-end and fault-injection tests: where the
//! built binaries are, and the [`harness`] that runs them under faults.

pub mod harness;

use std::path::PathBuf;

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
