//! Checks the architecture invariants of ARCHITECTURE.md that the sources can show: which crate
//! may depend on which, no source files importing each other round a loop, no file over the
//! size limit, the binary's crate under its own, the kernels crate's internals named only inside
//! it, no `anyhow` in a library crate.

use std::path::{Path, PathBuf};

use dgstereo_suite::import_graph::ImportGraph;

const STAGES: [&str; 6] = ["prior", "fusion", "encoder", "costvolume", "updater", "loss"];

/// The most lines a source file may have.
const MAX_LINES: usize = 500;

/// The binary's crate (`crates/cli/src`) has fewer lines than this: it parses flags, calls the
/// libraries and prints.
const BINARY_LINES_UNDER: usize = 2_500;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn manifest(krate: &str) -> toml::Table {
    let path = root().join("crates").join(krate).join("Cargo.toml");
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    text.parse().unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The names of a crate's dependencies in `sections` of its manifest.
fn dependency_names(krate: &str, sections: &[&str]) -> Vec<String> {
    let manifest = manifest(krate);
    let mut deps = Vec::new();
    for section in sections {
        if let Some(table) = manifest.get(*section).and_then(|t| t.as_table()) {
            deps.extend(table.keys().cloned());
        }
    }
    deps
}

fn dependencies(krate: &str) -> Vec<String> {
    dependency_names(krate, &["dependencies", "dev-dependencies", "build-dependencies"])
        .into_iter()
        .filter(|k| k.starts_with("dgstereo-"))
        .collect()
}

/// Every crate folder under `crates/`.
fn crate_names() -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(root().join("crates"))
        .expect("crates/")
        .map(|e| e.expect("crates/ entry").file_name().to_string_lossy().into_owned())
        .filter(|n| root().join("crates").join(n).join("Cargo.toml").is_file())
        .collect();
    names.sort();
    names
}

/// Every `.rs` file below `dir`, `target` and hidden folders left out.
fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = entry.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
        if path.is_dir() && name != "target" && !name.starts_with('.') {
            rust_files(&path, out);
        } else if name.ends_with(".rs") {
            out.push(path);
        }
    }
}

fn relative(path: &Path) -> String {
    path.strip_prefix(root()).unwrap_or(path).display().to_string()
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

/// **Architecture Invariant:** stage crates depend on `core`, `kernels` and `formats` only, never
/// on each other.
#[test]
fn stage_crates_depend_on_core_kernels_and_formats_only() {
    let allowed = ["dgstereo-core", "dgstereo-kernels", "dgstereo-formats"];
    for stage in STAGES {
        let deps = dependencies(stage);
        let others: Vec<_> = deps.iter().filter(|d| !allowed.contains(&d.as_str())).collect();
        assert!(others.is_empty(), "stage crate '{stage}' depends on {others:?}");
    }
}

/// **Architecture Invariant:** `kernels` and `formats` depend on `core` only, and `core` on
/// nothing of ours.
#[test]
fn kernels_and_formats_depend_on_core_only_and_core_on_nothing() {
    for low in ["kernels", "formats"] {
        let deps = dependencies(low);
        assert!(deps.iter().all(|d| d == "dgstereo-core"), "{low} depends on {deps:?}");
    }
    assert!(dependencies("core").is_empty(), "core depends on {:?}", dependencies("core"));
}

/// **Architecture Invariant:** `.npy` and PFM bytes are read and written in `crates/formats`
/// only: no other source file holds the NumPy magic or matches on a PFM magic.
#[test]
fn array_files_are_read_in_the_formats_crate_only() {
    let mut found = Vec::new();
    for src in source_roots() {
        if src.starts_with(root().join("crates/formats")) {
            continue;
        }
        let mut files = Vec::new();
        rust_files(&src, &mut files);
        for file in files {
            let code = std::fs::read_to_string(&file).expect("source file");
            if code.contains(r"\x93NUMPY") || code.contains(r#""Pf" =>"#) || code.contains(r#""PF" =>"#) {
                found.push(relative(&file));
            }
        }
    }
    assert!(found.is_empty(), "NPY/PFM codecs outside crates/formats: {found:?}");
}

/// The crates of ours that `krate` builds with: its normal dependencies, theirs, and so on (a
/// dev-dependency is left out: it builds only the crate's tests).
fn transitive_dependencies(krate: &str) -> Vec<String> {
    let mut found: Vec<String> = Vec::new();
    let mut pending = vec![krate.to_string()];
    while let Some(next) = pending.pop() {
        for dep in dependency_names(&next, &["dependencies"]) {
            let Some(name) = dep.strip_prefix("dgstereo-") else { continue };
            if !found.iter().any(|f| f == name) {
                found.push(name.to_string());
                pending.push(name.to_string());
            }
        }
    }
    found.sort();
    found
}

/// **Architecture Invariant:** the schema sits below what executes it: the experiment crate
/// (the `[train]` and `[data]` tables included) and the inference crate, and with it the Python
/// package, never build the trainer; the launcher meets the trainer through the small
/// `collective` crate alone.
#[test]
fn the_schema_and_inference_do_not_depend_on_the_trainer() {
    for krate in ["experiment", "inference", "distributed", "collective"] {
        let deps = transitive_dependencies(krate);
        assert!(!deps.iter().any(|d| d == "train"), "'{krate}' builds the trainer through {deps:?}");
    }
    let bindings = root().join("bindings/python/Cargo.toml");
    let bindings: toml::Table = std::fs::read_to_string(&bindings).expect("bindings manifest").parse().expect("TOML");
    let wheel = bindings["dependencies"].as_table().expect("[dependencies]");
    for dep in wheel.keys().filter_map(|d| d.strip_prefix("dgstereo-")) {
        let mut deps = transitive_dependencies(dep);
        deps.push(dep.to_string());
        assert!(!deps.iter().any(|d| d == "train"), "the Python package builds the trainer through '{dep}'");
    }
    // Not even for its tests: a dev-dependency on the trainer would be a cycle.
    assert!(!dependencies("experiment").iter().any(|d| d == "dgstereo-train"), "experiment depends on train");
    let collective = transitive_dependencies("collective");
    assert_eq!(collective, ["core"], "collective depends on {collective:?}");
    assert!(transitive_dependencies("train").iter().any(|d| d == "experiment"), "the trainer reads the schema");
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
    let mut files = Vec::new();
    for dir in ["crates", "src", "tests", "benches", "bindings"] {
        rust_files(&root().join(dir), &mut files);
    }
    let long: Vec<String> = files
        .iter()
        .filter_map(|path| {
            let lines = std::fs::read_to_string(path).map(|t| t.lines().count()).unwrap_or(0);
            (lines > MAX_LINES).then(|| format!("{} ({lines} lines)", relative(path)))
        })
        .collect();
    assert!(long.is_empty(), "files over {MAX_LINES} lines:\n{}", long.join("\n"));
}

/// **Architecture Invariant:** the binary parses flags, calls the libraries and prints: its crate
/// stays under [`BINARY_LINES_UNDER`] lines, and what is not flag parsing or printing is a
/// library's, where the Python package and tests reach it too.
#[test]
fn the_binary_crate_is_under_its_limit() {
    let mut files = Vec::new();
    rust_files(&root().join("crates/cli/src"), &mut files);
    assert!(files.len() > 5, "the binary's sources are not where this test looks");
    let lines: usize =
        files.iter().map(|path| std::fs::read_to_string(path).map(|t| t.lines().count()).unwrap_or(0)).sum();
    assert!(
        lines < BINARY_LINES_UNDER,
        "crates/cli/src has {lines} lines, the limit is under {BINARY_LINES_UNDER}: move what is not flag parsing \
         or printing into the library crate it belongs to"
    );
}

/// **Architecture Invariant:** the process's stop signals are a crate on `core` alone, so the
/// trainer takes a stop flag and knows no signals.
#[test]
fn the_stop_signals_depend_on_core_alone() {
    assert_eq!(transitive_dependencies("signals"), ["core"]);
    assert!(!transitive_dependencies("train").iter().any(|d| d == "signals"), "the trainer knows the signals");
}

/// The kernels crate's internal modules, which only the kernels crate itself may name.
const KERNEL_INTERNALS: [&str; 3] = ["gpu", "host", "autodiff"];

/// The internal modules of the kernels crate that `code` names through `dgstereo_kernels::`,
/// in a path or a `use` tree (`dgstereo_kernels::{gpu::x, ...}`). Comment lines are skipped.
fn kernel_internals_named(code: &str) -> Vec<&'static str> {
    let code: String = code.lines().filter(|l| !l.trim_start().starts_with("//")).collect::<Vec<_>>().join("\n");
    let mut named = Vec::new();
    for (at, _) in code.match_indices("dgstereo_kernels::") {
        let rest = &code[at + "dgstereo_kernels::".len()..];
        // A path ends at the first character that cannot continue it; a use tree at its `;`.
        let end = if rest.starts_with('{') {
            rest.find(';').unwrap_or(rest.len())
        } else {
            rest.find(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':')).unwrap_or(rest.len())
        };
        let tree = &rest[..end];
        for internal in KERNEL_INTERNALS {
            let prefix = format!("{internal}::");
            let starts_segment = |i: usize| i == 0 || !tree[..i].ends_with(|c: char| c.is_alphanumeric() || c == '_');
            if tree.match_indices(&prefix).any(|(i, _)| starts_segment(i) && !tree[..i].ends_with("::")) {
                named.push(internal);
            }
        }
    }
    named.sort();
    named.dedup();
    named
}

/// **Architecture Invariant:** the kernels crate's `gpu`, `host` and `autodiff` modules are its
/// own: no code outside `crates/kernels` names them, so stages reach the kernels through the
/// face alone.
#[test]
fn kernel_internals_are_named_only_inside_kernels() {
    let mut files = Vec::new();
    for dir in ["crates", "src", "tests", "benches", "bindings"] {
        rust_files(&root().join(dir), &mut files);
    }
    let kernels = root().join("crates").join("kernels");
    let offenders: Vec<String> = files
        .iter()
        // This file names the internals in the check's own tests.
        .filter(|path| !path.starts_with(&kernels) && !path.ends_with("tests/architecture.rs"))
        .filter_map(|path| {
            let text = std::fs::read_to_string(path).unwrap_or_default();
            let named = kernel_internals_named(&text);
            (!named.is_empty()).then(|| format!("{} names dgstereo_kernels::{named:?}", relative(path)))
        })
        .collect();
    assert!(offenders.is_empty(), "kernel internals named outside crates/kernels:\n{}", offenders.join("\n"));
}

#[test]
fn the_kernel_internals_check_sees_paths_and_use_trees() {
    assert_eq!(kernel_internals_named("use dgstereo_kernels::gpu::matmul_conv::X;"), ["gpu"]);
    assert_eq!(kernel_internals_named("use dgstereo_kernels::{conv2d_forward, host::conv};"), ["host"]);
    assert_eq!(kernel_internals_named("let y = dgstereo_kernels::autodiff::f(x);"), ["autodiff"]);
    assert!(kernel_internals_named("use dgstereo_kernels::{conv2d_forward, resize_bilinear};").is_empty());
    assert!(kernel_internals_named("use dgstereo_kernels::ops::lookup::all_pairs;").is_empty());
    assert!(kernel_internals_named("// see dgstereo_kernels::host::conv").is_empty());
}

/// The crates that may use `anyhow`: the binary and the Python bindings (outside `crates/`).
const ANYHOW_ALLOWED: [&str; 1] = ["cli"];

/// **Architecture Invariant:** library crates return `dgstereo_core::Error`; `anyhow` is for the
/// binary (and the Python bindings) alone.
#[test]
fn no_library_crate_depends_on_anyhow() {
    let offenders: Vec<String> = crate_names()
        .into_iter()
        .filter(|c| !ANYHOW_ALLOWED.contains(&c.as_str()))
        .filter(|c| dependency_names(c, &["dependencies"]).iter().any(|d| d == "anyhow"))
        .collect();
    assert!(offenders.is_empty(), "library crates depending on anyhow: {offenders:?}");
}

/// **Architecture Invariant:** errors that callers branch on are types: the library's `Error` has
/// no catch-all variant carrying only text, so no code decides anything by an error's wording.
#[test]
fn no_error_is_only_text() {
    let mut files = Vec::new();
    for dir in ["crates", "src", "tests", "benches", "bindings"] {
        rust_files(&root().join(dir), &mut files);
    }
    let catch_all = ["Error::", "Other("].concat();
    let offenders: Vec<String> = files
        .iter()
        .filter(|path| std::fs::read_to_string(path).unwrap_or_default().contains(&catch_all))
        .map(|path| relative(path))
        .collect();
    assert!(offenders.is_empty(), "files naming {catch_all}: {offenders:?}");
    let error = std::fs::read_to_string(root().join("crates/core/src/error.rs")).expect("core's error.rs");
    assert!(!error.contains("    Other("), "core's Error has a catch-all `Other` variant");
}

/// **Architecture Invariant:** the binary's command modules do not import each other: what two
/// commands share is a module of the binary beside them (`training.rs`, `measurement.rs`) or a
/// library (the study crate).
#[test]
fn command_modules_do_not_import_each_other() {
    let mut files = Vec::new();
    rust_files(&root().join("crates/cli/src/commands"), &mut files);
    assert!(files.len() > 5, "the command modules are not where this test looks");
    let offenders: Vec<String> = files
        .iter()
        .flat_map(|path| {
            let text = std::fs::read_to_string(path).unwrap_or_default();
            let lines: Vec<String> = text
                .lines()
                .filter(|l| !l.trim_start().starts_with("//"))
                // A module's own tests see their module through `use super::*`.
                .filter(|l| (l.contains("super::") && l.trim() != "use super::*;") || l.contains("crate::commands::"))
                .map(|l| format!("{}: {}", relative(path), l.trim()))
                .collect();
            lines
        })
        .collect();
    assert!(offenders.is_empty(), "command modules importing each other:\n{}", offenders.join("\n"));
}
