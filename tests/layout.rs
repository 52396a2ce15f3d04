//! The kernel's files depend on each other one way: every path a file names (`crate::a::b`,
//! `super::c`, `child::d`, in a `use` or inline) is an edge to the file of that module, and the
//! graph of those edges has no cycle. A child module naming its parent's items (the AVX2
//! twins in `engine/chunk/avx.rs` and `engine/integrate/wide.rs` use their parent's types) is
//! part of the parent's implementation and not an edge; siblings and top-level modules must
//! depend one way. (One type's `impl` blocks spread over several files, as the
//! engine's, call each other's methods without naming paths; those calls are not edges, and
//! neither is a module's `pub use child::Item`, its public face.)

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

/// Module path of a file under src/ ("" for lib.rs, "engine" for engine/mod.rs).
fn module_of(src: &Path, f: &Path) -> Vec<String> {
    let rel = f.strip_prefix(src).unwrap().with_extension("");
    let mut m: Vec<String> = rel.iter().map(|s| s.to_string_lossy().into()).collect();
    if matches!(m.last().map(String::as_str), Some("mod" | "lib")) {
        m.pop();
    }
    m
}

/// The deepest module of `path` that is a file of the crate.
fn resolve(path: &[String], files: &BTreeMap<Vec<String>, PathBuf>) -> Option<Vec<String>> {
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

#[test]
fn kernel_files_depend_one_way() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut list = vec![];
    rs_files(&src, &mut list);
    let files: BTreeMap<Vec<String>, PathBuf> = list
        .iter()
        .map(|f| (module_of(&src, f), f.clone()))
        .collect();
    let mut edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    for (m, f) in &files {
        let mut text = std::fs::read_to_string(f).unwrap();
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
            if let Some(t) = resolve(&target, &files) {
                // a child module using its parent's items is part of the parent's
                // implementation (inside its privacy boundary): not an edge
                if &t != m && !m.starts_with(&t) {
                    edges.entry(m.clone()).or_default().insert(t);
                }
            }
        }
    }
    // depth-first search for a cycle, reporting it
    fn visit(
        n: &Vec<String>,
        edges: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
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
    for n in files.keys() {
        if let Some(c) = visit(n, &edges, &mut state, &mut vec![]) {
            let names: Vec<String> = c.iter().map(|m| m.join("::")).collect();
            panic!("import cycle in src/: {}", names.join(" -> "));
        }
    }
    // the check sees the edges it should (a test that can fail on a broken scan)
    let e = |a: &str, b: &str| {
        let m = |s: &str| s.split("::").map(String::from).collect::<Vec<_>>();
        edges.get(&m(a)).is_some_and(|s| s.contains(&m(b)))
    };
    assert!(e("engine::chunk", "components"), "{edges:?}");
    assert!(e("engine::forces", "engine::chunk"), "{edges:?}");
    assert!(e("engine::integrate", "engine::forces"), "{edges:?}");
    assert!(e("engine::team", "engine::chunk"), "{edges:?}");
}
