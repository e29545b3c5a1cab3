//! Invariants of the `models` crate (issue 19, point 5; ARCHITECTURE.md "Invariants"):
//! - every paper or protocol number lives in models/data/160ec.toml with its source, and no
//!   code of models/src repeats one ([`no_paper_number_in_code`]);
//! - models does no I/O: its dependencies are pure ([`dependencies_are_pure`]) and its code
//!   names no file, socket, process or async runtime ([`no_io_in_code`]).
//!
//! Code means models/src/**/*.rs outside the data loader (src/data.rs), outside files named
//! `tests.rs` and outside `#[cfg(test)]` modules (by the crate's convention, the end of a file
//! from the first `#[cfg(test)]` on), with `//` comments left out.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The sections of the data file whose values are the paper's or a test protocol's: Table 2
/// (bodies), Table 4 (joints), the rigs of Figs 5–12, the slider rig, the paper's test
/// protocols; and gravity.
const PAPER_SECTIONS: [&str; 5] = ["bodies", "joints", "rigs", "slider", "paper_tests"];

/// The sections of the geometry file (`160ec-geometry.toml`) scanned likewise; left out:
/// `meta` (labels), `checks` and `reference_pose` (values computed from the file, for its
/// tests), `design` (a record of what was tuned) and `assembly` (branch signs ±1).
const GEOMETRY_SECTIONS: [&str; 8] = [
    "ground",
    "bodies",
    "joints",
    "head_suspension",
    "range",
    "drive",
    "stand",
    "lift_test",
];

/// Values of those sections that code uses for reasons of its own (unit factors, grids of
/// trial factors, integrator coefficients such as Dormand–Prince's 500/1113, kernel exponents):
/// too round to mean the paper. The paper's values among them (τ = 0.8 s, 500 Hz, −0.5 s, k =
/// 4.0 N/mm) are still read from the data file; this test just cannot tell them apart.
/// The geometry file adds 0.4 (τ's lower limit), 1.5, 1.8 (Table 1's top), 12, 30 (the stand's
/// longest test) and 0.99, each also an iteration count, a drift band, a clamp or a bit shift.
const ROUND: [f64; 20] = [
    0.0, 0.5, 1.0, 2.0, 3.0, 4.0, 5.0, 10.0, 0.001, 0.01, 0.05, 0.2, 0.8, 500.0, 0.4, 1.5, 1.8,
    12.0, 30.0, 0.99,
];

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn collect_numbers(v: &toml::Value, out: &mut BTreeSet<u64>, key: &str) {
    match v {
        // The paper's body numbers (1..n) are labels, not values.
        _ if key == "paper_no" => {}
        toml::Value::Float(f) => {
            out.insert(f.to_bits());
        }
        toml::Value::Integer(i) => {
            out.insert((*i as f64).to_bits());
        }
        toml::Value::Array(a) => a.iter().for_each(|x| collect_numbers(x, out, key)),
        toml::Value::Table(t) => t.iter().for_each(|(k, x)| collect_numbers(x, out, k)),
        _ => {}
    }
}

/// Every number of the paper sections, as `f64` bits, less the round ones.
fn paper_numbers() -> BTreeSet<u64> {
    let text = std::fs::read_to_string(root().join("data/160ec.toml")).expect("data file");
    let doc: toml::Value = toml::from_str(&text).expect("data file parses");
    let mut out = BTreeSet::new();
    for s in PAPER_SECTIONS {
        let section = doc.get(s).unwrap_or_else(|| panic!("data file has [{s}]"));
        collect_numbers(section, &mut out, s);
    }
    collect_numbers(&doc["gravity_m_s2"], &mut out, "gravity_m_s2");
    // The complete pantograph's file: the paper's lift states (Section 5.3), the drive's and
    // the stand's stated limits, the operating range (Table 1), the head suspension (Section
    // 4.2), the bodies' and joints' geometry.
    let text = std::fs::read_to_string(root().join("data/160ec-geometry.toml")).expect("geometry");
    let doc: toml::Value = toml::from_str(&text).expect("geometry file parses");
    for s in GEOMETRY_SECTIONS {
        let section = doc
            .get(s)
            .unwrap_or_else(|| panic!("geometry file has [{s}]"));
        collect_numbers(section, &mut out, s);
    }
    for r in ROUND {
        out.remove(&r.to_bits());
        out.remove(&(-r).to_bits());
    }
    out
}

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).expect("read dir") {
        let p = e.expect("dir entry").path();
        if p.is_dir() {
            if p.file_name().is_some_and(|n| n != "tests") {
                rust_files(&p, out);
            }
        } else if p.extension().is_some_and(|x| x == "rs")
            && p.file_name().is_some_and(|n| n != "tests.rs")
        {
            out.push(p);
        }
    }
}

/// (file relative to models/, line number, line) of every line of code (module doc).
fn code_lines() -> Vec<(String, usize, String)> {
    let mut files = Vec::new();
    rust_files(&root().join("src"), &mut files);
    files.sort();
    assert!(files.len() > 20, "models/src holds the crate's code");
    let mut out = Vec::new();
    for f in files {
        let rel = f
            .strip_prefix(root())
            .expect("under models/")
            .display()
            .to_string();
        // The type file's loader, and its tests that check the built-in file against the
        // paper's printed values on purpose.
        if rel == "src/data.rs" || rel == "src/data/tests.rs" {
            continue;
        }
        let text = std::fs::read_to_string(&f).expect("source file");
        for (i, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("#[cfg(test)]") {
                break;
            }
            let code = line.split("//").next().unwrap_or("");
            out.push((rel.clone(), i + 1, code.to_owned()));
        }
    }
    out
}

/// The numeric literals of a line of code, with their sign when a `-` stands right before them.
fn literals(code: &str) -> Vec<(String, f64)> {
    let b = code.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let prev_ident = i > 0 && (b[i - 1].is_ascii_alphanumeric() || b[i - 1] == b'_');
        let prev_dot = i > 0 && b[i - 1] == b'.';
        if !b[i].is_ascii_digit() || prev_ident || prev_dot {
            i += 1;
            continue;
        }
        let start = i;
        while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'_') {
            i += 1;
        }
        if i + 1 < b.len() && b[i] == b'.' && b[i + 1].is_ascii_digit() {
            i += 1;
            while i < b.len() && (b[i].is_ascii_digit() || b[i] == b'_') {
                i += 1;
            }
        }
        if i < b.len() && (b[i] == b'e' || b[i] == b'E') {
            let mut j = i + 1;
            if j < b.len() && (b[j] == b'-' || b[j] == b'+') {
                j += 1;
            }
            if j < b.len() && b[j].is_ascii_digit() {
                i = j;
                while i < b.len() && b[i].is_ascii_digit() {
                    i += 1;
                }
            }
        }
        let text = code[start..i].replace('_', "");
        if let Ok(v) = text.parse::<f64>() {
            let negative = start > 0 && b[start - 1] == b'-';
            let shown = if negative { format!("-{text}") } else { text };
            out.push((shown, if negative { -v } else { v }));
        }
    }
    out
}

#[test]
fn the_scanner_reads_literals_as_code_writes_them() {
    let found: Vec<f64> = literals("let x = [-10.1, 330.0, 1_000, 2e-3]; f(x0, 0.5f64)")
        .into_iter()
        .map(|(_, v)| v)
        .collect();
    assert_eq!(found, vec![-10.1, 330.0, 1000.0, 2e-3, 0.5]);
    let numbers = paper_numbers();
    for v in [
        70.0f64, -10.1, 330.0, 18.8, 0.802, 0.034, 4.05, 9.81, 1.84, 1110.0, 2220.0, 986.0,
    ] {
        assert!(numbers.contains(&v.to_bits()), "{v} is a paper number");
    }
}

#[test]
fn no_paper_number_in_code() {
    let numbers = paper_numbers();
    let found: Vec<String> = code_lines()
        .into_iter()
        .flat_map(|(file, n, code)| {
            literals(&code)
                .into_iter()
                .filter(|(_, v)| numbers.contains(&v.to_bits()))
                .map(|(text, _)| format!("models/{file}:{n}: {text}"))
                .collect::<Vec<_>>()
        })
        .collect();
    assert!(
        found.is_empty(),
        "paper numbers in code (move each to models/data/160ec.toml with its source, read it \
         through models::data):\n{}",
        found.join("\n")
    );
}

#[test]
fn dependencies_are_pure() {
    // utoipa: optional (feature `openapi`), schema derives only.
    const ALLOWED: [&str; 7] = [
        "nalgebra",
        "serde",
        "serde_json",
        "toml",
        "thiserror",
        "statrs",
        "utoipa",
    ];
    let text = std::fs::read_to_string(root().join("Cargo.toml")).expect("Cargo.toml");
    let doc: toml::Value = toml::from_str(&text).expect("Cargo.toml parses");
    let deps = doc
        .get("dependencies")
        .and_then(|d| d.as_table())
        .expect("[dependencies]");
    assert!(!deps.is_empty());
    let extra: Vec<&String> = deps
        .keys()
        .filter(|k| !ALLOWED.contains(&k.as_str()))
        .collect();
    assert!(
        extra.is_empty(),
        "models/Cargo.toml depends on {extra:?}: models is pure physics, no I/O (ARCHITECTURE.md)"
    );
    for table in ["target", "build-dependencies"] {
        assert!(
            doc.get(table).is_none(),
            "models/Cargo.toml has [{table}]: its dependencies are [dependencies] alone"
        );
    }
}

#[test]
fn no_io_in_code() {
    const IO: [&str; 5] = [
        "std::fs",
        "std::net",
        "std::process",
        "tokio",
        "std::io::stdin",
    ];
    let found: Vec<String> = code_lines()
        .into_iter()
        .filter(|(_, _, code)| IO.iter().any(|w| code.contains(w)))
        .map(|(file, n, code)| format!("models/{file}:{n}: {}", code.trim()))
        .collect();
    assert!(
        found.is_empty(),
        "I/O in models (it belongs in services):\n{}",
        found.join("\n")
    );
}
