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

/// `mech-gcs --check` says every reason the station would not start with
/// its configuration (a key file missing, one readable by others), not
/// only the first, and passes once the keys are made as it says.
#[test]
fn the_station_check_lists_every_key_problem_then_passes() {
    use std::os::unix::fs::PermissionsExt;
    let dir = tempfile::tempdir().expect("temp dir");
    let config = dir.path().join("gcs.toml");
    std::fs::write(
        &config,
        "[router]\nudp = \"0.0.0.0:0\"\ntcp = \"127.0.0.1:0\"\n\
         [[auth.keys]]\nrole = \"robot\"\nname = \"rover\"\nfile = \"keys/rover.key\"\n\
         [[auth.keys]]\nrole = \"operator\"\nname = \"ana\"\nfile = \"keys/ana.key\"\n",
    )
    .expect("config written");
    let keys = dir.path().join("keys");
    std::fs::create_dir(&keys).expect("key dir");
    let gcs = |args: &[&str]| {
        Command::new(mech_e2e::binary("mech-gcs"))
            .args(args)
            .output()
            .expect("mech-gcs runs")
    };
    let ana = keys.join("ana.key");
    assert!(
        gcs(&["keygen", "ana", "--out", ana.to_str().unwrap()])
            .status
            .success()
    );
    std::fs::set_permissions(&ana, std::fs::Permissions::from_mode(0o644)).unwrap();
    let check = || gcs(&["--config", config.to_str().unwrap(), "--check"]);
    let out = check();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{stdout}");
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 3, "{stdout}");
    assert!(
        lines[0].ends_with("the station would not start:"),
        "{stdout}"
    );
    assert!(
        lines[1].contains("rover.key") && lines[1].contains("mech-gcs keygen rover --out"),
        "{stdout}"
    );
    assert!(lines[2].contains("ana.key"), "{stdout}");
    std::fs::set_permissions(&ana, std::fs::Permissions::from_mode(0o600)).unwrap();
    let rover = keys.join("rover.key");
    assert!(
        gcs(&["keygen", "rover", "--out", rover.to_str().unwrap()])
            .status
            .success()
    );
    let out = check();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stdout)
    );
    assert!(String::from_utf8_lossy(&out.stdout).ends_with("gcs.toml: ok\n"));
    // Beyond loopback with no keys at all: refused, and why.
    std::fs::write(&config, "[router]\nudp = \"0.0.0.0:0\"\n").unwrap();
    let out = check();
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stdout).contains("no keys are configured"));
}

/// The manual pages the Debian packages install (`docs/man/`) name every
/// option and command each binary's `--help` lists, so they cannot fall
/// behind the programs.
#[test]
fn the_manual_pages_name_every_option() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("..");
    for (binary, commands) in [
        ("mech-agent", &[][..]),
        ("mech-gcs", &["serve", "replay", "keygen"][..]),
    ] {
        let page = std::fs::read_to_string(root.join(format!("docs/man/{binary}.1")))
            .expect("the manual page");
        let mut helps = vec![vec!["--help"]];
        helps.extend(commands.iter().map(|c| vec![*c, "--help"]));
        for args in helps {
            let out = Command::new(mech_e2e::binary(binary))
                .args(&args)
                .output()
                .expect("runs");
            let help = String::from_utf8_lossy(&out.stdout);
            for word in help.split(|c: char| !(c.is_ascii_alphanumeric() || c == '-')) {
                let Some(name) = word.strip_prefix("--") else {
                    continue;
                };
                if name.is_empty() || !help.contains(&format!("  --{name}")) {
                    continue; // a mention in a description, not an option
                }
                let troff = format!("\\-\\-{}", name.replace('-', "\\-"));
                assert!(
                    page.contains(&troff),
                    "{binary} {args:?}: --{name} is not in its manual page"
                );
            }
            for c in commands {
                assert!(
                    page.contains(&format!(".B {c}")) || page.contains(&format!(".BI {c}")),
                    "{binary}: {c}"
                );
            }
        }
    }
}
