//! The house rule that no module imports its way round in a circle,
//! read from the code's own paths: within every crate of the workspace,
//! the modules (and, one level down, the modules of each module) form a
//! graph by the `crate::…` and `super::…` paths their non-test code names,
//! and that graph has no cycle. Between crates Cargo already forbids one,
//! and the crates' order (core < cnn < daemon < sim < lab < the binary)
//! is their dependency order.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

/// A crate's modules by path (`motion::reach`), each with its source file.
fn modules(src: &Path) -> BTreeMap<Vec<String>, PathBuf> {
    let mut out = BTreeMap::new();
    let mut stack = vec![src.to_path_buf()];
    while let Some(dir) = stack.pop() {
        for entry in std::fs::read_dir(&dir).expect("a source folder") {
            let path = entry.expect("a folder entry").path();
            if path.is_dir() {
                stack.push(path);
                continue;
            }
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
            if !name.ends_with(".rs") || name.ends_with("tests.rs") {
                continue;
            }
            let rel = path.strip_prefix(src).expect("inside src").with_extension("");
            let mut parts: Vec<String> = rel.iter().map(|p| p.to_string_lossy().into_owned()).collect();
            if matches!(parts.last().map(String::as_str), Some("mod" | "lib" | "main")) {
                parts.pop();
            }
            out.insert(parts, path);
        }
    }
    out
}

/// The code of a file without its test module and its comments.
fn code(path: &Path) -> String {
    let text = std::fs::read_to_string(path).expect("a source file");
    let text = text.split("#[cfg(test)]").next().unwrap_or_default();
    text.lines().map(|l| l.split("//").next().unwrap_or_default()).collect::<Vec<_>>().join("\n")
}

/// The module paths a piece of code names, absolute within its crate.
fn named_paths(code: &str, here: &[String]) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    for (base, rest) in [("crate", false), ("super", true)] {
        let mut from = 0;
        while let Some(i) = code[from..].find(base) {
            let start = from + i;
            from = start + base.len();
            let before = code[..start].chars().next_back();
            if before.is_some_and(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                continue;
            }
            let mut path: Vec<String> = if rest { here[..here.len().saturating_sub(1)].to_vec() } else { Vec::new() };
            let mut tail = &code[from..];
            while let Some(t) = tail.strip_prefix("::") {
                let ident: String = t.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                if ident.is_empty() {
                    break;
                }
                tail = &t[ident.len()..];
                path.push(ident);
            }
            out.push(path);
        }
    }
    out
}

/// The module the crate-absolute `path` lies in: its longest prefix that is
/// a module.
fn module_of<'a>(path: &[String], mods: &'a BTreeMap<Vec<String>, PathBuf>) -> Option<&'a Vec<String>> {
    (1..=path.len()).rev().find_map(|k| mods.get_key_value(&path[..k]).map(|(m, _)| m))
}

/// The edges between modules of one level: `depth` 1 compares the crate's
/// top modules, 2 the modules of each top module among themselves.
fn edges(mods: &BTreeMap<Vec<String>, PathBuf>, depth: usize) -> BTreeMap<Vec<String>, BTreeSet<Vec<String>>> {
    let mut out: BTreeMap<Vec<String>, BTreeSet<Vec<String>>> = BTreeMap::new();
    for (here, file) in mods {
        if here.len() < depth {
            continue;
        }
        let from = here[..depth].to_vec();
        for path in named_paths(&code(file), here) {
            let Some(to) = module_of(&path, mods) else { continue };
            if to.len() < depth || to[..depth - 1] != from[..depth - 1] {
                continue;
            }
            let to = to[..depth].to_vec();
            if to != from {
                out.entry(from.clone()).or_default().insert(to);
            }
        }
    }
    out
}

/// A cycle of the graph, if it has one.
fn cycle(g: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>) -> Option<Vec<Vec<String>>> {
    fn visit(
        v: &Vec<String>,
        g: &BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
        state: &mut BTreeMap<Vec<String>, u8>,
        stack: &mut Vec<Vec<String>>,
    ) -> Option<Vec<Vec<String>>> {
        state.insert(v.clone(), 1);
        stack.push(v.clone());
        for w in g.get(v).into_iter().flatten() {
            match state.get(w) {
                Some(1) => {
                    let at = stack.iter().position(|x| x == w).expect("on the stack");
                    return Some(stack[at..].to_vec());
                }
                Some(_) => {}
                None => {
                    if let Some(c) = visit(w, g, state, stack) {
                        return Some(c);
                    }
                }
            }
        }
        stack.pop();
        state.insert(v.clone(), 2);
        None
    }
    let mut state = BTreeMap::new();
    for v in g.keys() {
        if !state.contains_key(v)
            && let Some(c) = visit(v, g, &mut state, &mut Vec::new())
        {
            return Some(c);
        }
    }
    None
}

fn crate_sources() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut out = vec![root.join("src")];
    for entry in std::fs::read_dir(root.join("crates")).expect("crates/") {
        out.push(entry.expect("a crate").path().join("src"));
    }
    out
}

#[test]
fn no_module_imports_its_way_round_in_a_circle() {
    let mut found = Vec::new();
    for src in crate_sources() {
        let mods = modules(&src);
        for depth in 1..=3 {
            if let Some(c) = cycle(&edges(&mods, depth)) {
                let names: Vec<String> = c.iter().map(|m| m.join("::")).collect();
                found.push(format!("{}: {}", src.display(), names.join(" -> ")));
            }
        }
    }
    assert!(found.is_empty(), "import circles:\n{}", found.join("\n"));
}

#[test]
fn a_circle_is_found_where_there_is_one() {
    let m = |s: &str| s.split("::").map(String::from).collect::<Vec<_>>();
    let mut mods = BTreeMap::new();
    for name in ["a", "b", "c"] {
        mods.insert(m(name), PathBuf::from(name));
    }
    assert_eq!(named_paths("use crate::b::X; use super::c;", &m("a")), vec![m("b::X"), m("c")]);
    assert_eq!(named_paths("my_crate::b; x_super::c", &m("a")), Vec::<Vec<String>>::new());
    assert_eq!(module_of(&m("b::X"), &mods), Some(&m("b")));
    let mut g = BTreeMap::new();
    g.insert(m("a"), BTreeSet::from([m("b")]));
    g.insert(m("b"), BTreeSet::from([m("c")]));
    assert_eq!(cycle(&g), None);
    g.insert(m("c"), BTreeSet::from([m("a")]));
    assert_eq!(cycle(&g), Some(vec![m("a"), m("b"), m("c")]));
}
