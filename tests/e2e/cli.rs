//! Both binaries start and describe themselves.

use std::process::Command;

#[test]
fn binaries_answer_help() {
    for name in ["mech-gcs", "mech-agent"] {
        let out = Command::new(mech_e2e::binary(name))
            .arg("--help")
            .output()
            .unwrap_or_else(|e| panic!("{name} runs: {e}"));
        assert!(out.status.success(), "{name} --help exits 0");
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(text.contains("Usage"), "{name} --help prints usage: {text}");
    }
}
