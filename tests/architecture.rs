//! Checks the architecture invariants of ARCHITECTURE.md that the sources can show: which crate
//! may depend on which, no source files importing each other round a loop, no file over the
//! size limit.

use std::path::{Path, PathBuf};

use dgstereo_suite::import_graph::ImportGraph;

const STAGES: [&str; 6] = ["prior", "fusion", "encoder", "costvolume", "updater", "loss"];

/// The most lines a source file may have.
const MAX_LINES: usize = 600;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn dependencies(krate: &str) -> Vec<String> {
    let path = root().join("crates").join(krate).join("Cargo.toml");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let manifest: toml::Table = text.parse().unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut deps = Vec::new();
    for section in ["dependencies", "dev-dependencies", "build-dependencies"] {
        if let Some(table) = manifest.get(section).and_then(|t| t.as_table()) {
            deps.extend(table.keys().filter(|k| k.starts_with("dgstereo-")).cloned());
        }
    }
    deps
}

/// Every crate folder of the workspace, and the root package's `src`.
fn source_roots() -> Vec<PathBuf> {
    let mut roots: Vec<PathBuf> = std::fs::read_dir(root().join("crates"))
        .expect("crates/")
        .map(|e| e.expect("crates/ entry").path().join("src"))
        .filter(|p| p.is_dir())
        .collect();
    roots.push(root().join("src"));
    roots.sort();
    roots
}

/// **Architecture Invariant:** stage crates depend on `core` and `kernels` only, never on each
/// other.
#[test]
fn stage_crates_depend_on_core_and_kernels_only() {
    for stage in STAGES {
        let deps = dependencies(stage);
        let others: Vec<_> = deps.iter().filter(|d| *d != "dgstereo-core" && *d != "dgstereo-kernels").collect();
        assert!(others.is_empty(), "stage crate '{stage}' depends on {others:?}");
    }
}

/// **Architecture Invariant:** `kernels` depends on `core` only, and `core` on nothing of ours.
#[test]
fn kernels_depend_on_core_only_and_core_on_nothing() {
    let kernels = dependencies("kernels");
    assert!(kernels.iter().all(|d| d == "dgstereo-core"), "kernels depends on {kernels:?}");
    assert!(dependencies("core").is_empty(), "core depends on {:?}", dependencies("core"));
}

/// **Architecture Invariant:** no two source files import each other, directly or round a loop.
#[test]
fn no_source_files_import_each_other() {
    let mut loops = Vec::new();
    for src in source_roots() {
        let graph = ImportGraph::of_crate(&src).unwrap_or_else(|e| panic!("{}: {e}", src.display()));
        for cycle in graph.cycles() {
            let names: Vec<String> =
                cycle.iter().map(|p| p.strip_prefix(root()).unwrap_or(p).display().to_string()).collect();
            loops.push(names.join(" <-> "));
        }
    }
    assert!(loops.is_empty(), "files that import each other:\n{}", loops.join("\n"));
}

/// **Architecture Invariant:** no source file is over [`MAX_LINES`] lines.
#[test]
fn no_source_file_is_over_the_limit() {
    fn walk(dir: &Path, out: &mut Vec<String>) {
        for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
            let path = entry.path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if path.is_dir() && name != "target" && !name.starts_with('.') {
                walk(&path, out);
            } else if name.ends_with(".rs") {
                let lines = std::fs::read_to_string(&path).map(|t| t.lines().count()).unwrap_or(0);
                if lines > MAX_LINES {
                    out.push(format!("{} ({lines} lines)", path.strip_prefix(root()).unwrap_or(&path).display()));
                }
            }
        }
    }
    let mut long = Vec::new();
    for dir in ["crates", "src", "tests", "benches"] {
        walk(&root().join(dir), &mut long);
    }
    assert!(long.is_empty(), "files over {MAX_LINES} lines:\n{}", long.join("\n"));
}
