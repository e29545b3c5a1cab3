//! The layout's invariants (issue 19, points 3 and 4; ARCHITECTURE.md "Invariants"): no circle
//! between the source files of `models`, of `services` or of `tools`, the web pages never fit,
//! and the service library holds no benchmark or load tool (those are `tools/`).
//!
//! The graph: file A depends on file B when A's code (outside `#[cfg(test)]`, `//` comments
//! left out) names B's module by a `crate::…` or `super::…` path. A circle is a strongly
//! connected set of more than one file (Tarjan).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).expect("read dir") {
        let p = e.expect("entry").path();
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// Module path of each file under `src` (`lift::identify`; `lib.rs` and `main.rs` are the
/// root, ""), with its code.
fn modules(src: &Path) -> BTreeMap<String, String> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let mut out = BTreeMap::new();
    for f in files {
        let rel = f.strip_prefix(src).expect("under src").with_extension("");
        let parts: Vec<String> = rel
            .components()
            .map(|c| c.as_os_str().to_string_lossy().into_owned())
            .collect();
        let mut m = parts.join("::");
        if m == "lib" || m == "main" {
            m = String::new();
        } else if let Some(stripped) = m.strip_suffix("::mod") {
            m = stripped.to_owned();
        }
        let text = std::fs::read_to_string(&f).expect("source");
        let code: String = text
            .split("#[cfg(test)]")
            .next()
            .unwrap_or("")
            .lines()
            .map(|l| l.split("//").next().unwrap_or(""))
            .collect::<Vec<_>>()
            .join("\n");
        out.entry(m).or_insert(code);
    }
    out
}

/// Each file's dependencies on the crate's other files.
fn graph(mods: &BTreeMap<String, String>) -> BTreeMap<String, BTreeSet<String>> {
    let mut g = BTreeMap::new();
    for (m, code) in mods {
        let parent = m.rsplit_once("::").map_or("", |(p, _)| p).to_owned();
        let mut deps = BTreeSet::new();
        for root in ["crate::", "super::"] {
            for (i, _) in code.match_indices(root) {
                // Not the tail of a longer path (`pantowatch::crate::` does not occur; an
                // identifier ending in "crate" or "super" would).
                if i > 0 && code.as_bytes()[i - 1].is_ascii_alphanumeric() {
                    continue;
                }
                let rest = &code[i + root.len()..];
                let path: Vec<&str> = rest
                    .split(|c: char| !(c.is_ascii_alphanumeric() || c == '_' || c == ':'))
                    .next()
                    .unwrap_or("")
                    .split("::")
                    .filter(|s| !s.is_empty())
                    .collect();
                let mut cur = if root == "crate::" {
                    String::new()
                } else {
                    parent.clone()
                };
                let mut best = None;
                for seg in path {
                    cur = if cur.is_empty() {
                        seg.to_owned()
                    } else {
                        format!("{cur}::{seg}")
                    };
                    if mods.contains_key(&cur) {
                        best = Some(cur.clone());
                    } else {
                        break;
                    }
                }
                if let Some(b) = best
                    && &b != m
                    && !m.starts_with(&format!("{b}::"))
                    && !b.starts_with(&format!("{m}::"))
                {
                    deps.insert(b);
                }
            }
        }
        g.insert(m.clone(), deps);
    }
    g
}

/// Strongly connected sets of more than one file.
fn circles(g: &BTreeMap<String, BTreeSet<String>>) -> Vec<Vec<String>> {
    struct T<'a> {
        g: &'a BTreeMap<String, BTreeSet<String>>,
        index: BTreeMap<&'a str, usize>,
        low: BTreeMap<&'a str, usize>,
        stack: Vec<&'a str>,
        on: BTreeSet<&'a str>,
        next: usize,
        out: Vec<Vec<String>>,
    }
    fn visit<'a>(t: &mut T<'a>, v: &'a str) {
        t.index.insert(v, t.next);
        t.low.insert(v, t.next);
        t.next += 1;
        t.stack.push(v);
        t.on.insert(v);
        let g = t.g;
        for w in &g[v] {
            let w = w.as_str();
            if !t.index.contains_key(w) {
                visit(t, w);
                let lw = t.low[w];
                let lv = t.low.get_mut(v).expect("visited");
                *lv = (*lv).min(lw);
            } else if t.on.contains(w) {
                let iw = t.index[w];
                let lv = t.low.get_mut(v).expect("visited");
                *lv = (*lv).min(iw);
            }
        }
        if t.low[v] == t.index[v] {
            let mut comp = Vec::new();
            while let Some(w) = t.stack.pop() {
                t.on.remove(w);
                comp.push(w.to_owned());
                if w == v {
                    break;
                }
            }
            if comp.len() > 1 {
                comp.sort();
                t.out.push(comp);
            }
        }
    }
    let mut t = T {
        g,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on: BTreeSet::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in g.keys() {
        if !t.index.contains_key(v.as_str()) {
            visit(&mut t, v);
        }
    }
    t.out
}

fn crate_src(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(name)
        .join("src")
}

#[test]
fn the_finder_sees_a_circle_it_is_shown() {
    let mut mods = BTreeMap::new();
    mods.insert("a".to_owned(), "use crate::b::X;".to_owned());
    mods.insert("b".to_owned(), "use super::c::Y;".to_owned());
    mods.insert("c".to_owned(), "fn f() { crate::a::g() }".to_owned());
    mods.insert("d".to_owned(), "use crate::a;".to_owned());
    assert_eq!(circles(&graph(&mods)), vec![vec!["a", "b", "c"]]);
    mods.insert("c".to_owned(), String::new());
    assert!(circles(&graph(&mods)).is_empty());
}

#[test]
fn no_circle_between_the_files_of_models_services_or_tools() {
    for (name, at_least) in [("models", 20), ("services", 20), ("tools", 10)] {
        let mods = modules(&crate_src(name));
        assert!(mods.len() > at_least, "{name}: {} files", mods.len());
        let found = circles(&graph(&mods));
        assert!(found.is_empty(), "{name}: circles {found:?}");
    }
}

/// The benchmark suite and the load generator live in `tools/` (crate `pantowatch-tools`), not
/// in the service library: no `bench` or `load` module in services/src, no `bench`/`load`
/// subcommand in the `pantowatch` binary, and no dependency of the service on the tools.
#[test]
fn the_service_library_holds_no_benchmark_or_load_tool() {
    let services = crate_src("services");
    for gone in ["cli/bench", "cli/bench.rs", "cli/load", "cli/load.rs"] {
        assert!(
            !services.join(gone).exists(),
            "services/src/{gone}: the tools belong in tools/"
        );
    }
    let mods = modules(&services);
    for (m, code) in &mods {
        assert!(
            !m.split("::").any(|seg| seg == "bench" || seg == "load"),
            "services::{m}: a benchmark or load module in the service library"
        );
        assert!(
            !code.contains("pantowatch_tools"),
            "services::{m} uses the tools crate"
        );
    }
    let main_rs = std::fs::read_to_string(services.join("main.rs")).expect("main.rs");
    for sub in ["Bench(", "Load("] {
        assert!(
            !main_rs.contains(sub),
            "the pantowatch binary has a {sub}…) subcommand"
        );
    }
    let manifest =
        std::fs::read_to_string(services.join("../Cargo.toml")).expect("services/Cargo.toml");
    assert!(
        !manifest.contains("pantowatch-tools"),
        "services/Cargo.toml depends on the tools crate"
    );
    // Where they are instead (so this test cannot pass on an empty tree).
    let tools = modules(&crate_src("tools"));
    for m in ["bench", "bench::suite", "load"] {
        assert!(tools.contains_key(m), "tools::{m} missing");
    }
}

#[test]
fn the_web_pages_never_fit() {
    let mods = modules(&crate_src("services"));
    let fitters = [
        "fitting::",
        "fit_joint_test",
        "fit_lift_trace",
        "fit_map",
        "fit_swing",
    ];
    for (m, code) in mods.iter().filter(|(m, _)| m.starts_with("web")) {
        for f in fitters {
            assert!(
                !code.contains(f),
                "services::{m} calls {f}: a page draws stored fits"
            );
        }
    }
}

/// Issue 19, point 4: `models/src` shows its architecture — the pantograph type's data, then one
/// folder per thing a reader looks for (numerics, one joint, the complete pantograph, the
/// quadrangle, the contract) and nothing loose beside them.
#[test]
fn models_src_is_grouped_by_what_a_reader_looks_for() {
    let src = crate_src("models");
    let mut found: Vec<String> = std::fs::read_dir(&src)
        .expect("models/src")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    found.sort();
    assert_eq!(
        found,
        [
            "contract",
            "data.rs",
            "joint",
            "lib.rs",
            "lift",
            "numerics",
            "quadrangle"
        ],
        "models/src holds a file outside its groups"
    );
}

/// Issue 19, point 4: no source file over ~800 lines (820) in the crates' `src`.
#[test]
fn no_source_file_is_over_820_lines() {
    for name in ["models", "services", "tools"] {
        let mut files = Vec::new();
        rust_files(&crate_src(name), &mut files);
        for f in files {
            let n = std::fs::read_to_string(&f).expect("source").lines().count();
            assert!(n <= 820, "{}: {n} lines", f.display());
        }
    }
}

/// Ways of picking a field out of a fit result held as JSON: a key of the result (or of its
/// parts) looked up by `.get("…")`, `["…"]` or a `.pointer("/…")` path.
const RESULT_KEYS: [&str; 17] = [
    "joints",
    "joint",
    "viscous",
    "dry",
    "baseline",
    "rmse",
    "residual",
    "effects",
    "verdict",
    "correlates_with",
    "excess_ratio",
    "joints_withheld",
    "holdout_note",
    "autocorrelation",
    "pooled",
    "combinations",
    "model_version",
];

/// Where `code` picks a fit-result field out of JSON: `(line, text)`.
fn json_field_picks(code: &str) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    for (n, line) in code.lines().enumerate() {
        let picks = RESULT_KEYS.iter().any(|k| {
            line.contains(&format!(".get(\"{k}\")"))
                || line.contains(&format!("[\"{k}\"]"))
                || line.contains(&format!(".pointer(\"/{k}"))
        }) || line.contains(".pointer(&format!(\"/{");
        if picks {
            found.push((n + 1, line.trim().to_owned()));
        }
    }
    found
}

#[test]
fn the_finder_sees_json_field_picking() {
    assert_eq!(
        json_field_picks("let a = 1;\nlet j = result.get(\"joints\");\nr[\"verdict\"]").len(),
        2
    );
    assert_eq!(
        json_field_picks("x.pointer(\"/residual/effects\")").len(),
        1
    );
    assert_eq!(
        json_field_picks("j.pointer(&format!(\"/{p}/baseline\"))").len(),
        1
    );
    assert!(json_field_picks("result.residual.verdict.is_none()").is_empty());
}

/// Issue 19, point 1: the fit result is a Rust type (`models::report::FitResult`) from the fit
/// to the store, which serialises it; the alert rules, health, the pooled fit, the API and the
/// web pages read that type (`FitRecord::result`), never fields out of its JSON.
#[test]
fn fit_results_are_read_typed_not_picked_out_of_json() {
    let mods = modules(&crate_src("services"));
    let readers = |m: &str| {
        ["alerts", "health", "pooled", "worker", "store::records"].contains(&m)
            || m.starts_with("web")
            || m.starts_with("api")
    };
    let mut seen = 0;
    for (m, code) in mods.iter().filter(|(m, _)| readers(m)) {
        seen += 1;
        let picks = json_field_picks(code);
        assert!(
            picks.is_empty(),
            "services::{m} picks fit-result fields out of JSON: {picks:?}"
        );
    }
    assert!(seen > 10, "{seen} files scanned");
}
