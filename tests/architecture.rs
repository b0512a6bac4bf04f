//! Checks the architecture invariants of ARCHITECTURE.md that the build can see.

use std::path::Path;

const STAGES: [&str; 6] = ["prior", "fusion", "encoder", "costvolume", "updater", "loss"];

fn dependencies(krate: &str) -> Vec<String> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("crates").join(krate).join("Cargo.toml");
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

/// **Architecture Invariant:** stage crates never depend on each other, only on `core`.
#[test]
fn stage_crates_depend_on_core_only() {
    for stage in STAGES {
        let deps = dependencies(stage);
        let others: Vec<_> = deps.iter().filter(|d| *d != "dgstereo-core").collect();
        assert!(others.is_empty(), "stage crate '{stage}' depends on {others:?}");
    }
}

/// `core` is the root of the graph: it depends on no other crate of the workspace.
#[test]
fn core_depends_on_nothing_of_ours() {
    assert!(dependencies("core").is_empty(), "core depends on {:?}", dependencies("core"));
}
