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
fn ablate_scores_benchmarks_reuses_finished_runs_and_rescores_new_benchmarks() {
    let dir = tempfile::tempdir().unwrap();
    let exp = tiny_experiment(dir.path(), "tiny", &cones_dir(), "");
    let out = dir.path().join("ablation");
    let args = ["ablate", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"];
    let o = dgstereo(&args);
    assert!(o.status.success(), "{}", text(&o));
    let csv = std::fs::read_to_string(out.join("ablation.csv")).unwrap();
    let header = csv.lines().next().unwrap();
    assert!(header.starts_with("run,n,steps,synthetic epe,synthetic epe std,"), "{header}");
    assert!(header.contains("cones bad-2 std"), "{header}");
    let row = csv.lines().nth(1).expect("one row");
    assert!(row.starts_with("tiny,1,3,"), "{row}");
    let values: Vec<f64> = row.split(',').skip(3).map(|v| v.parse().unwrap()).collect();
    assert_eq!(
        values.len(),
        2 * (3 + 3),
        "synthetic epe/bad-1/bad-3 and cones epe/bad-2/bad-3, each with std: {header}"
    );
    assert!(values.iter().all(|v| v.is_finite() && *v >= 0.0), "{row}");
    let md = std::fs::read_to_string(out.join("ablation.md")).unwrap();
    assert!(md.contains("Lower is better") && md.contains("Pairs scored: synthetic 1, cones 1."), "{md}");
    assert!(out.join("ablation.json").is_file() && out.join("ablation.png").is_file());
    assert!(!out.join("paper-tables.md").exists(), "no row is one of the paper's");

    let modified = |p: &Path| std::fs::metadata(p).unwrap().modified().unwrap();
    let model = out.join("tiny/model.safetensors");
    let before = modified(&model);
    let o = dgstereo(&args);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("reusing it") && text(&o).contains("scores reused"), "{}", text(&o));
    assert_eq!(modified(&model), before, "a finished run is not trained again");
    assert_eq!(std::fs::read_to_string(out.join("ablation.csv")).unwrap(), csv, "same scores on reuse");

    // A benchmark added to the finished study: scored, nothing trained.
    let again = format!(
        "[[benchmarks]]\nname = \"cones-small\"\ndataset = \"folder\"\nroot = '{}'\niters = 2\nmax_size = 64\n",
        cones_dir().display()
    );
    tiny_experiment(dir.path(), "tiny", &cones_dir(), &again);
    let o = dgstereo(&args);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(said.contains("reusing it") && !said.contains("scores reused") && said.contains("cones-small"), "{said}");
    assert_eq!(modified(&model), before, "adding a benchmark trains nothing");
    let csv = std::fs::read_to_string(out.join("ablation.csv")).unwrap();
    assert!(csv.lines().next().unwrap().contains("cones-small epe"), "{csv}");
    // --rescore scores again without training.
    let o = dgstereo(&[&args[..], &["--rescore"]].concat());
    assert!(o.status.success() && !text(&o).contains("scores reused"), "{}", text(&o));
    assert_eq!(modified(&model), before);

    // --collect builds the same tables from the run folders; a run without its model is a row
    // saying so, with its log, and the status is a failure.
    let csv = std::fs::read_to_string(out.join("ablation.csv")).unwrap();
    let o = dgstereo(&["ablate", "--collect", "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(std::fs::read_to_string(out.join("ablation.csv")).unwrap(), csv);
    std::fs::remove_file(&model).unwrap();
    let o = dgstereo(&["ablate", "--collect", "--out", out.to_str().unwrap()]);
    assert!(!o.status.success(), "{}", text(&o));
    let md = std::fs::read_to_string(out.join("ablation.md")).unwrap();
    let log = out.join("tiny/log.jsonl");
    assert!(md.contains(&format!("| tiny | 0 | – | not finished (log: {}) |", log.display())), "{md}");
}

#[test]
fn ablate_makes_one_row_of_a_seed_sweep() {
    let dir = tempfile::tempdir().unwrap();
    let exp = tiny_experiment(dir.path(), "seeds", &cones_dir(), "[sweep]\n\"train.seed\" = [1, 2, 3]\n");
    let out = dir.path().join("ablation");
    let o = dgstereo(&["ablate", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", text(&o));
    let csv = std::fs::read_to_string(out.join("ablation.csv")).unwrap();
    assert_eq!(csv.lines().count(), 2, "one row: {csv}");
    assert!(csv.lines().nth(1).unwrap().starts_with("seeds,3,3,"), "{csv}");
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("ablation.json")).unwrap()).unwrap();
    assert_eq!(json["rows"][0]["seeds"].as_array().unwrap().len(), 3);
    assert!(json["rows"][0]["std"]["synthetic/epe"].as_f64().unwrap() > 0.0, "three seeds differ");
    assert!(std::fs::read_to_string(out.join("ablation.md")).unwrap().contains(" ± "));
}

/// A benchmark root relative to the experiment file resolves from any working directory.
#[test]
fn paths_in_an_experiment_are_relative_to_its_file() {
    let dir = tempfile::tempdir().unwrap();
    let data = dir.path().join("data/cones");
    std::fs::create_dir_all(&data).unwrap();
    for entry in std::fs::read_dir(cones_dir()).unwrap() {
        let path = entry.unwrap().path();
        if path.is_file() {
            std::fs::copy(&path, data.join(path.file_name().unwrap())).unwrap();
        }
    }
    let folder = dir.path().join("exp");
    std::fs::create_dir_all(&folder).unwrap();
    let exp = tiny_experiment(&folder, "relative", Path::new("../data/cones"), "");
    let o = std::process::Command::new(env!("CARGO_BIN_EXE_dgstereo"))
        .args(["experiment", "check", exp.to_str().unwrap(), "--show"])
        .current_dir("/")
        .output()
        .unwrap();
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(said.contains(&format!("root = \"{}\"", data.display())), "{said}");
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

    // A benchmark folder that does not exist fails the ablation with its path and key, before
    // any run trains (the good run listed first included).
    let good = tiny_experiment(dir.path(), "good", &cones_dir(), "");
    let missing = dir.path().join("no-such-benchmark");
    let exp = tiny_experiment(dir.path(), "nobench", &missing, "");
    let abl = dir.path().join("abl");
    let o =
        dgstereo(&["ablate", good.to_str().unwrap(), exp.to_str().unwrap(), "--out", abl.to_str().unwrap(), "--quiet"]);
    assert!(!o.status.success());
    let t = text(&o);
    assert!(
        t.contains(&missing.display().to_string()) && t.contains("benchmarks[0]") && t.contains("nobench.toml"),
        "{t}"
    );
    assert!(!t.contains("panicked"), "{t}");
    assert!(!abl.join("good").exists(), "nothing trained before the check failed");
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
