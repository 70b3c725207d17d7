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

/// A configuration error is said once, with where it is, and exits 2.
#[test]
fn a_bad_configuration_is_reported_once() {
    let dir = std::env::temp_dir().join(format!("mech-e2e-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let bad = dir.join("bad.toml");
    std::fs::write(&bad, "[router]\nudp = \"nonsense\"\n").expect("config written");
    let missing = dir.join("missing.toml");
    for (name, config, said) in [
        ("mech-gcs", &bad, "invalid socket address syntax"),
        ("mech-gcs", &missing, "No such file or directory"),
        ("mech-agent", &missing, "No such file or directory"),
    ] {
        let out = Command::new(mech_e2e::binary(name))
            .arg("--config")
            .arg(config)
            .arg(if name == "mech-agent" {
                "--check"
            } else {
                "--no-mouse"
            })
            .output()
            .unwrap_or_else(|e| panic!("{name} runs: {e}"));
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{name}: {stderr}");
        assert_eq!(stderr.matches(said).count(), 1, "{name}: {stderr}");
        assert!(stderr.contains(&config.display().to_string()), "{stderr}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
