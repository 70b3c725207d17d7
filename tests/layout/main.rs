//! The workspace's shape, checked: no import cycles between the modules of
//! any crate, a station core that needs no terminal, gamepad or simulator,
//! a station service and a Zenoh station that need no terminal or gamepad,
//! a default build without Zenoh, and the size limits of structs, impl
//! blocks and functions (`limits`).
//!
//! Modules may depend on their parent and their children freely (a parent
//! re-exports its children, a child uses its parent's shared types); what
//! must not happen is two siblings depending on each other, directly or
//! around a loop. A reference from module `a::b` to `c::d` is an edge
//! between the siblings `a` and `c` under their common ancestor (the crate
//! root here). Test modules (`#[cfg(test)]` to the end of a file) are left
//! out: a test may reach anywhere.

mod limits;

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Library crates whose module graph must be acyclic, by source folder.
const CRATES: &[&str] = &[
    "proto/src",
    "agent/src",
    "gcs-tui/core/src",
    "gcs-tui/control/src",
    "gcs-tui/station/src",
    "gcs-tui/tui/src",
    "gcs-tui/zenoh/src",
    "gcs-tui/ros2/src",
];

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("tests/ sits in the workspace")
        .to_path_buf()
}

/// Module path of a source file: `src/lang/parse.rs` -> `["lang", "parse"]`.
fn module_of(src: &Path, file: &Path) -> Vec<String> {
    let rel = file.strip_prefix(src).expect("file under src");
    let mut parts: Vec<String> = rel
        .iter()
        .map(|c| c.to_string_lossy().trim_end_matches(".rs").to_string())
        .collect();
    if parts.last().is_some_and(|p| p == "lib" || p == "main") && parts.len() == 1 {
        parts.clear();
    }
    parts
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let mut entries: Vec<_> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .filter_map(Result::ok)
        .map(|e| e.path())
        .collect();
    entries.sort();
    for p in entries {
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The source without line comments and without the test module at its end.
fn code_of(text: &str) -> String {
    let text = match text.find("#[cfg(test)]") {
        Some(i) => &text[..i],
        None => text,
    };
    text.lines()
        .map(|l| match l.find("//") {
            Some(i) => &l[..i],
            None => l,
        })
        .collect::<Vec<_>>()
        .join("\n")
}

fn is_ident(c: char) -> bool {
    c.is_alphanumeric() || c == '_'
}

/// Every path written after `crate::`, `super::` or `self::`, with `use`
/// groups (`crate::{a, b::{c, d}}`) expanded, each as its segments after the
/// leading keyword, tagged with that keyword.
fn paths(code: &str) -> Vec<(&'static str, Vec<String>)> {
    let mut out = Vec::new();
    let chars: Vec<char> = code.chars().collect();
    let mut i = 0;
    while i < chars.len() {
        let start_ok = i == 0 || !is_ident(chars[i - 1]) && chars[i - 1] != ':';
        let rest: String = chars[i..chars.len().min(i + 8)].iter().collect();
        let head = ["crate::", "super::", "self::"]
            .into_iter()
            .find(|h| rest.starts_with(h));
        match head.filter(|_| start_ok) {
            Some(h) => {
                let mut j = i + h.len();
                let mut found = Vec::new();
                tree(&chars, &mut j, Vec::new(), &mut found);
                let kw = match h {
                    "crate::" => "crate",
                    "super::" => "super",
                    _ => "self",
                };
                out.extend(found.into_iter().map(|p| (kw, p)));
                i = j;
            }
            None => i += 1,
        }
    }
    out
}

/// Reads `a::b::{c, d::e}` from `chars[*j..]`, appending each full path.
fn tree(chars: &[char], j: &mut usize, prefix: Vec<String>, out: &mut Vec<Vec<String>>) {
    let mut path = prefix;
    loop {
        while *j < chars.len() && chars[*j].is_whitespace() {
            *j += 1;
        }
        if *j < chars.len() && chars[*j] == '{' {
            *j += 1;
            loop {
                tree(chars, j, path.clone(), out);
                while *j < chars.len() && chars[*j].is_whitespace() {
                    *j += 1;
                }
                match chars.get(*j) {
                    Some(',') => *j += 1,
                    Some('}') => {
                        *j += 1;
                        return;
                    }
                    _ => return,
                }
                while *j < chars.len() && chars[*j].is_whitespace() {
                    *j += 1;
                }
                if chars.get(*j) == Some(&'}') {
                    *j += 1;
                    return;
                }
            }
        }
        let s = *j;
        while *j < chars.len() && is_ident(chars[*j]) {
            *j += 1;
        }
        if *j == s {
            out.push(path);
            return;
        }
        path.push(chars[s..*j].iter().collect());
        if chars.get(*j) == Some(&':') && chars.get(*j + 1) == Some(&':') {
            *j += 2;
        } else {
            // `a::b as c` and the like end the path here.
            out.push(path);
            return;
        }
    }
}

/// Sibling edges `(parent, from, to)` of one crate, with an example
/// reference for each.
type Edges = BTreeMap<(Vec<String>, String, String), String>;

fn edges_of(src: &Path) -> Edges {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let modules: BTreeSet<Vec<String>> = files
        .iter()
        .filter(|f| !f.ends_with("main.rs") || f.parent() != Some(src))
        .map(|f| module_of(src, f))
        .collect();
    let mut edges = Edges::new();
    for file in &files {
        if file.parent() == Some(src) && file.ends_with("main.rs") {
            continue; // a binary's own crate root
        }
        let me = module_of(src, file);
        let text = std::fs::read_to_string(file).expect("readable source");
        for (kw, rel) in paths(&code_of(&text)) {
            let mut full = match kw {
                "crate" => Vec::new(),
                "super" => me[..me.len().saturating_sub(1)].to_vec(),
                _ => me.clone(),
            };
            let mut rel = rel.as_slice();
            // `super::super::x`
            while rel.first().is_some_and(|s| s == "super") {
                full.pop();
                rel = &rel[1..];
            }
            full.extend(rel.iter().cloned());
            // The module the path lands in: its longest known prefix.
            let target = (0..=full.len())
                .rev()
                .map(|n| full[..n].to_vec())
                .find(|p| modules.contains(p))
                .unwrap_or_default();
            let common = me.iter().zip(&target).take_while(|(a, b)| a == b).count();
            if common == me.len() || common == target.len() {
                continue; // parent <-> child
            }
            let parent = me[..common].to_vec();
            let key = (parent, me[common].clone(), target[common].clone());
            edges
                .entry(key)
                .or_insert_with(|| format!("{} uses {}", me.join("::"), full.join("::")));
        }
    }
    edges
}

/// Every group of siblings that depend on each other around a loop (the
/// strongly connected components with more than one module), each with its
/// parent.
fn find_cycles(edges: &Edges) -> Vec<(Vec<String>, Vec<String>)> {
    let mut groups: BTreeMap<Vec<String>, BTreeMap<String, Vec<String>>> = BTreeMap::new();
    for (parent, from, to) in edges.keys() {
        let g = groups.entry(parent.clone()).or_default();
        g.entry(from.clone()).or_default().push(to.clone());
        g.entry(to.clone()).or_default();
    }
    let mut out = Vec::new();
    for (parent, graph) in groups {
        // Two modules are in one loop when each reaches the other.
        let reach = |from: &String| {
            let mut seen = BTreeSet::new();
            let mut todo = vec![from.clone()];
            while let Some(n) = todo.pop() {
                for m in &graph[&n] {
                    if seen.insert(m.clone()) {
                        todo.push(m.clone());
                    }
                }
            }
            seen
        };
        let reaches: BTreeMap<&String, BTreeSet<String>> =
            graph.keys().map(|n| (n, reach(n))).collect();
        let mut placed = BTreeSet::new();
        for n in graph.keys() {
            if placed.contains(n) || !reaches[n].contains(n) {
                continue;
            }
            let component: Vec<String> = graph
                .keys()
                .filter(|m| reaches[n].contains(*m) && reaches[*m].contains(n))
                .cloned()
                .collect();
            placed.extend(component.iter().cloned());
            out.push((parent.clone(), component));
        }
    }
    out
}

#[test]
fn no_crate_has_an_import_cycle_between_its_modules() {
    let mut failures = Vec::new();
    for dir in CRATES {
        let src = workspace().join(dir);
        let edges = edges_of(&src);
        for (parent, cycle) in find_cycles(&edges) {
            let why: Vec<&String> = edges
                .iter()
                .filter(|((p, f, t), _)| *p == parent && cycle.contains(f) && cycle.contains(t))
                .map(|(_, why)| why)
                .collect();
            let under = if parent.is_empty() {
                String::new()
            } else {
                format!(" under {}", parent.join("::"))
            };
            failures.push(format!(
                "{dir}: {{{}}}{under}: {}",
                cycle.join(", "),
                why.iter()
                    .map(|w| w.as_str())
                    .collect::<Vec<_>>()
                    .join("; ")
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "import cycles:\n{}",
        failures.join("\n")
    );
}

#[test]
fn the_cycle_finder_sees_a_cycle_through_a_use_group() {
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path();
    std::fs::create_dir_all(src.join("a")).unwrap();
    std::fs::write(src.join("lib.rs"), "mod a;\nmod b;\nmod c;\n").unwrap();
    std::fs::write(src.join("a.rs"), "mod inner;\n").unwrap();
    std::fs::write(
        src.join("a/inner.rs"),
        "use crate::{b::{X, Y}, c};\nuse super::super::c::Z;\n",
    )
    .unwrap();
    std::fs::write(src.join("b.rs"), "use super::c::W; // crate::a\n").unwrap();
    std::fs::write(
        src.join("c.rs"),
        "pub fn f() { crate::a::inner::g() }\n#[cfg(test)]\nmod t { use crate::b; }\n",
    )
    .unwrap();
    let edges = edges_of(src);
    let names: BTreeSet<(String, String)> = edges
        .keys()
        .map(|(_, f, t)| (f.clone(), t.clone()))
        .collect();
    let expect: BTreeSet<(String, String)> = [("a", "b"), ("a", "c"), ("b", "c"), ("c", "a")]
        .into_iter()
        .map(|(a, b)| (a.to_string(), b.to_string()))
        .collect();
    assert_eq!(names, expect, "comments and test modules are ignored");
    let cycles = find_cycles(&edges);
    let abc = ["a", "b", "c"].map(String::from).to_vec();
    assert_eq!(
        cycles,
        vec![(vec![], abc)],
        "a -> b -> c -> a and a -> c -> a"
    );
}

#[test]
fn the_station_core_needs_no_terminal_gamepad_or_simulator() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    for krate in ["mech-core", "mech-control"] {
        let tree = normal_tree(&cargo, krate);
        for banned in ["ratatui ", "crossterm ", "gilrs ", "mech-agent ", "libudev"] {
            assert!(
                !tree.lines().any(|l| l.starts_with(banned)),
                "{krate} depends on {banned}:\n{tree}"
            );
        }
    }
    // mech-core's tests and benches too: nothing heavier than the protocol.
    let out = Command::new(&cargo)
        .current_dir(workspace())
        .args(["tree", "-p", "mech-core", "--prefix", "none"])
        .output()
        .expect("cargo tree runs");
    let tree = String::from_utf8_lossy(&out.stdout);
    for banned in ["ratatui ", "crossterm ", "gilrs ", "mech-agent "] {
        assert!(
            !tree.lines().any(|l| l.starts_with(banned)),
            "mech-core (with dev-dependencies) depends on {banned}"
        );
    }
}

/// `cargo tree -p KRATE -e normal,build` (what the crate's library and
/// binaries link), one crate a line.
fn normal_tree(cargo: &str, krate: &str) -> String {
    let args = ["tree", "-p", krate, "-e", "normal,build"];
    cargo_stdout(cargo, &[&args[..], &["--prefix", "none"]].concat())
}

/// What `cargo ARGS` prints in the workspace; it must succeed.
fn cargo_stdout(cargo: &str, args: &[&str]) -> String {
    let out = Command::new(cargo)
        .current_dir(workspace())
        .args(args)
        .output()
        .unwrap_or_else(|e| panic!("cargo {args:?} runs: {e}"));
    assert!(
        out.status.success(),
        "cargo {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

#[test]
fn the_station_service_and_the_zenoh_station_need_no_terminal_or_gamepad() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    for krate in ["mech-station", "mech-zenoh"] {
        let tree = normal_tree(&cargo, krate);
        assert!(
            tree.lines().any(|l| l.starts_with("mech-control ")),
            "{krate}'s tree is read: {tree}"
        );
        for banned in ["ratatui ", "crossterm ", "gilrs ", "mech-gcs ", "libudev"] {
            assert!(
                !tree.lines().any(|l| l.starts_with(banned)),
                "{krate} depends on {banned}:\n{tree}"
            );
        }
    }
    // The Foxglove live view adds no terminal either.
    let out = Command::new(&cargo)
        .current_dir(workspace())
        .args(["tree", "-p", "mech-station", "--features", "foxglove"])
        .args(["-e", "normal,build", "--prefix", "none"])
        .output()
        .expect("cargo tree runs");
    let tree = String::from_utf8_lossy(&out.stdout);
    assert!(
        tree.lines().any(|l| l.starts_with("tokio-tungstenite ")),
        "{tree}"
    );
    for banned in ["ratatui ", "crossterm ", "gilrs "] {
        assert!(
            !tree.lines().any(|l| l.starts_with(banned)),
            "mech-station with foxglove depends on {banned}"
        );
    }
    // Dependencies point one way: the TUI on the station, not back.
    let gcs = normal_tree(&cargo, "mech-gcs");
    assert!(gcs.lines().any(|l| l.starts_with("mech-station ")), "{gcs}");
}

#[test]
fn the_default_build_leaves_zenoh_out() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let manifest = std::fs::read_to_string(workspace().join("Cargo.toml")).unwrap();
    let defaults = &manifest[manifest
        .find("default-members")
        .expect("the workspace lists its default members")..];
    let defaults = &defaults[..defaults.find(']').unwrap()];
    assert!(!defaults.contains("zenoh"), "{defaults}");
    assert!(!defaults.contains("ros2"), "{defaults}");
    for krate in [
        "mech-gcs",
        "mech-station",
        "mech-agent",
        "mech-control",
        "mech-core",
        "mech-e2e",
    ] {
        let out = Command::new(&cargo)
            .current_dir(workspace())
            .args([
                "tree",
                "-p",
                krate,
                "-e",
                "normal,build,dev",
                "--prefix",
                "none",
            ])
            .output()
            .expect("cargo tree runs");
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let tree = String::from_utf8_lossy(&out.stdout);
        assert!(
            !tree
                .lines()
                .any(|l| l.starts_with("zenoh ") || l.starts_with("mech-zenoh ")),
            "{krate} depends on zenoh"
        );
        assert!(
            !tree.lines().any(|l| l.starts_with("rustdds ")
                || l.starts_with("ros2-client ")
                || l.starts_with("mech-ros2 ")),
            "{krate} depends on DDS"
        );
    }
}

/// The crate graph `docs/architecture.md` states in its table ("Each
/// crate's library and binary use these of MECH's crates") is the
/// manifests' `[dependencies]`: a crate that starts using another, or stops,
/// fails here until the doc says so.
#[test]
fn the_architecture_doc_states_the_crate_graph_of_the_manifests() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let args = [
        "metadata",
        "--format-version",
        "1",
        "--no-deps",
        "--offline",
    ];
    let out = cargo_stdout(&cargo, &args);
    let meta: serde_json::Value = serde_json::from_str(&out).expect("metadata is JSON");
    let manifests: BTreeMap<String, BTreeSet<String>> = meta["packages"]
        .as_array()
        .expect("packages")
        .iter()
        .filter_map(|p| {
            let name = p["name"].as_str()?;
            (name.starts_with("mech-") && name != "mech-e2e").then(|| {
                let uses = p["dependencies"]
                    .as_array()
                    .into_iter()
                    .flatten()
                    .filter(|d| d["kind"].is_null())
                    .filter_map(|d| d["name"].as_str())
                    .filter(|d| d.starts_with("mech-"))
                    .map(str::to_string)
                    .collect();
                (name.to_string(), uses)
            })
        })
        .collect();
    assert!(manifests.len() >= 8, "{manifests:?}");
    let doc = std::fs::read_to_string(workspace().join("docs/architecture.md")).unwrap();
    let table = doc
        .split("| crate | uses |\n| --- | --- |\n")
        .nth(1)
        .expect("docs/architecture.md has its crate table");
    let stated: BTreeMap<String, BTreeSet<String>> = table
        .lines()
        .take_while(|l| l.starts_with('|'))
        .map(|l| {
            let cells: Vec<&str> = l.trim_matches('|').split('|').map(str::trim).collect();
            let name = cells[0].trim_matches('`').to_string();
            let uses = cells[1]
                .split(", ")
                .filter(|u| *u != "none")
                .map(|u| u.trim_matches('`').to_string())
                .collect();
            (name, uses)
        })
        .collect();
    assert_eq!(
        stated, manifests,
        "docs/architecture.md's crate table (left) against the manifests (right)"
    );
}

/// Only what runs simulated robots links the agent's code: the station
/// with its `sim` feature (the demo's `spawn`), so the TUI and the Zenoh
/// bridge; the ROS 2 bridge, which only attaches to a station, does not,
/// nor does the station built without it.
#[test]
fn only_the_programs_that_simulate_robots_link_the_agent() {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let links = |args: &[&str]| {
        let tree = cargo_stdout(
            &cargo,
            &[&["tree", "-e", "normal,build", "--prefix", "none"], args].concat(),
        );
        tree.lines().any(|l| l.starts_with("mech-agent "))
    };
    for krate in ["mech-gcs", "mech-zenoh"] {
        assert!(links(&["-p", krate]), "{krate} runs the demo's robots");
    }
    assert!(
        !links(&["-p", "mech-ros2"]),
        "the ROS 2 bridge links mech-agent"
    );
    assert!(!links(&["-p", "mech-station", "--no-default-features"]));
}
