//! The kernel's files (`src/`) and the bindings' files (`bindings/src/`) depend on each other
//! one way, each crate on its own: every path a file names (`crate::a::b`,
//! `super::c`, `child::d`, in a `use` or inline) is an edge to the file of that module, and the
//! graph of those edges has no cycle. A child module naming its parent's items (the AVX2
//! twins in `engine/chunk/avx.rs` and `engine/integrate/wide.rs` use their parent's types) is
//! part of the parent's implementation and not an edge; siblings and top-level modules must
//! depend one way. (One type's `impl` blocks spread over several files, as the
//! engine's, call each other's methods without naming paths; those calls are not edges, and
//! neither is a module's `pub use child::Item`, its public face.)
//!
//! Besides having no cycle, the kernel keeps a layer order ([`LAYERS`]): the samplers are
//! handed views by the engine and never reach into it.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

fn rs_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap() {
        let p = e.unwrap().path();
        if p.is_dir() {
            rs_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

/// Module path of a file under a crate's source root ("" for lib.rs, "engine" for
/// engine/mod.rs).
fn module_of(src: &Path, f: &Path) -> Vec<String> {
    let rel = f.strip_prefix(src).unwrap().with_extension("");
    let mut m: Vec<String> = rel.iter().map(|s| s.to_string_lossy().into()).collect();
    if matches!(m.last().map(String::as_str), Some("mod" | "lib")) {
        m.pop();
    }
    m
}

/// The deepest module of `path` that is a file of the crate.
fn resolve<V>(path: &[String], files: &BTreeMap<Vec<String>, V>) -> Option<Vec<String>> {
    (0..=path.len())
        .rev()
        .map(|k| path[..k].to_vec())
        .find(|m| files.contains_key(m))
}

/// How a path named in code starts.
#[derive(Clone, Copy, PartialEq)]
enum Root {
    Crate,
    Super,
    /// A child module of the file, by name.
    Child,
}

/// The child modules a file declares (`mod name;`, `pub mod name;`).
fn children(text: &str) -> Vec<String> {
    text.lines()
        .filter_map(|l| {
            let l = l
                .trim_start()
                .trim_start_matches("pub ")
                .trim_start_matches("pub(crate) ");
            let name = l.strip_prefix("mod ")?.strip_suffix(';')?;
            Some(name.to_string())
        })
        .collect()
}

/// Paths named in code (comments and strings left out): `crate::…`, `super::…` and
/// `child::…` for the file's own child modules.
fn named_paths(text: &str) -> Vec<(Root, Vec<String>)> {
    let kids = children(text);
    let mut roots: Vec<(String, Root)> = vec![
        ("crate::".into(), Root::Crate),
        ("super::".into(), Root::Super),
    ];
    roots.extend(kids.iter().map(|k| (format!("{k}::"), Root::Child)));
    let mut out = vec![];
    for line in text.lines() {
        // a parent's `pub use child::Item` is the module's public face, not a use of the
        // child's code
        if line.starts_with("pub use ") {
            continue;
        }
        let code = line.split("//").next().unwrap();
        let code: String = code.split('"').step_by(2).collect::<Vec<_>>().join(" ");
        for (root, kind) in &roots {
            let (root, kind) = (root.as_str(), *kind);
            let mut rest = code.as_str();
            while let Some(i) = rest.find(root) {
                let before = rest[..i].chars().last();
                rest = &rest[i + root.len()..];
                if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                    continue;
                }
                let mut segs = vec![];
                if kind == Root::Child {
                    segs.push(root.trim_end_matches("::").to_string());
                }
                let mut r = rest;
                loop {
                    let end = r
                        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
                        .unwrap_or(r.len());
                    if end == 0 {
                        break;
                    }
                    segs.push(r[..end].to_string());
                    r = &r[end..];
                    match r.strip_prefix("::") {
                        Some(x) => r = x,
                        None => break,
                    }
                }
                out.push((kind, segs));
            }
        }
    }
    out
}

/// Module path -> file text, for every `.rs` file under `src`.
type Files = BTreeMap<Vec<String>, String>;
/// Module -> the modules (files) it names.
type Edges = BTreeMap<Vec<String>, BTreeSet<Vec<String>>>;

fn scan(src: &Path) -> Files {
    let mut list = vec![];
    rs_files(src, &mut list);
    list.iter()
        .map(|f| (module_of(src, f), std::fs::read_to_string(f).unwrap()))
        .collect()
}

fn modules(s: &str) -> Vec<String> {
    if s.is_empty() {
        return vec![];
    }
    s.split("::").map(String::from).collect()
}

/// The edges between the files of one crate.
fn edges_of(files: &Files) -> Edges {
    let mut edges = Edges::new();
    for (m, text) in files {
        let mut text = text.clone();
        // an inline `mod tests` (whose `super` is the file itself) is not the file's code
        if let Some(i) = text.find("#[cfg(test)]\nmod tests") {
            text.truncate(i);
        }
        for (kind, segs) in named_paths(&text) {
            let target = match kind {
                Root::Crate => segs,
                Root::Super => {
                    let mut t = m[..m.len().saturating_sub(1)].to_vec();
                    t.extend(segs);
                    t
                }
                Root::Child => {
                    let mut t = m.clone();
                    t.extend(segs);
                    t
                }
            };
            if let Some(t) = resolve(&target, files) {
                // a child module using its parent's items is part of the parent's
                // implementation (inside its privacy boundary): not an edge
                if &t != m && !m.starts_with(&t) {
                    edges.entry(m.clone()).or_default().insert(t);
                }
            }
        }
    }
    edges
}

/// A cycle of the graph, if it has one (depth-first search).
fn find_cycle(nodes: impl Iterator<Item = Vec<String>>, edges: &Edges) -> Option<Vec<String>> {
    fn visit(
        n: &Vec<String>,
        edges: &Edges,
        state: &mut BTreeMap<Vec<String>, u8>,
        stack: &mut Vec<Vec<String>>,
    ) -> Option<Vec<Vec<String>>> {
        match state.get(n) {
            Some(2) => return None,
            Some(1) => {
                let i = stack.iter().position(|x| x == n).unwrap();
                return Some(stack[i..].to_vec());
            }
            _ => {}
        }
        state.insert(n.clone(), 1);
        stack.push(n.clone());
        for t in edges.get(n).into_iter().flatten() {
            if let Some(c) = visit(t, edges, state, stack) {
                return Some(c);
            }
        }
        stack.pop();
        state.insert(n.clone(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for n in nodes {
        if let Some(c) = visit(&n, edges, &mut state, &mut vec![]) {
            return Some(c.iter().map(|m| m.join("::")).collect());
        }
    }
    None
}

/// Kernel layers: (lower, upper) means no module under `lower` names one under `upper`.
const LAYERS: &[(&str, &str)] = &[("sampling", "engine")];

/// The edges that break a layer of `layers`, as "from -> to".
fn layer_breaks(edges: &Edges, layers: &[(&str, &str)]) -> Vec<String> {
    let mut out = vec![];
    for (lower, upper) in layers {
        let (lower, upper) = (modules(lower), modules(upper));
        for (m, ts) in edges {
            for t in ts {
                if m.starts_with(&lower) && t.starts_with(&upper) {
                    out.push(format!("{} -> {}", m.join("::"), t.join("::")));
                }
            }
        }
    }
    out
}

/// The crate under `dir` (relative to the kernel's root) has no cycle; returns its edges.
fn one_way(dir: &str) -> Edges {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join(dir);
    let files = scan(&src);
    assert!(
        files.contains_key(&Vec::<String>::new()),
        "no lib.rs under {dir}"
    );
    let edges = edges_of(&files);
    if let Some(c) = find_cycle(files.keys().cloned(), &edges) {
        panic!("import cycle in {dir}/: {}", c.join(" -> "));
    }
    edges
}

/// Whether `edges` has the edge a -> b.
fn has(edges: &Edges, a: &str, b: &str) -> bool {
    edges
        .get(&modules(a))
        .is_some_and(|s| s.contains(&modules(b)))
}

#[test]
fn kernel_files_depend_one_way() {
    let edges = one_way("src");
    let breaks = layer_breaks(&edges, LAYERS);
    assert!(breaks.is_empty(), "layer order broken in src/: {breaks:?}");
    // the check sees the edges it should (a test that can fail on a broken scan)
    for (a, b) in [
        ("engine::chunk", "components"),
        ("engine::forces", "engine::chunk"),
        ("engine::integrate", "engine::forces"),
        ("engine::team", "engine::chunk"),
        ("engine::chunk", "simd"),
        ("sampling::channel", "simd"),
    ] {
        assert!(has(&edges, a, b), "{a} -> {b} not seen: {edges:?}");
    }
}

#[test]
fn binding_files_depend_one_way() {
    let edges = one_way("bindings/src");
    for (a, b) in [
        ("build", "convert"),
        ("build", "sim"),
        ("sim", "convert"),
        ("sim", "arrow"),
        ("convert", "errors"),
    ] {
        assert!(has(&edges, a, b), "{a} -> {b} not seen: {edges:?}");
    }
}

/// The rules fail where they should: a synthetic crate with a circle through `crate::`, one
/// through `super::`, a child naming its parent (allowed) and a broken layer.
#[test]
fn the_rules_can_fail() {
    let crate_of = |files: &[(&str, &str)]| -> Files {
        files
            .iter()
            .map(|(m, t)| (modules(m), t.to_string()))
            .collect()
    };
    let cycle = |files: &[(&str, &str)]| {
        let files = crate_of(files);
        find_cycle(files.keys().cloned(), &edges_of(&files))
    };
    // crate:: circle between siblings, seen with its members
    let c = cycle(&[
        ("", "mod a;\nmod b;\n"),
        ("a", "use crate::b::Thing;\n"),
        ("b", "fn f() { crate::a::g(); }\n"),
    ])
    .expect("a <-> b is a circle");
    assert_eq!(c.len(), 2, "{c:?}");
    assert!(
        c.contains(&"a".to_string()) && c.contains(&"b".to_string()),
        "{c:?}"
    );
    // super:: circle through three files
    assert!(cycle(&[
        ("", "mod x;\n"),
        ("x", "mod p;\nmod q;\nmod r;\n"),
        ("x::p", "use super::q::A;\n"),
        ("x::q", "use super::r::B;\n"),
        ("x::r", "use super::p::C;\n"),
    ])
    .is_some());
    // one way, a child naming its parent's items, a comment, a string and a test module
    // naming the other way: no circle
    assert_eq!(
        cycle(&[
            ("", "mod a;\nmod b;\n"),
            ("a", "mod w;\nuse crate::b::Thing;\nfn f() { w::g(); }\n"),
            ("a::w", "use super::Own;\n"),
            (
                "b",
                "// crate::a::x\nconst S: &str = \"crate::a::y\";\n#[cfg(test)]\nmod tests {\n    use crate::a::z;\n}\n",
            ),
        ]),
        None
    );
    // a layer broken by a sampler naming the engine
    let files = crate_of(&[
        ("", "mod engine;\nmod sampling;\n"),
        ("engine", "use crate::sampling::View;\n"),
        ("sampling", "use crate::engine::simd::dispatch;\n"),
    ]);
    let edges = edges_of(&files);
    assert_eq!(
        layer_breaks(&edges, LAYERS),
        vec!["sampling -> engine".to_string()]
    );
}
