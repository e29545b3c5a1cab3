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
/// root, ""), with its whole text.
fn sources(src: &Path) -> BTreeMap<String, String> {
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
        out.entry(m)
            .or_insert(std::fs::read_to_string(&f).expect("source"));
    }
    out
}

/// Module path of each file under `src` with its code: the text before its first
/// `#[cfg(test)]`, `//` comments left out (what the text checks below scan; the graph reads
/// [`sources`] through [`code_tokens`]).
fn modules(src: &Path) -> BTreeMap<String, String> {
    sources(src)
        .into_iter()
        .map(|(m, text)| {
            let code: String = text
                .split("#[cfg(test)]")
                .next()
                .unwrap_or("")
                .lines()
                .map(|l| l.split("//").next().unwrap_or(""))
                .collect::<Vec<_>>()
                .join("\n");
            (m, code)
        })
        .collect()
}

/// A token of Rust code as the graph needs it: identifiers (keywords included), `::`, and
/// single punctuation characters. Comments, string and character literals and lifetimes are
/// dropped; a string or a number becomes `"`.
fn tokens(text: &str) -> Vec<String> {
    let c: Vec<char> = text.chars().collect();
    let mut out = Vec::new();
    let mut i = 0;
    while i < c.len() {
        let ch = c[i];
        let next = c.get(i + 1).copied();
        if ch.is_whitespace() {
            i += 1;
        } else if ch == '/' && next == Some('/') {
            while i < c.len() && c[i] != '\n' {
                i += 1;
            }
        } else if ch == '/' && next == Some('*') {
            let mut depth = 0;
            while i < c.len() {
                if c[i] == '/' && c.get(i + 1) == Some(&'*') {
                    depth += 1;
                    i += 2;
                } else if c[i] == '*' && c.get(i + 1) == Some(&'/') {
                    depth -= 1;
                    i += 2;
                    if depth == 0 {
                        break;
                    }
                } else {
                    i += 1;
                }
            }
        } else if ch == '"' || ((ch == 'r' || ch == 'b') && raw_or_byte_string(&c, i)) {
            i = skip_string(&c, i);
            out.push("\"".to_owned());
        } else if ch == '\'' {
            // A character literal ('a', '\n', '\u{..}') or a lifetime ('a): both dropped.
            if next == Some('\\') {
                // Past the quote, the backslash and the escaped character.
                i += 3;
                while i < c.len() && c[i] != '\'' {
                    i += 1;
                }
                i += 1;
            } else if c.get(i + 2) == Some(&'\'') {
                i += 3;
            } else {
                i += 1;
                while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                    i += 1;
                }
            }
        } else if ch.is_alphabetic() || ch == '_' {
            let s = i;
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_') {
                i += 1;
            }
            out.push(c[s..i].iter().collect());
        } else if ch.is_ascii_digit() {
            while i < c.len() && (c[i].is_alphanumeric() || c[i] == '_' || c[i] == '.') {
                if c[i] == '.' && !c.get(i + 1).is_some_and(|d| d.is_ascii_digit()) {
                    break;
                }
                i += 1;
            }
            out.push("\"".to_owned());
        } else if ch == ':' && next == Some(':') {
            out.push("::".to_owned());
            i += 2;
        } else {
            out.push(ch.to_string());
            i += 1;
        }
    }
    out
}

/// Whether a string literal starts at `i` with a prefix: `r"`, `r#"`, `b"`, `br"`, `br#"`.
fn raw_or_byte_string(c: &[char], i: usize) -> bool {
    if i > 0 && (c[i - 1].is_alphanumeric() || c[i - 1] == '_') {
        return false;
    }
    let mut j = i;
    if c[j] == 'b' {
        j += 1;
    }
    if c.get(j) == Some(&'r') {
        j += 1;
        while c.get(j) == Some(&'#') {
            j += 1;
        }
    }
    j > i && c.get(j) == Some(&'"')
}

/// The index after the string literal starting at `i` (plain, byte or raw).
fn skip_string(c: &[char], mut i: usize) -> usize {
    let mut raw = false;
    while c[i] != '"' {
        raw |= c[i] == 'r';
        i += 1;
    }
    let hashes = c[..i].iter().rev().take_while(|ch| **ch == '#').count();
    i += 1;
    while i < c.len() {
        if !raw && c[i] == '\\' {
            i += 2;
        } else if c[i] == '"'
            && c[i + 1..]
                .iter()
                .take(hashes)
                .filter(|h| **h == '#')
                .count()
                == hashes
        {
            return i + 1 + hashes;
        } else {
            i += 1;
        }
    }
    i
}

/// The tokens of `text` without the items marked `#[cfg(test)]` (a `mod x;`, or an item up to
/// its `;` or its closing brace): the code a build of the crate compiles.
fn code_tokens(text: &str) -> Vec<String> {
    let t = tokens(text);
    let mut out = Vec::with_capacity(t.len());
    let mut i = 0;
    while i < t.len() {
        let is_cfg_test = t[i] == "#"
            && t.get(i + 1).is_some_and(|s| s == "[")
            && t.get(i + 2).is_some_and(|s| s == "cfg")
            && t.get(i + 3).is_some_and(|s| s == "(")
            && t.get(i + 4).is_some_and(|s| s == "test")
            && t.get(i + 5).is_some_and(|s| s == ")")
            && t.get(i + 6).is_some_and(|s| s == "]");
        if !is_cfg_test {
            out.push(t[i].clone());
            i += 1;
            continue;
        }
        // Skip the item: to its `;` at depth 0 or to the brace closing its first `{`.
        i += 7;
        let mut depth = 0i32;
        while i < t.len() {
            match t[i].as_str() {
                "{" | "(" | "[" => depth += 1,
                "}" | ")" | "]" => {
                    depth -= 1;
                    if depth == 0 && t[i] == "}" {
                        i += 1;
                        break;
                    }
                }
                ";" if depth == 0 => {
                    i += 1;
                    break;
                }
                _ => {}
            }
            i += 1;
        }
    }
    out
}

/// A name a `use` brings into scope: `alias` for the path `path` (as written, not resolved);
/// `glob` for `path::*`.
#[derive(Debug, Clone, PartialEq)]
struct UseItem {
    alias: String,
    path: Vec<String>,
    glob: bool,
}

/// Expand the use tree starting at `t[*i]` under `prefix` into `out`: `a::b::{c, d::{e as f},
/// self, *}`.
fn use_tree(t: &[String], i: &mut usize, prefix: &[String], out: &mut Vec<UseItem>) {
    let mut path = prefix.to_vec();
    // A leading `::` (an extern path) adds nothing.
    if t.get(*i).is_some_and(|s| s == "::") {
        *i += 1;
    }
    loop {
        match t.get(*i).map(String::as_str) {
            Some("{") => {
                *i += 1;
                while t.get(*i).is_some_and(|s| s != "}") {
                    use_tree(t, i, &path, out);
                    if t.get(*i).is_some_and(|s| s == ",") {
                        *i += 1;
                    }
                }
                *i += 1;
                return;
            }
            Some("*") => {
                *i += 1;
                out.push(UseItem {
                    alias: String::new(),
                    path,
                    glob: true,
                });
                return;
            }
            Some(s)
                if s.chars()
                    .next()
                    .is_some_and(|c| c.is_alphabetic() || c == '_') =>
            {
                path.push(s.to_owned());
                *i += 1;
                if t.get(*i).is_some_and(|s| s == "::") {
                    *i += 1;
                    continue;
                }
                if path.last().is_some_and(|s| s == "self") {
                    path.pop();
                }
                let mut alias = path.last().cloned().unwrap_or_default();
                if t.get(*i).is_some_and(|s| s == "as") {
                    alias = t.get(*i + 1).cloned().unwrap_or_default();
                    *i += 2;
                }
                out.push(UseItem {
                    alias,
                    path,
                    glob: false,
                });
                return;
            }
            _ => {
                // Not a use tree (a stray token): step over it.
                *i += 1;
                return;
            }
        }
    }
}

/// A file's `use` declarations expanded (every visibility; `extern crate` is not one), and
/// the paths its other code names: chains `a::b::c` of two or more segments.
fn uses_and_paths(t: &[String]) -> (Vec<UseItem>, Vec<Vec<String>>) {
    let mut uses = Vec::new();
    let mut paths = Vec::new();
    let mut i = 0;
    while i < t.len() {
        if t[i] == "use" {
            i += 1;
            while i < t.len() && t[i] != ";" {
                use_tree(t, &mut i, &[], &mut uses);
            }
            i += 1;
            continue;
        }
        let starts_path = t[i]
            .chars()
            .next()
            .is_some_and(|c| c.is_alphabetic() || c == '_')
            && t.get(i + 1).is_some_and(|s| s == "::")
            && (i == 0 || (t[i - 1] != "::" && t[i - 1] != "."));
        if !starts_path {
            i += 1;
            continue;
        }
        let mut path = vec![t[i].clone()];
        i += 1;
        while t.get(i).is_some_and(|s| s == "::")
            && t.get(i + 1).is_some_and(|s| {
                s.chars()
                    .next()
                    .is_some_and(|c| c.is_alphabetic() || c == '_')
            })
        {
            path.push(t[i + 1].clone());
            i += 2;
        }
        paths.push(path);
    }
    (uses, paths)
}

/// What the graph knows of a crate: each module's `use` items and named paths.
struct Crate {
    uses: BTreeMap<String, Vec<UseItem>>,
    paths: BTreeMap<String, Vec<Vec<String>>>,
    code: BTreeMap<String, Vec<String>>,
}

impl Crate {
    fn new(texts: &BTreeMap<String, String>) -> Self {
        let mut c = Crate {
            uses: BTreeMap::new(),
            paths: BTreeMap::new(),
            code: BTreeMap::new(),
        };
        for (m, text) in texts {
            let t = code_tokens(text);
            let (u, p) = uses_and_paths(&t);
            c.uses.insert(m.clone(), u);
            c.paths.insert(m.clone(), p);
            c.code.insert(m.clone(), t);
        }
        c
    }

    fn is_module(&self, m: &[String]) -> bool {
        self.code.contains_key(&m.join("::"))
    }

    /// The absolute path (from the crate root) of `path` as written in module `m`: `crate::`,
    /// `super::` (any number), `self::`, a name `m` imports, or a child module of `m`. `None`
    /// for what is outside the crate (std, other crates, a local type's associated item).
    fn absolute(&self, m: &str, path: &[String], depth: usize) -> Option<Vec<String>> {
        if depth > 16 || path.is_empty() {
            return None;
        }
        let here: Vec<String> = if m.is_empty() {
            Vec::new()
        } else {
            m.split("::").map(str::to_owned).collect()
        };
        let mut base = here.clone();
        let mut k = 0;
        match path[0].as_str() {
            "crate" => {
                base.clear();
                k = 1;
            }
            "self" => k = 1,
            "super" => {
                while path.get(k).is_some_and(|s| s == "super") {
                    base.pop()?;
                    k += 1;
                }
            }
            first => {
                if let Some(u) = self
                    .uses
                    .get(m)
                    .and_then(|us| us.iter().find(|u| !u.glob && u.alias == first))
                {
                    // `use x::y as first;` then `first::…`; a `use` of itself resolves in `m`.
                    if u.path.first().is_some_and(|s| s == first) && u.path.len() == 1 {
                        return None;
                    }
                    base = self.absolute(m, &u.path, depth + 1)?;
                    k = 1;
                } else {
                    let mut child = here.clone();
                    child.push(first.to_owned());
                    if !self.is_module(&child) {
                        return None;
                    }
                    base = child;
                    k = 1;
                }
            }
        }
        base.extend(path[k..].iter().cloned());
        Some(base)
    }

    /// The file an absolute path lands in: its longest prefix that is a file's module, then,
    /// where the next segment is a name that module imports (a re-export, `pub use`, or an
    /// import its submodules see), the file that import lands in.
    fn target(&self, abs: &[String], depth: usize) -> Option<String> {
        let mut n = 0;
        for k in 0..=abs.len() {
            if self.is_module(&abs[..k]) {
                n = k;
            } else if k > 0 {
                break;
            }
        }
        if !self.is_module(&abs[..n]) {
            return None;
        }
        let m = abs[..n].join("::");
        if depth < 16
            && let Some(name) = abs.get(n)
        {
            let uses = &self.uses[&m];
            let via = uses
                .iter()
                .find(|u| !u.glob && &u.alias == name)
                .map(|u| u.path.clone())
                .or_else(|| {
                    // A name from a glob import, where that module defines it.
                    uses.iter().filter(|u| u.glob).find_map(|u| {
                        let g = self.absolute(&m, &u.path, 0)?;
                        let gm = self.target(&g, depth + 1)?;
                        self.defines(&gm, name).then(|| {
                            let mut p = u.path.clone();
                            p.push(name.clone());
                            p
                        })
                    })
                });
            if let Some(p) = via
                && let Some(mut a) = self.absolute(&m, &p, 0)
            {
                a.extend(abs[n + 1..].iter().cloned());
                if let Some(t) = self.target(&a, depth + 1) {
                    return Some(t);
                }
            }
        }
        Some(m)
    }

    /// Module `m` defines an item `name` (fn, struct, enum, const, static, type, trait, mod, union, macro).
    fn defines(&self, m: &str, name: &str) -> bool {
        let t = &self.code[m];
        t.windows(2).any(|w| {
            w[1] == name
                && [
                    "fn", "struct", "enum", "const", "static", "type", "trait", "mod", "union",
                ]
                .contains(&w[0].as_str())
        })
    }

    /// The files module `m`'s code depends on (itself, its ancestors and descendants left out:
    /// a module declares its submodules and they see it).
    fn deps(&self, m: &str) -> BTreeSet<String> {
        let mut out = BTreeSet::new();
        let written = self.uses[m]
            .iter()
            .map(|u| u.path.clone())
            .chain(self.paths[m].iter().cloned());
        for p in written {
            let Some(abs) = self.absolute(m, &p, 0) else {
                continue;
            };
            let Some(b) = self.target(&abs, 0) else {
                continue;
            };
            let related = b == m
                || m.starts_with(&format!("{b}::"))
                || b.starts_with(&format!("{m}::"))
                || b.is_empty()
                || m.is_empty();
            if !related {
                out.insert(b);
            }
        }
        out
    }
}

/// Each file's dependencies on the crate's other files: file A depends on file B when A's
/// code (outside `#[cfg(test)]` items, comments and strings left out) names a path that lands
/// in B — by `crate::`, `super::` chains, `self::`, a child module, or a name a `use` brought
/// into scope (grouped and nested `use` trees expanded), in a `use` or inline; a path to a name
/// a module re-exports lands where the re-export does.
fn graph(texts: &BTreeMap<String, String>) -> BTreeMap<String, BTreeSet<String>> {
    let c = Crate::new(texts);
    texts.keys().map(|m| (m.clone(), c.deps(m))).collect()
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

fn texts(files: &[(&str, &str)]) -> BTreeMap<String, String> {
    files
        .iter()
        .map(|(m, t)| ((*m).to_owned(), (*t).to_owned()))
        .collect()
}

fn deps_of(g: &BTreeMap<String, BTreeSet<String>>, m: &str) -> Vec<String> {
    g[m].iter().cloned().collect()
}

/// Every way a file names another resolves to that file: `super::super::` chains, `self::`,
/// grouped and nested `use` trees, aliases, inline paths, a name reached through a module's
/// `use` (a re-export) or glob; and what a build does not compile (`#[cfg(test)]` items,
/// comments, strings) names nothing.
#[test]
fn the_finder_resolves_every_form_of_path() {
    let g = graph(&texts(&[
        ("", "pub mod a; pub mod b; pub mod c; pub mod d;"),
        ("a", "pub mod x; pub mod y;"),
        // `super::super::` from a/x reaches the root's b; `self::` stays in a/x's children.
        (
            "a::x",
            "use super::super::b::B;\npub mod inner;\nfn f() { self::inner::g() }",
        ),
        ("a::x::inner", "pub fn g() {}"),
        // A grouped, nested use tree: `c` and `d` both.
        ("a::y", "use crate::{c::{self as cc, C}, d::*};"),
        ("b", "pub struct B;"),
        ("c", "pub struct C;"),
        ("d", "pub struct D;"),
    ]));
    assert_eq!(deps_of(&g, "a::x"), ["b"]);
    assert_eq!(deps_of(&g, "a::y"), ["c", "d"]);

    let g = graph(&texts(&[
        ("", "pub mod p;"),
        (
            "p",
            "pub mod q; pub mod r; pub mod s; pub mod t; pub mod u;",
        ),
        // A parent re-exporting its child's item: a path to it lands in the child's file.
        (
            "p::q",
            "pub mod inner; pub use inner::Thing; pub use inner::*;",
        ),
        ("p::q::inner", "pub struct Thing; pub fn helper() {}"),
        // Inline paths in code, one through an alias of a module, one by a re-export.
        (
            "p::r",
            "use super::q as qq;\nfn f() -> usize { let _ = super::s::value(); qq::inner::helper(); 0 }",
        ),
        ("p::s", "pub fn value() -> super::q::Thing { todo!() }"),
        // A glob re-export: the name is found where the glob's module defines it.
        ("p::t", "fn f() { super::q::helper() }"),
        // Only what a build compiles: no test item, comment, doc or string names a file.
        (
            "p::u",
            "// super::q::Thing\n/// [`super::r`]\n/* super::s::value */\nconst S: &str = \"super::t::f\";\n#[cfg(test)]\nmod tests { use super::super::q::Thing; }\n#[cfg(test)]\nfn helper() { super::s::value(); }",
        ),
    ]));
    assert_eq!(deps_of(&g, "p::r"), ["p::q", "p::q::inner", "p::s"]);
    assert_eq!(deps_of(&g, "p::s"), ["p::q::inner"]);
    assert_eq!(deps_of(&g, "p::t"), ["p::q::inner"]);
    assert!(deps_of(&g, "p::u").is_empty(), "{:?}", g["p::u"]);
}

/// The circle of issue 39, point 4, as it was: `lift/gauge/fit.rs` took the lift fit's types
/// and `inverse_spd` from `super::super::identify` (three `super::` hops the old finder read as
/// `lift::gauge::super`), and `lift/identify.rs` its Jacobian step, the gauge zero's prior and
/// the warm starts from `super::gauge::…`; `lift/fit.rs` held the gauge's estimate through the
/// parent's re-export. The lines are the old files' own (commit 119290c), each file with its
/// module's other declarations reduced to what names a file.
#[test]
fn the_finder_sees_the_old_gauge_identify_circle() {
    let old = texts(&[
        ("", "pub mod lift;"),
        (
            "lift",
            "pub mod attribution; pub mod fit; pub mod gauge; pub mod identify; pub mod static_force;",
        ),
        (
            "lift::attribution",
            "pub use super::fit::{AttributionOptions, Combination};",
        ),
        ("lift::static_force", "pub struct DriveLine;"),
        (
            "lift::fit",
            "pub struct PooledGauge {\n    pub record: super::gauge::GaugeRecord,\n    pub drive: super::static_force::DriveLine,\n}\npub struct LiftFit {\n    pub gauge_offsets: Vec<super::gauge::GaugeEffectEstimate>,\n}\npub struct EffectPrior;\npub struct LiftFitOptions;\npub struct ParamEstimate;",
        ),
        (
            "lift::identify",
            "pub use super::fit::{\n    EffectEstimate, EffectPrior, Identifiability, JointEstimate, LiftFit, LiftFitError,\n    LiftFitOptions, LiftTrace, POOLED_INTERVAL_SCALE, POOLED_PER_TRACE, ParamEstimate, PooledGauge,\n    effect_prior,\n};\nconst GAUGE_FD_STEP: f64 = super::gauge::fit::FD_STEP;\nconst GAUGE_ZERO_PRIOR: EffectPrior = super::gauge::fit::SENSOR_OFFSET_PRIOR;\npub(crate) fn inverse_spd(a: &DMatrix<f64>) -> DMatrix<f64> { todo!() }\nfn f() {\n    let gauge_warm = super::gauge::solve::warm_starts(model, model.alpha_range_rad, &g.drive, &g.record);\n}",
        ),
        (
            "lift::gauge",
            "pub mod fit;\npub(crate) mod solve;\npub use fit::{GaugeEffect, GaugeEffectEstimate, GaugeFit, GaugeFitOptions, fit_gauge};\npub use super::static_force::DriveLine;\npub struct GaugeRecord;",
        ),
        (
            "lift::gauge::fit",
            "use super::super::attribution::{AttributionOptions, Combination, attribute};\nuse super::super::identify::{EffectPrior, LiftFitOptions, ParamEstimate};\nuse super::solve::{Warm, forces_near, warm_starts};\npub const FD_STEP: f64 = 1e-4;\npub const SENSOR_OFFSET_PRIOR: EffectPrior = EffectPrior;\npub struct GaugeEffectEstimate;\nfn f() {\n    let cov0 = super::super::identify::inverse_spd(&post0);\n}",
        ),
        (
            "lift::gauge::solve",
            "use super::{GaugeError, GaugeRecord};\npub fn warm_starts() {}",
        ),
    ]);
    let g = graph(&old);
    assert!(g["lift::gauge::fit"].contains("lift::identify"), "{g:?}");
    assert!(g["lift::identify"].contains("lift::gauge::fit"), "{g:?}");
    // `attribution` was in it too: the gauge fit used it, and it the lift fit's types.
    assert_eq!(
        circles(&g),
        vec![vec![
            "lift::attribution",
            "lift::fit",
            "lift::gauge::fit",
            "lift::identify"
        ]]
    );

    // The same circle put back into today's files (each naming an item the other defines):
    // the guard on the real tree finds it.
    let mut models = sources(&crate_src("models"));
    assert!(circles(&graph(&models)).is_empty());
    models
        .get_mut("lift::gauge::fit")
        .expect("models/src/lift/gauge/fit.rs")
        .push_str("\nfn old() { let _ = super::super::identify::fit_map; }\n");
    models
        .get_mut("lift::identify")
        .expect("models/src/lift/identify.rs")
        .push_str("\nfn old() { let _ = super::gauge::fit::fit_gauge_from; }\n");
    let found = circles(&graph(&models));
    assert!(
        found
            .iter()
            .any(|c| c.contains(&"lift::gauge::fit".to_owned())
                && c.contains(&"lift::identify".to_owned())),
        "{found:?}"
    );
}

#[test]
fn no_circle_between_the_files_of_models_services_or_tools() {
    for (name, at_least) in [("models", 20), ("services", 20), ("tools", 10)] {
        let mods = sources(&crate_src(name));
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
            "data",
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
