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
