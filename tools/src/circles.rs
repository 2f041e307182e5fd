//! No import circles between a crate's top-level modules: a test over the
//! source's `crate::` paths (and `super::` in top-level files), so that
//! each crate's modules read as layers, dependencies pointing one way
//! (CONTRIBUTING.md). Comment lines and test code (a `#[cfg(test)]`
//! module and everything after it, files named `tests.rs` or `test_*.rs`)
//! are left out: a test may use any module.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// The crates checked, by source folder from the workspace root (the
/// `pcrnet` CLI is one file, `train-host/cli/src/main.rs`).
pub const CRATES: [&str; 5] = [
    "core/src",
    "capi/src",
    "train-host/io/src",
    "train-host/train/src",
    "train-host/eval/src",
];

/// Each top-level module of the crate in `src` and the other top-level
/// modules its non-test code names.
pub fn module_graph(src: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    collect(src, &mut files);
    let module_of = |path: &Path| -> Option<(String, bool)> {
        let rel = path.strip_prefix(src).ok()?;
        let parts: Vec<_> = rel.iter().filter_map(|p| p.to_str()).collect();
        let first = parts.first()?;
        let name = first.strip_suffix(".rs").unwrap_or(first).to_string();
        let top_level = parts.len() == 1 || parts.get(1) == Some(&"mod.rs");
        (name != "lib" && name != "main").then_some((name, top_level))
    };
    let modules: BTreeSet<String> = files
        .iter()
        .filter_map(|f| module_of(f).map(|(m, _)| m))
        .collect();
    let mut graph: BTreeMap<String, BTreeSet<String>> = modules
        .iter()
        .map(|m| (m.clone(), BTreeSet::new()))
        .collect();
    for file in &files {
        let Some((module, top_level)) = module_of(file) else {
            continue;
        };
        let name = file.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if name == "tests.rs" || name.starts_with("test_") {
            continue;
        }
        let text = std::fs::read_to_string(file).unwrap_or_default();
        let code = non_test_code(&text);
        let mut named = paths_after(&code, "crate::");
        if top_level {
            named.extend(paths_after(&code, "super::"));
        }
        let edges = graph.entry(module.clone()).or_default();
        edges.extend(
            named
                .into_iter()
                .filter(|n| *n != module && modules.contains(n)),
        );
    }
    graph
}

/// The cycles of `graph` (strongly connected parts of more than one module).
pub fn circles(graph: &BTreeMap<String, BTreeSet<String>>) -> Vec<BTreeSet<String>> {
    // Two modules are in one circle when each reaches the other.
    let reach = |from: &String| -> BTreeSet<String> {
        let mut seen = BTreeSet::new();
        let mut todo = vec![from.clone()];
        while let Some(m) = todo.pop() {
            for n in graph.get(&m).into_iter().flatten() {
                if seen.insert(n.clone()) {
                    todo.push(n.clone());
                }
            }
        }
        seen
    };
    let reached: BTreeMap<&String, BTreeSet<String>> =
        graph.keys().map(|m| (m, reach(m))).collect();
    let mut out: Vec<BTreeSet<String>> = Vec::new();
    for (m, r) in &reached {
        let circle: BTreeSet<String> = r
            .iter()
            .filter(|n| reached.get(n).is_some_and(|back| back.contains(*m)))
            .cloned()
            .collect();
        if circle.len() > 1 && !out.contains(&circle) {
            out.push(circle);
        }
    }
    out
}

fn collect(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for entry in entries.flatten() {
        let path = entry.path();
        if path.is_dir() {
            collect(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// `text` up to its first test module, without comment lines.
fn non_test_code(text: &str) -> String {
    let mut code = String::new();
    let mut lines = text.lines().peekable();
    while let Some(line) = lines.next() {
        let t = line.trim_start();
        if t.starts_with("#[cfg(test)]") || t.starts_with("#[cfg(all(test") {
            let next = lines.peek().map_or("", |l| l.trim_start());
            if next.starts_with("mod ") || next.starts_with("pub(crate) mod ") {
                break;
            }
        }
        if !t.starts_with("//") {
            code.push_str(line);
            code.push('\n');
        }
    }
    code
}

/// The first path segment after each `prefix` in `code`, and each name of
/// a `prefix{a, b::c}` group.
fn paths_after(code: &str, prefix: &str) -> BTreeSet<String> {
    let ident = |s: &str| -> String {
        s.chars()
            .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
            .collect()
    };
    let mut out = BTreeSet::new();
    for (at, _) in code.match_indices(prefix) {
        let rest = &code[at + prefix.len()..];
        if let Some(group) = rest.strip_prefix('{') {
            let inner = group.split('}').next().unwrap_or("");
            out.extend(inner.split(',').map(|p| ident(p.trim())));
        } else {
            out.insert(ident(rest));
        }
    }
    out.retain(|n| !n.is_empty());
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every checked crate is free of circles; a planted one is found.
    #[test]
    fn no_import_circles() {
        let root = crate::root();
        for src in CRATES {
            let graph = module_graph(&root.join(src));
            assert!(graph.len() > 1, "{src}: no modules found");
            let found = circles(&graph);
            assert!(
                found.is_empty(),
                "{src}: modules that import each other: {found:?}; move what they share into a module below both"
            );
        }
        let mut planted = module_graph(&root.join("core/src"));
        planted
            .entry("arch".into())
            .or_default()
            .insert("registration".into());
        assert!(!circles(&planted).is_empty());
        assert_eq!(
            paths_after("use crate::{a, b::c};\nx = super::d::e;", "crate::"),
            ["a", "b"].map(String::from).into()
        );
    }
}
