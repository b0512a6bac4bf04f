//! The graph of which source file imports which, within each crate of the workspace.
//!
//! Design decision: the rule "no two files import each other, directly or round a loop" is
//! checked on the source text, without a compiler: each file is a module (`lib.rs` the root,
//! `a.rs` or `a/mod.rs` the module `a`, `a/b.rs` its child `b`), and every path it names that
//! starts at `crate::`, `super::`, `self::` or one of its own child modules is resolved to the
//! deepest module file of that path; a name the target re-exports with `pub use` is followed to
//! the file that defines it. Declaring a child (`mod b;`) and re-exporting a descendant's items
//! (`pub use b::Item;`, a module's public face) are not imports; naming them in code is.
//! Paths inside an inline module (`mod tests { ... }`) resolve from that module, so a test
//! module's `use super::*` is the file itself. Comments and string literals are skipped.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};

mod source_text;

use source_text::{is_ident, strip_comments_and_strings, tokenize};

/// One crate's files and the imports between them.
#[derive(Debug, Default)]
pub struct ImportGraph {
    /// Module path (`["host", "winograd"]`) of each file.
    pub modules: BTreeMap<Vec<String>, PathBuf>,
    /// Edges from a file's module to the modules it imports.
    pub edges: BTreeMap<Vec<String>, BTreeSet<Vec<String>>>,
}

impl ImportGraph {
    /// The graph of the crate whose `src` folder is `src` (entry `lib.rs` or `main.rs`).
    pub fn of_crate(src: &Path) -> std::io::Result<Self> {
        let mut files = Vec::new();
        collect_rs(src, &mut files)?;
        let mut graph = Self::default();
        let mut texts = BTreeMap::new();
        for file in files {
            let module = module_path(src, &file);
            let text = strip_comments_and_strings(&std::fs::read_to_string(&file)?);
            graph.modules.insert(module.clone(), file);
            texts.insert(module, text);
        }
        let reexports: BTreeMap<Vec<String>, BTreeMap<String, Vec<String>>> =
            texts.iter().map(|(m, t)| (m.clone(), reexports_of(m, t, &graph.modules))).collect();
        for (module, text) in &texts {
            let mut targets = BTreeSet::new();
            for (scope, path, reexport) in named_paths(text) {
                // A module's `pub use` of its own descendants declares its public face, as
                // `mod` declares a child: not an import.
                if reexport && path.first().is_some_and(|p| p != "super" && p != "crate") {
                    continue;
                }
                let here: Vec<String> = module.iter().cloned().chain(scope).collect();
                if let Some(absolute) = absolute(&here, &path, &graph.modules) {
                    let target = resolve(&absolute, &graph.modules, &reexports, 0);
                    if &target != module {
                        targets.insert(target);
                    }
                }
            }
            graph.edges.insert(module.clone(), targets);
        }
        Ok(graph)
    }

    /// The loops: each a list of files that import each other round a cycle (strongly
    /// connected components of more than one file).
    pub fn cycles(&self) -> Vec<Vec<PathBuf>> {
        let nodes: Vec<&Vec<String>> = self.modules.keys().collect();
        let index: BTreeMap<&Vec<String>, usize> = nodes.iter().enumerate().map(|(i, m)| (*m, i)).collect();
        let adjacency: Vec<Vec<usize>> = nodes
            .iter()
            .map(|m| self.edges.get(*m).into_iter().flatten().filter_map(|t| index.get(t).copied()).collect())
            .collect();
        strongly_connected(&adjacency)
            .into_iter()
            .filter(|c| c.len() > 1)
            .map(|c| c.into_iter().map(|i| self.modules[nodes[i]].clone()).collect())
            .collect()
    }
}

fn collect_rs(dir: &Path, out: &mut Vec<PathBuf>) -> std::io::Result<()> {
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

/// `src/a/b.rs` -> `[a, b]`; `src/a/mod.rs` -> `[a]`; `src/lib.rs` -> `[]`.
fn module_path(src: &Path, file: &Path) -> Vec<String> {
    let relative = file.strip_prefix(src).unwrap_or(file);
    let mut parts: Vec<String> = relative.iter().map(|p| p.to_string_lossy().into_owned()).collect();
    let last = parts.pop().unwrap_or_default();
    let stem = last.trim_end_matches(".rs");
    if !(stem == "mod" || (parts.is_empty() && (stem == "lib" || stem == "main"))) {
        parts.push(stem.to_string());
    }
    parts
}

/// Every path the text names that may be a module path, with the inline modules it is inside.
/// `use` trees are expanded (`use a::{b, c::d}` -> `a::b`, `a::c::d`).
fn named_paths(text: &str) -> Vec<(Vec<String>, Vec<String>, bool)> {
    let tokens = tokenize(text);
    let mut out = Vec::new();
    let mut scopes: Vec<(String, usize)> = Vec::new();
    let mut depth = 0usize;
    let mut i = 0;
    while i < tokens.len() {
        let t = tokens[i].as_str();
        match t {
            "{" => depth += 1,
            "}" => {
                depth = depth.saturating_sub(1);
                if scopes.last().is_some_and(|(_, d)| *d == depth) {
                    scopes.pop();
                }
            }
            "mod" if tokens.get(i + 2).is_some_and(|t| t == "{") => {
                scopes.push((tokens[i + 1].clone(), depth));
                depth += 1;
                i += 3;
                continue;
            }
            "use" => {
                let end = (i..tokens.len()).find(|&j| tokens[j] == ";").unwrap_or(tokens.len());
                let scope: Vec<String> = scopes.iter().map(|(n, _)| n.clone()).collect();
                let reexport = is_public_use(&tokens, i);
                for path in expand_use_tree(&tokens[i + 1..end]) {
                    out.push((scope.clone(), path, reexport));
                }
                i = end;
                continue;
            }
            _ if is_ident(t) && tokens.get(i + 1).is_some_and(|n| n == "::") && !preceded_by_path(&tokens, i) => {
                let mut path = vec![t.to_string()];
                let mut j = i + 1;
                while tokens.get(j).is_some_and(|n| n == "::") && tokens.get(j + 1).is_some_and(|n| is_ident(n)) {
                    path.push(tokens[j + 1].clone());
                    j += 2;
                }
                let scope: Vec<String> = scopes.iter().map(|(n, _)| n.clone()).collect();
                out.push((scope, path, false));
                i = j;
                continue;
            }
            _ => {}
        }
        i += 1;
    }
    out
}

/// Whether the `use` at `tokens[i]` is public (`pub use`, `pub(crate) use`, ...).
fn is_public_use(tokens: &[String], i: usize) -> bool {
    i >= 1 && (tokens[i - 1] == "pub" || (tokens[i - 1] == ")" && (2..=4).any(|k| i > k && tokens[i - 1 - k] == "pub")))
}

fn preceded_by_path(tokens: &[String], i: usize) -> bool {
    i > 0 && (tokens[i - 1] == "::" || tokens[i - 1] == "$")
}

/// The paths of a `use` tree's tokens (without `use` and `;`).
fn expand_use_tree(tokens: &[String]) -> Vec<Vec<String>> {
    fn walk(tokens: &[String], prefix: &[String], out: &mut Vec<Vec<String>>) {
        let mut path = prefix.to_vec();
        let mut i = 0;
        while i < tokens.len() {
            let t = tokens[i].as_str();
            match t {
                "::" => {}
                "{" => {
                    let mut depth = 0;
                    let mut start = i + 1;
                    for j in i..tokens.len() {
                        match tokens[j].as_str() {
                            "{" => depth += 1,
                            "}" => {
                                depth -= 1;
                                if depth == 0 {
                                    walk(&tokens[start..j], &path, out);
                                    return;
                                }
                            }
                            "," if depth == 1 => {
                                walk(&tokens[start..j], &path, out);
                                start = j + 1;
                            }
                            _ => {}
                        }
                    }
                    return;
                }
                "as" | "*" | "pub" | "(" | ")" => break,
                _ if is_ident(t) => path.push(t.to_string()),
                _ => break,
            }
            i += 1;
        }
        if path.len() > prefix.len() || !path.is_empty() {
            out.push(path);
        }
    }
    let mut out = Vec::new();
    walk(tokens, &[], &mut out);
    out
}

/// `path` named in module `here`, as an absolute module path of the crate; `None` for a path
/// outside the crate (another crate, `std`, a type's associated item).
fn absolute(here: &[String], path: &[String], modules: &BTreeMap<Vec<String>, PathBuf>) -> Option<Vec<String>> {
    let first = path.first()?.as_str();
    let mut base: Vec<String> = match first {
        "crate" => Vec::new(),
        "self" => here.to_vec(),
        "super" => here.to_vec(),
        _ => {
            let mut child = here.to_vec();
            child.push(first.to_string());
            return modules.contains_key(&child).then(|| here.iter().chain(path).cloned().collect());
        }
    };
    let mut rest = &path[1..];
    if first == "super" {
        base.pop();
    }
    while rest.first().is_some_and(|s| s == "super") {
        base.pop();
        rest = &rest[1..];
    }
    Some(base.into_iter().chain(rest.iter().cloned()).collect())
}

/// The deepest module file of `path`, following re-exports of the name after it.
fn resolve(
    path: &[String],
    modules: &BTreeMap<Vec<String>, PathBuf>,
    reexports: &BTreeMap<Vec<String>, BTreeMap<String, Vec<String>>>,
    hops: usize,
) -> Vec<String> {
    let mut deepest = 0;
    for k in 0..=path.len() {
        if modules.contains_key(&path[..k].to_vec()) {
            deepest = k;
        }
    }
    let module = path[..deepest].to_vec();
    if hops < 8
        && let Some(name) = path.get(deepest)
        && let Some(target) = reexports.get(&module).and_then(|r| r.get(name))
    {
        let rest: Vec<String> = target.iter().chain(&path[deepest + 1..]).cloned().collect();
        return resolve(&rest, modules, reexports, hops + 1);
    }
    module
}

/// Names a module re-exports with `pub use` (`pub use a::B;` -> `B` -> `[.., a, B]`), as
/// absolute paths.
fn reexports_of(
    module: &[String],
    text: &str,
    modules: &BTreeMap<Vec<String>, PathBuf>,
) -> BTreeMap<String, Vec<String>> {
    let tokens = tokenize(text);
    let mut out = BTreeMap::new();
    for i in 0..tokens.len() {
        if tokens[i] != "use" {
            continue;
        }
        if !is_public_use(&tokens, i) {
            continue;
        }
        let end = (i..tokens.len()).find(|&j| tokens[j] == ";").unwrap_or(tokens.len());
        for path in expand_use_tree(&tokens[i + 1..end]) {
            if let (Some(name), Some(absolute)) = (path.last(), absolute(module, &path, modules)) {
                out.insert(name.clone(), absolute);
            }
        }
    }
    out
}

/// Tarjan's strongly connected components of a graph given as adjacency lists.
fn strongly_connected(adjacency: &[Vec<usize>]) -> Vec<Vec<usize>> {
    struct State<'a> {
        adjacency: &'a [Vec<usize>],
        index: Vec<Option<usize>>,
        low: Vec<usize>,
        on_stack: Vec<bool>,
        stack: Vec<usize>,
        next: usize,
        out: Vec<Vec<usize>>,
    }
    fn visit(s: &mut State, v: usize) {
        s.index[v] = Some(s.next);
        s.low[v] = s.next;
        s.next += 1;
        s.stack.push(v);
        s.on_stack[v] = true;
        for k in 0..s.adjacency[v].len() {
            let w = s.adjacency[v][k];
            match s.index[w] {
                None => {
                    visit(s, w);
                    s.low[v] = s.low[v].min(s.low[w]);
                }
                Some(iw) if s.on_stack[w] => s.low[v] = s.low[v].min(iw),
                Some(_) => {}
            }
        }
        if Some(s.low[v]) == s.index[v] {
            let mut component = Vec::new();
            while let Some(w) = s.stack.pop() {
                s.on_stack[w] = false;
                component.push(w);
                if w == v {
                    break;
                }
            }
            s.out.push(component);
        }
    }
    let n = adjacency.len();
    let mut s = State {
        adjacency,
        index: vec![None; n],
        low: vec![0; n],
        on_stack: vec![false; n],
        stack: Vec::new(),
        next: 0,
        out: Vec::new(),
    };
    for v in 0..n {
        if s.index[v].is_none() {
            visit(&mut s, v);
        }
    }
    s.out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph(files: &[(&str, &str)]) -> ImportGraph {
        let dir = std::env::temp_dir().join(format!("import-graph-{}-{}", std::process::id(), files.len()));
        let _ = std::fs::remove_dir_all(&dir);
        for (name, text) in files {
            let path = dir.join(name);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, text).unwrap();
        }
        let g = ImportGraph::of_crate(&dir).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
        g
    }

    /// A parent that uses its child while the child uses the parent's item is a loop; a
    /// facade parent with siblings importing each other one way is not; test modules' `super`
    /// is their own file; comments do not count.
    #[test]
    fn loops_are_found_and_facades_are_not_loops() {
        let looped = graph(&[
            ("lib.rs", "mod a;"),
            ("a.rs", "mod b;\npub struct Shared;\nfn f() { b::g(); }"),
            ("a/b.rs", "use super::Shared;\npub fn g() {}"),
        ]);
        assert_eq!(looped.cycles().len(), 1, "{:?}", looped.edges);
        let facade = graph(&[
            ("lib.rs", "pub mod a;\npub use a::b::g;"),
            ("a/mod.rs", "pub mod b;\npub mod shared;\npub use b::g;"),
            ("a/b.rs", "use super::shared::Shared;\n// use crate::g;\npub fn g() { let _ = \"crate::g\"; }"),
            (
                "a/shared.rs",
                "pub struct Shared;\n#[cfg(test)]\nmod tests { use super::*; use crate::a::shared::Shared as S; }",
            ),
        ]);
        assert!(facade.cycles().is_empty(), "{:?}", facade.edges);
        // Through a re-export: `crate::g` is b's `g`, so b naming it is no edge to the root.
        let via_root = graph(&[("lib.rs", "mod a;\npub use a::f;"), ("a.rs", "pub fn f() { crate::f(); }")]);
        assert!(via_root.cycles().is_empty(), "{:?}", via_root.edges);
        // A real loop round three files.
        let round = graph(&[
            ("lib.rs", "mod x; mod y; mod z;"),
            ("x.rs", "use crate::y::Y; pub struct X;"),
            ("y.rs", "use crate::z::Z; pub struct Y;"),
            ("z.rs", "fn f() -> crate::x::X { todo!() } pub struct Z;"),
        ]);
        assert_eq!(round.cycles().first().map(Vec::len), Some(3), "{:?}", round.edges);
    }
}
