//! `dgstereo train` and `dgstereo ablate` run as a user runs them: a tiny experiment file trains
//! for a few steps, leaves every promised output, and the ablation runner scores it on the
//! synthetic set and on the bundled Cones pair (a `[[benchmarks]]` entry), reusing a finished run
//! on the second call. Bad experiment files are reported with the file and the key.
//!
//! Compute is kept small: 8-channel trunks, 16-channel GRUs on one level, 32x64 crops, three
//! steps, two update iterations.

mod common;

use std::path::{Path, PathBuf};

use common::{cones_dir, dgstereo, infer_cones, text};
/// A tiny experiment scored on `benchmark_root`, written into `dir`.
fn tiny_experiment(dir: &Path, name: &str, benchmark_root: &Path, extra: &str) -> PathBuf {
    let toml = format!(
        r#"name = "{name}"
[model.encoder]
feature_dim = 16
trunk_dims = [8, 8, 8]
[model.updater]
hidden_dims = [16, 16, 16]
n_gru_layers = 1
[train]
steps = 3
batch_size = 1
crop = [32, 64]
iters = 2
seed = 7
log_every = 1
checkpoint_every = 2
validate_every = 2
[[data.sources]]
kind = "synthetic"
width = 96
height = 48
[data.validation]
count = 1
width = 64
height = 32
iters = 2
[[benchmarks]]
name = "cones"
dataset = "folder"
root = '{}'
iters = 2
max_size = 96
{extra}
"#,
        benchmark_root.display()
    );
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, toml).unwrap();
    path
}

#[test]
fn train_writes_model_log_plot_and_checkpoints() {
    let dir = tempfile::tempdir().unwrap();
    let exp = tiny_experiment(dir.path(), "tiny", &cones_dir(), "");
    let out = dir.path().join("run");
    let o = dgstereo(&["train", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", text(&o));
    for f in ["model.safetensors", "log.jsonl", "curves.png", "config.toml", "summary.json"] {
        assert!(out.join(f).is_file(), "{f} missing after training:\n{}", text(&o));
    }
    let log = std::fs::read_to_string(out.join("log.jsonl")).unwrap();
    let steps: Vec<u64> = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .filter(|v| v["kind"] == "train")
        .map(|v| v["step"].as_u64().unwrap())
        .collect();
    assert_eq!(steps, vec![1, 2, 3], "one log line per step with log_every = 1");
    assert!(log.contains(r#""kind":"validation""#), "validation at step 2 is logged");
    // `experiment validate` scores the final weights on the same set: the log's last validation.
    let last_validation = log
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .rfind(|v| v["kind"] == "validation")
        .unwrap();
    assert_eq!(last_validation["step"], 3);
    let weights = out.join("model.safetensors");
    let o = dgstereo(&["experiment", "validate", exp.to_str().unwrap(), "--weights", weights.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let (a, b) = (report["epe"].as_f64().unwrap(), last_validation["epe"].as_f64().unwrap());
    assert!((a - b).abs() <= 1e-6 * b.abs().max(1.0), "validate {a} vs the log's {b}");
    let o = dgstereo(&["experiment", "validate", exp.to_str().unwrap()]);
    assert!(!o.status.success() && text(&o).contains("train.init"), "{}", text(&o));
    // The trained weights carry their config: `infer` loads them without an experiment file.
    let pred = dir.path().join("pred");
    let o = infer_cones(&[
        "--weights",
        out.join("model.safetensors").to_str().unwrap(),
        "--iters",
        "2",
        "--max-size",
        "128",
        "--out",
        pred.to_str().unwrap(),
        "--save",
        "pfm",
    ]);
    assert!(o.status.success(), "{}", text(&o));
}

/// The tensors of a safetensors file by name (the header's metadata order is not stable across
/// processes: the format stores it as a hash map).
fn tensors(path: &Path) -> Vec<(String, Vec<u8>)> {
    let bytes = std::fs::read(path).unwrap();
    let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
    let mut out: Vec<(String, Vec<u8>)> = st.tensors().into_iter().map(|(n, v)| (n, v.data().to_vec())).collect();
    out.sort();
    out
}

#[test]
fn training_is_reproducible_across_processes() {
    let dir = tempfile::tempdir().unwrap();
    let exp = tiny_experiment(dir.path(), "tiny", &cones_dir(), "");
    let run = |name: &str| {
        let out = dir.path().join(name);
        let o = dgstereo(&["train", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"]);
        assert!(o.status.success(), "{}", text(&o));
        out
    };
    let (a, b) = (run("a"), run("b"));
    let (ta, tb) = (tensors(&a.join("model.safetensors")), tensors(&b.join("model.safetensors")));
    assert!(!ta.is_empty());
    assert!(ta == tb, "two processes with the same experiment file train bit-identical weights");
}

#[test]
fn ablate_scores_benchmarks_and_reuses_finished_runs() {
    let dir = tempfile::tempdir().unwrap();
    let exp = tiny_experiment(dir.path(), "tiny", &cones_dir(), "");
    let out = dir.path().join("ablation");
    let args = ["ablate", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"];
    let o = dgstereo(&args);
    assert!(o.status.success(), "{}", text(&o));
    let csv = std::fs::read_to_string(out.join("ablation.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    for column in ["synthetic", "cones"] {
        assert!(header.contains(column), "column {column} in {header}");
    }
    let row = csv.lines().nth(1).expect("one row");
    assert!(row.starts_with("tiny,"), "{row}");
    let values: Vec<f64> = row.split(',').skip(1).map(|v| v.parse().unwrap()).collect();
    assert_eq!(values.len(), 3 + 3, "synthetic epe/bad-1/bad-3 and cones epe/bad-2/bad-3: {header}");
    assert!(values.iter().all(|v| v.is_finite() && *v >= 0.0), "{row}");
    assert!(out.join("ablation.md").is_file() && out.join("ablation.json").is_file());

    let modified = |p: &Path| std::fs::metadata(p).unwrap().modified().unwrap();
    let model = out.join("tiny/model.safetensors");
    let before = modified(&model);
    // The paper's tables are written too; the run matches none of their rows.
    let tables = std::fs::read_to_string(out.join("paper-tables.md")).unwrap();
    assert!(tables.contains("### Table 5: EALS's threshold tau") && !tables.contains("1.81"), "{tables}");
    let o = dgstereo(&[&args[..], &["--paper"]].concat());
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("reusing it"), "{}", text(&o));
    assert_eq!(modified(&model), before, "a finished run is not trained again");
    assert_eq!(std::fs::read_to_string(out.join("ablation.csv")).unwrap(), csv, "same scores on reuse");
    // --paper sets the published figures beside ours: Table 2's baseline row reads 1.81.
    let tables = std::fs::read_to_string(out.join("paper-tables.md")).unwrap();
    assert!(tables.contains("| | | paper | 1.81 | 8.34 |"), "{tables}");
    let table2 = std::fs::read_to_string(out.join("paper-table2.csv")).unwrap();
    assert!(table2.contains("Baseline,baseline,paper,1.81,8.34,"), "{table2}");
}

#[test]
fn bad_experiment_files_name_the_file_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let typo = tiny_experiment(dir.path(), "typo", &cones_dir(), "[train.schedule]\nwarmup = 0.1");
    let o = dgstereo(&["train", typo.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"]);
    assert!(!o.status.success());
    let t = text(&o);
    assert!(t.contains("typo.toml") && t.contains("schedule"), "{t}");
    assert!(!t.contains("panicked"), "{t}");

    // A benchmark folder that does not exist fails the ablation with its path, after training.
    let missing = dir.path().join("no-such-benchmark");
    let exp = tiny_experiment(dir.path(), "nobench", &missing, "");
    let o = dgstereo(&["ablate", exp.to_str().unwrap(), "--out", dir.path().join("abl").to_str().unwrap(), "--quiet"]);
    assert!(!o.status.success());
    let t = text(&o);
    assert!(t.contains("no-such-benchmark") && t.contains("cones"), "{t}");
    assert!(!t.contains("panicked"), "{t}");
}

#[test]
fn experiment_samples_writes_the_augmented_training_pairs() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("rich.toml");
    std::fs::write(
        &file,
        r#"name = "rich"
[train]
batch_size = 2
crop = [32, 64]
[[data.sources]]
kind = "synthetic"
width = 96
height = 48
textures = "rich"
"#,
    )
    .unwrap();
    let out = dir.path().join("samples");
    let o =
        dgstereo(&["experiment", "samples", file.to_str().unwrap(), "--out", out.to_str().unwrap(), "--count", "3"]);
    assert!(o.status.success(), "{}", text(&o));
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("step 1, element 0: synthetic/"), "{stdout}");
    for k in 0..3 {
        let picture = dgstereo_data::load_rgb(out.join(format!("sample-{k:03}.png"))).unwrap();
        // Left | right | colour-coded ground truth (with its legend strip below).
        assert_eq!(picture.width, 3 * 64, "sample {k}");
        assert!(picture.height >= 32, "sample {k}");
    }
    // A misspelt texture preset is named with its key.
    std::fs::write(&file, std::fs::read_to_string(&file).unwrap().replace("\"rich\"", "\"fancy\"")).unwrap();
    let o = dgstereo(&["experiment", "samples", file.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(text(&o).contains("textures"), "{}", text(&o));
}

/// A build without MPI started by a launcher as one of several ranks refuses, naming the build
/// that would work, before touching the output folder.
#[cfg(not(feature = "mpi"))]
#[test]
fn a_build_without_mpi_refuses_to_run_as_one_of_several_ranks() {
    let dir = tempfile::tempdir().unwrap();
    let exp = tiny_experiment(dir.path(), "ranks", &cones_dir(), "");
    let out = dir.path().join("run");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_dgstereo"))
        .args(["train", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"])
        .env("OMPI_COMM_WORLD_SIZE", "2")
        .output()
        .unwrap();
    let all = text(&o);
    assert!(!o.status.success(), "{all}");
    assert!(all.contains("2 ranks") && all.contains("--features mpi"), "{all}");
    assert!(!out.exists(), "{} was created", out.display());
}
