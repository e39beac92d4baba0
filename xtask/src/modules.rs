//! No circle of modules in any crate: each crate's top-level modules (`src/<m>.rs` or
//! `src/<m>/…`) import one another (`crate::m`, `super::m` from a top-level module) without a
//! cycle, so each can be read knowing only those below it (ARCHITECTURE.md, "Invariants").
//!
//! Read as text, not parsed: a module's unit tests (from its first `#[cfg(test)]` line on) and
//! comment lines are left out; names re-exported at the crate root (`crate::Thing`) are not
//! followed to the module that defines them. `cargo test -p xtask` (part of `cargo xtask test`)
//! fails on a cycle.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// `module → the modules it imports`, for the crate whose `src/` is `src`.
pub type ModuleGraph = BTreeMap<String, BTreeSet<String>>;

/// The import graph between the top-level modules of the crate at `src` (its `src/` folder).
pub fn module_graph(src: &Path) -> std::io::Result<ModuleGraph> {
    let mut files = Vec::new();
    collect_rs(src, &mut files)?;
    let modules: BTreeSet<String> = files.iter().filter_map(|f| top_module(src, f)).collect();
    let mut graph = ModuleGraph::new();
    for file in &files {
        let Some(module) = top_module(src, file) else { continue };
        let nested = file.parent() != Some(src);
        let text = std::fs::read_to_string(file)?;
        let edges = graph.entry(module.clone()).or_default();
        for name in imported_modules(&text, nested) {
            if name != module && modules.contains(&name) {
                edges.insert(name);
            }
        }
    }
    Ok(graph)
}

/// Every `.rs` file below `dir`.
fn collect_rs(dir: &Path, out: &mut Vec<std::path::PathBuf>) -> std::io::Result<()> {
    for entry in std::fs::read_dir(dir)? {
        let path = entry?.path();
        if path.is_dir() {
            collect_rs(&path, out)?;
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
    Ok(())
}

/// The top-level module a file belongs to (`None` for the crate root, `lib.rs` / `main.rs`,
/// and `src/bin/`).
fn top_module(src: &Path, file: &Path) -> Option<String> {
    let relative = file.strip_prefix(src).ok()?;
    let first = relative.components().next()?.as_os_str().to_str()?;
    let name = first.strip_suffix(".rs").unwrap_or(first);
    (!matches!(name, "lib" | "main" | "bin")).then(|| name.to_owned())
}

/// The top-level modules `text` names: `crate::m…`, `crate::{m…, n…}`, and — in a top-level
/// module's own file (`nested` false) — `super::m…`. Unit tests and comment lines are skipped.
fn imported_modules(text: &str, nested: bool) -> BTreeSet<String> {
    let mut out = BTreeSet::new();
    for line in text.lines() {
        let code = line.trim_start();
        if code.starts_with("#[cfg(test)]") {
            break;
        }
        if code.starts_with("//") {
            continue;
        }
        let mut prefixes = vec!["crate::"];
        if !nested {
            prefixes.push("super::");
        }
        for prefix in prefixes {
            let mut rest = code;
            while let Some(at) = rest.find(prefix) {
                // Not the tail of another path (`my_crate::`, `egoexo_crate::`).
                let before = rest[..at].chars().next_back();
                rest = &rest[at + prefix.len()..];
                if before.is_some_and(|c| c.is_alphanumeric() || c == '_') {
                    continue;
                }
                if let Some(group) = rest.strip_prefix('{') {
                    // `crate::{a::X, b, c::{…}}`: the first name of each item at depth one.
                    let mut depth = 1;
                    let mut item_start = true;
                    let mut name = String::new();
                    for c in group.chars() {
                        match c {
                            '{' => depth += 1,
                            '}' => depth -= 1,
                            _ => {}
                        }
                        if depth == 0 {
                            break;
                        }
                        if depth == 1 && item_start && (c.is_alphanumeric() || c == '_') {
                            name.push(c);
                            continue;
                        }
                        if !name.is_empty() {
                            out.insert(std::mem::take(&mut name));
                        }
                        item_start = depth == 1 && (c == ',' || (item_start && c.is_whitespace()));
                    }
                    if !name.is_empty() {
                        out.insert(name);
                    }
                } else {
                    let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                    if !name.is_empty() {
                        out.insert(name);
                    }
                }
            }
        }
    }
    out
}

/// The cycles of `graph`: its strongly connected components of more than one module, each
/// sorted (Tarjan's algorithm).
pub fn cycles(graph: &ModuleGraph) -> Vec<Vec<String>> {
    struct Tarjan<'g> {
        graph: &'g ModuleGraph,
        index: BTreeMap<&'g str, usize>,
        low: BTreeMap<&'g str, usize>,
        stack: Vec<&'g str>,
        on_stack: BTreeSet<&'g str>,
        out: Vec<Vec<String>>,
    }
    impl<'g> Tarjan<'g> {
        fn visit(&mut self, v: &'g str) {
            let i = self.index.len();
            self.index.insert(v, i);
            self.low.insert(v, i);
            self.stack.push(v);
            self.on_stack.insert(v);
            for w in self.graph.get(v).into_iter().flatten() {
                let w = w.as_str();
                if !self.index.contains_key(w) {
                    self.visit(w);
                    let low = self.low[v].min(self.low[w]);
                    self.low.insert(v, low);
                } else if self.on_stack.contains(w) {
                    let low = self.low[v].min(self.index[w]);
                    self.low.insert(v, low);
                }
            }
            if self.low[v] == self.index[v] {
                let mut component = Vec::new();
                while let Some(w) = self.stack.pop() {
                    self.on_stack.remove(w);
                    component.push(w.to_owned());
                    if w == v {
                        break;
                    }
                }
                if component.len() > 1 {
                    component.sort();
                    self.out.push(component);
                }
            }
        }
    }
    let mut t = Tarjan {
        graph,
        index: BTreeMap::new(),
        low: BTreeMap::new(),
        stack: Vec::new(),
        on_stack: BTreeSet::new(),
        out: Vec::new(),
    };
    for v in graph.keys() {
        if !t.index.contains_key(v.as_str()) {
            t.visit(v);
        }
    }
    t.out.sort();
    t.out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn no_crate_has_a_circle_of_modules() {
        let root = crate::workspace_root();
        let mut found = Vec::new();
        let mut crates = 0;
        let mut dirs: Vec<_> = std::fs::read_dir(root.join("crates")).unwrap().map(|e| e.unwrap().path()).collect();
        dirs.push(root.join("xtask"));
        for dir in dirs {
            let src = dir.join("src");
            if !src.is_dir() {
                continue;
            }
            crates += 1;
            let graph = module_graph(&src).unwrap();
            for cycle in cycles(&graph) {
                // Each module with what it imports from the others in the cycle.
                let edges: Vec<String> = cycle
                    .iter()
                    .map(|m| {
                        let to: Vec<&str> = graph[m].iter().filter(|n| cycle.contains(n)).map(String::as_str).collect();
                        format!("{m} → {}", to.join(", "))
                    })
                    .collect();
                found.push(format!("{}: {}", dir.file_name().unwrap().to_string_lossy(), edges.join("; ")));
            }
        }
        assert!(crates > 15, "{crates} crates read");
        assert!(found.is_empty(), "circles of modules:\n{}", found.join("\n"));
    }

    #[test]
    fn a_circle_is_found_and_a_layering_is_not() {
        let dir = std::env::temp_dir().join(format!("egoexo-modules-{}", std::process::id()));
        let src = dir.join("src");
        std::fs::create_dir_all(src.join("engine")).unwrap();
        let write = |path: &str, text: &str| std::fs::write(src.join(path), text).unwrap();
        write("lib.rs", "pub mod engine;\npub mod job;\npub mod types;\npub use engine::Engine;\n");
        write("types.rs", "pub struct Options;\n");
        write("engine.rs", "use crate::types::Options;\nmod run;\n");
        write("engine/run.rs", "use super::Thing; // the parent, not a sibling\nuse crate::{job::Job, types};\n");
        write(
            "job.rs",
            "// use crate::engine::Engine; (a comment)\nuse crate::types::Options;\n#[cfg(test)]\nmod tests { use crate::engine::Engine; }\n",
        );
        let graph = module_graph(&src).unwrap();
        assert_eq!(graph["engine"], BTreeSet::from(["job".to_owned(), "types".to_owned()]));
        assert_eq!(graph["job"], BTreeSet::from(["types".to_owned()]));
        assert!(cycles(&graph).is_empty());
        // The job reaches back into the engine: a circle.
        write("job.rs", "use super::engine::Engine;\n");
        assert_eq!(cycles(&module_graph(&src).unwrap()), [vec!["engine".to_owned(), "job".to_owned()]]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
