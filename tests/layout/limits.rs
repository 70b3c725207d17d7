//! The workspace's size limits, checked on its sources: no struct with more
//! than [`MAX_FIELDS`] fields unless it is plain configuration, counters or
//! a wire type; no impl block over [`MAX_IMPL_LINES`] lines; no function
//! over [`MAX_FN_LINES`] lines unless it is a flat table. A type or
//! function past a limit is a sign it holds more than one job.
//!
//! Every Rust file of the workspace's members is parsed (`syn`), tests and
//! benches included. A struct counts its fields; an impl block its lines
//! from `impl` to its closing brace; a function (free, method, or trait
//! default) from `fn` to its closing brace. What a macro invocation holds
//! is not seen. Each exception is listed in [`EXCEPTIONS`] with why it may
//! stand; an exception that no longer applies fails the check too, so the
//! list says what is true.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use syn::visit::Visit;

/// Most fields a struct may have.
pub const MAX_FIELDS: usize = 15;
/// Most lines an impl block may span.
pub const MAX_IMPL_LINES: usize = 400;
/// Most lines a function may span.
pub const MAX_FN_LINES: usize = 80;

/// Which limit an item passes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum Limit {
    Fields,
    ImplLines,
    FnLines,
}

/// An item allowed past a limit, and why.
#[derive(Debug)]
pub struct Exception {
    /// Path from the workspace root.
    pub file: &'static str,
    /// `Struct`, `Type` (an impl block of it), `function` or
    /// `Type::method`.
    pub item: &'static str,
    pub limit: Limit,
    pub why: &'static str,
}

const CONFIG: &str = "plain configuration: one field per setting, read from a file";
const COUNTERS: &str = "counters: one field per thing counted";
const ROS_MESSAGE: &str = "a wire type: a ROS 2 message's fields, in its layout";
const BENCH_RUN: &str = "a benchmark's whole run in the order it happens (start the \
                         station, load it, measure, print the table); not one of the \
                         kinds the limits exempt, listed so the check holds for the rest";

const fn allow(
    file: &'static str,
    item: &'static str,
    limit: Limit,
    why: &'static str,
) -> Exception {
    Exception {
        file,
        item,
        limit,
        why,
    }
}

/// The items allowed past a limit.
pub const EXCEPTIONS: &[Exception] = &[
    // Structs.
    allow(
        "agent/src/machine/counters.rs",
        "Counters",
        Limit::Fields,
        COUNTERS,
    ),
    allow("agent/src/config.rs", "RobotConfig", Limit::Fields, CONFIG),
    allow(
        "gcs-tui/core/src/router/config.rs",
        "RouterConfig",
        Limit::Fields,
        CONFIG,
    ),
    allow(
        "gcs-tui/ros2/src/config.rs",
        "Ros2Config",
        Limit::Fields,
        CONFIG,
    ),
    allow(
        "gcs-tui/ros2/src/stats.rs",
        "StatsSnapshot",
        Limit::Fields,
        COUNTERS,
    ),
    allow(
        "ros2-dds/src/msgs/sensor.rs",
        "BatteryState",
        Limit::Fields,
        ROS_MESSAGE,
    ),
    allow(
        "ros2-dds/src/msgs/visualization.rs",
        "Marker",
        Limit::Fields,
        ROS_MESSAGE,
    ),
    allow(
        "gcs-tui/station/src/view.rs",
        "RobotView",
        Limit::Fields,
        "a wire type: the attach protocol's robot, as a UI shows it",
    ),
    allow(
        "gcs-tui/core/src/fleet/robot.rs",
        "Robot",
        Limit::Fields,
        "the fleet model's one record of a robot: registration, links, telemetry, route, \
         missions, trail and the operators' settings for it, each read by another part \
         of the station",
    ),
    // Functions that are flat tables.
    allow(
        "agent/src/drivers/l298.rs",
        "pin_sequence_forward_back_turn_stop",
        Limit::FnLines,
        "a flat table: the pin writes expected after each output",
    ),
    allow(
        "gcs-tui/control/src/lang/verbs.rs",
        "every_control_verb_parses",
        Limit::FnLines,
        "a flat table: one line of the language and what it parses to, per verb",
    ),
    allow(
        "proto/tests/corrupt.rs",
        "samples",
        Limit::FnLines,
        "a flat table: one sample message per body",
    ),
    allow(
        "proto/tests/roundtrip.rs",
        "body",
        Limit::FnLines,
        "a flat table: one generator per message body",
    ),
    allow(
        "gcs-tui/core/src/record/schema.rs",
        "every_event",
        Limit::FnLines,
        "a flat table: one of every event, as the recorder writes it",
    ),
    // Benchmarks.
    allow(
        "gcs-tui/ros2/benches/bridge.rs",
        "run",
        Limit::FnLines,
        BENCH_RUN,
    ),
    allow(
        "agent/examples/safety_bench.rs",
        "main",
        Limit::FnLines,
        BENCH_RUN,
    ),
    allow("tests/flood/main.rs", "main", Limit::FnLines, BENCH_RUN),
];

/// One item past a limit.
#[derive(Debug, Clone, PartialEq, Eq, PartialOrd, Ord)]
pub struct Finding {
    pub file: String,
    pub item: String,
    pub limit: Limit,
    /// Fields or lines.
    pub size: usize,
    /// Line where the item starts.
    pub line: usize,
}

/// Sizes of every struct, impl block and function of one file.
#[derive(Debug, Default)]
pub struct Sizes {
    /// `(item, limit, size, line)`.
    pub items: Vec<(String, Limit, usize, usize)>,
    /// The impl block being walked (for method names).
    owner: Vec<String>,
}

fn type_name(ty: &syn::Type) -> String {
    match ty {
        syn::Type::Path(p) => p
            .path
            .segments
            .last()
            .map(|s| s.ident.to_string())
            .unwrap_or_default(),
        syn::Type::Reference(r) => type_name(&r.elem),
        _ => "?".to_string(),
    }
}

fn lines(from: proc_macro2::Span, to: proc_macro2::Span) -> (usize, usize) {
    let (start, end) = (from.start().line, to.end().line);
    (end.saturating_sub(start) + 1, start)
}

impl Sizes {
    fn function(&mut self, name: &syn::Ident, fn_token: &syn::token::Fn, block: &syn::Block) {
        let (n, line) = lines(fn_token.span, block.brace_token.span.close());
        let item = match self.owner.last() {
            Some(owner) => format!("{owner}::{name}"),
            None => name.to_string(),
        };
        self.items.push((item, Limit::FnLines, n, line));
    }
}

impl<'ast> Visit<'ast> for Sizes {
    fn visit_item_struct(&mut self, s: &'ast syn::ItemStruct) {
        let line = s.struct_token.span.start().line;
        self.items
            .push((s.ident.to_string(), Limit::Fields, s.fields.len(), line));
        syn::visit::visit_item_struct(self, s);
    }

    fn visit_item_impl(&mut self, i: &'ast syn::ItemImpl) {
        let name = type_name(&i.self_ty);
        let (n, line) = lines(i.impl_token.span, i.brace_token.span.close());
        self.items.push((name.clone(), Limit::ImplLines, n, line));
        self.owner.push(name);
        syn::visit::visit_item_impl(self, i);
        self.owner.pop();
    }

    fn visit_item_trait(&mut self, t: &'ast syn::ItemTrait) {
        self.owner.push(t.ident.to_string());
        syn::visit::visit_item_trait(self, t);
        self.owner.pop();
    }

    fn visit_item_fn(&mut self, f: &'ast syn::ItemFn) {
        self.function(&f.sig.ident, &f.sig.fn_token, &f.block);
        // A function inside a function is named on its own.
        let owner = std::mem::take(&mut self.owner);
        syn::visit::visit_item_fn(self, f);
        self.owner = owner;
    }

    fn visit_impl_item_fn(&mut self, f: &'ast syn::ImplItemFn) {
        self.function(&f.sig.ident, &f.sig.fn_token, &f.block);
        let owner = std::mem::take(&mut self.owner);
        syn::visit::visit_impl_item_fn(self, f);
        self.owner = owner;
    }

    fn visit_trait_item_fn(&mut self, f: &'ast syn::TraitItemFn) {
        if let Some(block) = &f.default {
            self.function(&f.sig.ident, &f.sig.fn_token, block);
        }
        let owner = std::mem::take(&mut self.owner);
        syn::visit::visit_trait_item_fn(self, f);
        self.owner = owner;
    }
}

/// The sizes of every item of `source`.
pub fn sizes(source: &str) -> Result<Vec<(String, Limit, usize, usize)>, syn::Error> {
    let file = syn::parse_file(source)?;
    let mut sizes = Sizes::default();
    sizes.visit_file(&file);
    Ok(sizes.items)
}

/// Whether an item of this size passes its limit.
fn over(limit: Limit, size: usize) -> bool {
    match limit {
        Limit::Fields => size > MAX_FIELDS,
        Limit::ImplLines => size > MAX_IMPL_LINES,
        Limit::FnLines => size > MAX_FN_LINES,
    }
}

/// Every Rust file under `dir`, leaving out build output.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<PathBuf> = entries.filter_map(Result::ok).map(|e| e.path()).collect();
    entries.sort();
    for p in entries {
        let name = p.file_name().map(|n| n.to_string_lossy().into_owned());
        if p.is_dir() {
            if !matches!(name.as_deref(), Some("target" | ".git")) {
                rust_files(&p, out);
            }
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// The workspace's member folders, from its manifest.
pub fn members(root: &Path) -> Vec<PathBuf> {
    let manifest = std::fs::read_to_string(root.join("Cargo.toml")).expect("workspace manifest");
    let start = manifest.find("members = [").expect("workspace members");
    let list = &manifest[start..];
    let list = &list[..list.find(']').expect("end of members")];
    list.split('"')
        .skip(1)
        .step_by(2)
        .map(|m| root.join(m))
        .collect()
}

/// Every item of the workspace past a limit, and the files that did not
/// parse.
pub fn findings(root: &Path) -> (Vec<Finding>, Vec<String>) {
    let mut files = Vec::new();
    for member in members(root) {
        rust_files(&member, &mut files);
    }
    let (mut found, mut unreadable) = (Vec::new(), Vec::new());
    for path in files {
        let file = path
            .strip_prefix(root)
            .unwrap_or(&path)
            .to_string_lossy()
            .into_owned();
        let parsed = std::fs::read_to_string(&path)
            .map_err(|e| e.to_string())
            .and_then(|text| sizes(&text).map_err(|e| e.to_string()));
        match parsed {
            Ok(items) => found.extend(
                items
                    .into_iter()
                    .filter(|(_, limit, size, _)| over(*limit, *size))
                    .map(|(item, limit, size, line)| Finding {
                        file: file.clone(),
                        item,
                        limit,
                        size,
                        line,
                    }),
            ),
            Err(e) => unreadable.push(format!("{file}: {e}")),
        }
    }
    found.sort();
    (found, unreadable)
}

fn excepted(f: &Finding) -> bool {
    EXCEPTIONS
        .iter()
        .any(|e| e.file == f.file && e.item == f.item && e.limit == f.limit)
}

#[test]
fn no_struct_impl_or_function_passes_its_limit_unless_listed() {
    let root = super::workspace();
    let (found, unreadable) = findings(&root);
    assert!(
        unreadable.is_empty(),
        "not parsed:\n{}",
        unreadable.join("\n")
    );
    let over: Vec<String> = found
        .iter()
        .filter(|f| !excepted(f))
        .map(|f| {
            let what = match f.limit {
                Limit::Fields => format!("{} fields (limit {MAX_FIELDS})", f.size),
                Limit::ImplLines => format!("impl of {} lines (limit {MAX_IMPL_LINES})", f.size),
                Limit::FnLines => format!("{} lines (limit {MAX_FN_LINES})", f.size),
            };
            format!("{}:{}: {} has {what}", f.file, f.line, f.item)
        })
        .collect();
    assert!(
        over.is_empty(),
        "past the limits (split it, or list it in EXCEPTIONS with why):\n{}",
        over.join("\n")
    );
    let stale: Vec<String> = EXCEPTIONS
        .iter()
        .filter(|e| {
            !found
                .iter()
                .any(|f| e.file == f.file && e.item == f.item && e.limit == f.limit)
        })
        .map(|e| format!("{} {} ({:?})", e.file, e.item, e.limit))
        .collect();
    assert!(
        stale.is_empty(),
        "listed as exceptions but within the limits (remove them):\n{}",
        stale.join("\n")
    );
    let unexplained: Vec<&str> = EXCEPTIONS
        .iter()
        .filter(|e| e.why.trim().is_empty())
        .map(|e| e.item)
        .collect();
    assert!(
        unexplained.is_empty(),
        "exceptions without a reason: {unexplained:?}"
    );
    let mut seen = BTreeSet::new();
    let doubled: Vec<&str> = EXCEPTIONS
        .iter()
        .filter(|e| !seen.insert((e.file, e.item, e.limit)))
        .map(|e| e.item)
        .collect();
    assert!(doubled.is_empty(), "listed twice: {doubled:?}");
}

#[test]
fn the_checker_measures_fields_impls_and_functions() {
    let source = r#"
/// Docs are not counted.
struct Small { a: u8, b: u8 }
struct Tuple(u8, u8, u8);
impl Small {
    fn new() -> Small {
        // A comment line.
        let s = "}"; // a brace in a string
        Small { a: 0, b: 0 }
    }

    fn tiny(&self) {}
}
trait Named {
    fn name(&self) -> String {
        fn inner() {}
        String::new()
    }
}
fn free() {
    macro_rules! m { () => { fn hidden() {} } }
}
"#;
    let items = sizes(source).unwrap();
    let find = |name: &str, limit: Limit| {
        items
            .iter()
            .find(|(n, l, _, _)| n == name && *l == limit)
            .map(|(_, _, size, line)| (*size, *line))
    };
    assert_eq!(find("Small", Limit::Fields), Some((2, 3)));
    assert_eq!(find("Tuple", Limit::Fields), Some((3, 4)));
    assert_eq!(find("Small", Limit::ImplLines), Some((9, 5)));
    assert_eq!(find("Small::new", Limit::FnLines), Some((5, 6)));
    assert_eq!(find("Small::tiny", Limit::FnLines), Some((1, 12)));
    assert_eq!(find("Named::name", Limit::FnLines), Some((4, 15)));
    assert_eq!(find("inner", Limit::FnLines), Some((1, 16)));
    assert_eq!(find("free", Limit::FnLines), Some((3, 20)));
    assert_eq!(
        find("hidden", Limit::FnLines),
        None,
        "macro bodies are not seen"
    );
    assert!(over(Limit::Fields, MAX_FIELDS + 1) && !over(Limit::Fields, MAX_FIELDS));
    assert!(over(Limit::FnLines, MAX_FN_LINES + 1) && !over(Limit::FnLines, MAX_FN_LINES));
    assert!(over(Limit::ImplLines, MAX_IMPL_LINES + 1) && !over(Limit::ImplLines, MAX_IMPL_LINES));
}

#[test]
fn every_member_is_read() {
    let root = super::workspace();
    let members = members(&root);
    for m in ["proto", "agent", "gcs-tui/core", "gcs-tui/zenoh", "tests"] {
        assert!(members.contains(&root.join(m)), "{m}: {members:?}");
    }
}
