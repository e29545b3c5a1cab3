//! ARCHITECTURE.md's module list stays true (issue 39, point 1): its section "Where things live"
//! names every module directly under `models/src`, `services/src` and `tools/src` and every
//! module of `models::lift`, and every module path it names (`models::…`, `services::…`,
//! `tools::…` in backticks) is a file or folder of that crate.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

const SECTION: &str = "## Where things live";

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .expect("the tests crate sits in the workspace")
        .to_path_buf()
}

/// The `src` folder of a crate as ARCHITECTURE.md names it (`models`, `services`, `tools`).
fn src_of(krate: &str) -> Option<PathBuf> {
    match krate {
        "models" | "services" | "tools" => Some(repo().join(krate).join("src")),
        _ => None,
    }
}

/// The text of one `## ` section of a Markdown document, up to the next `## ` heading.
fn section<'a>(doc: &'a str, heading: &str) -> Option<&'a str> {
    let start = doc.find(&format!("\n{heading}\n"))? + heading.len() + 2;
    let rest = &doc[start..];
    Some(rest.find("\n## ").map_or(rest, |end| &rest[..end]))
}

/// Every backticked `krate::a::b` path in `text` whose first segment is a crate of the
/// workspace, as written (items after the module path are not allowed in this section).
fn named_paths(text: &str) -> BTreeSet<String> {
    text.split('`')
        .skip(1)
        .step_by(2)
        .filter(|span| {
            span.split_once("::")
                .is_some_and(|(krate, _)| src_of(krate).is_some())
                && span
                    .chars()
                    .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_' || c == ':')
        })
        .map(str::to_owned)
        .collect()
}

/// Whether `krate::a::b` is a module of that crate: `src/a/b.rs`, or a folder `src/a/b/`.
fn is_module(path: &str) -> bool {
    let mut parts = path.split("::");
    let Some(src) = parts.next().and_then(src_of) else {
        return false;
    };
    let rel: PathBuf = parts.collect();
    if rel.as_os_str().is_empty() {
        return false;
    }
    src.join(&rel).with_extension("rs").is_file() || src.join(&rel).is_dir()
}

/// The modules directly under `dir` (files `x.rs` and folders `x/`), as `prefix::x`, leaving
/// out the crate roots and `mod.rs`, test-only files and folders named `tests`.
fn modules_under(dir: &Path, prefix: &str) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("reading {}: {e}", dir.display()))
    {
        let path = entry.expect("directory entry").path();
        let name = if path.is_dir() {
            path.file_name().map(|n| n.to_string_lossy().into_owned())
        } else if path.extension().is_some_and(|x| x == "rs") {
            path.file_stem().map(|n| n.to_string_lossy().into_owned())
        } else {
            None
        };
        let Some(name) = name else { continue };
        if ["lib", "main", "mod", "tests"].contains(&name.as_str()) || name.ends_with("_tests") {
            continue;
        }
        out.insert(format!("{prefix}::{name}"));
    }
    out
}

fn architecture_section() -> String {
    let path = repo().join("ARCHITECTURE.md");
    let doc = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("reading {}: {e}", path.display()));
    section(&doc, SECTION)
        .unwrap_or_else(|| panic!("ARCHITECTURE.md has no section \"{SECTION}\""))
        .to_owned()
}

/// What is wrong with a "Where things live" section: the modules it does not name, and the
/// names in it that are not modules.
fn problems(section: &str) -> (Vec<String>, Vec<String>) {
    let named = named_paths(section);
    let mut expected = BTreeSet::new();
    for krate in ["models", "services", "tools"] {
        expected.extend(modules_under(&src_of(krate).expect("a crate"), krate));
    }
    expected.extend(modules_under(
        &repo().join("models/src/lift"),
        "models::lift",
    ));
    let missing = expected.difference(&named).cloned().collect();
    let not_modules = named.into_iter().filter(|p| !is_module(p)).collect();
    (missing, not_modules)
}

#[test]
fn architecture_md_names_every_module_and_only_modules() {
    let (missing, not_modules) = problems(&architecture_section());
    assert!(
        missing.is_empty() && not_modules.is_empty(),
        "ARCHITECTURE.md \"{SECTION}\" is out of date:\n  modules it does not name: {missing:?}\n  \
         names that are not modules: {not_modules:?}\nName each module there, in backticks, \
         with its crate (`models::lift::fit`), and remove the names of modules that are gone."
    );
}

#[test]
fn the_check_names_a_module_left_out_and_a_name_that_is_no_module() {
    // The guard itself, on the real section edited: `models::lift::fit` left out and an
    // invented module named instead are both reported, and nothing else is.
    let section = architecture_section();
    assert!(
        named_paths(&section).len() > 40,
        "the section's module paths are parsed"
    );
    let edited = section.replace("`models::lift::fit`", "`models::lift::no_such_module`");
    let (missing, not_modules) = problems(&edited);
    assert_eq!(missing, ["models::lift::fit"]);
    assert_eq!(not_modules, ["models::lift::no_such_module"]);
}
