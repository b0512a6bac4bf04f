//! Running the `dgstereo` binary from integration tests.

#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The repository's `assets/` folder.
pub fn assets() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../assets")
}

/// The bundled Cones pair.
pub fn cones_dir() -> PathBuf {
    assets().join("cones")
}

/// Runs the binary with `args`.
pub fn dgstereo(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dgstereo")).args(args).output().expect("the dgstereo binary runs")
}

/// Runs `dgstereo infer` on the bundled Cones pair with `extra` arguments.
pub fn infer_cones(extra: &[&str]) -> Output {
    let cones = cones_dir();
    let (left, right) = (cones.join("left_rgb.png"), cones.join("right_rgb.png"));
    let mut args = vec!["infer", "-l", left.to_str().unwrap(), "-r", right.to_str().unwrap()];
    args.extend_from_slice(extra);
    dgstereo(&args)
}

/// Standard output and error together, for assertion messages and searches.
pub fn text(o: &Output) -> String {
    format!("{}\n{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// The tiny network of the training tests: 8-channel trunks, 16-channel GRUs on one level.
pub const TINY_MODEL: &str = "[model.encoder]\nfeature_dim = 16\ntrunk_dims = [8, 8, 8]\n[model.updater]\nhidden_dims = [16, 16, 16]\nn_gru_layers = 1\n";

/// A small synthetic training source.
pub const SYNTHETIC_SOURCE: &str = "[[data.sources]]\nkind = \"synthetic\"\nwidth = 96\nheight = 48\n";

/// A one-pair validation set of 64x32, scored with two iterations.
pub const TINY_VALIDATION: &str = "[data.validation]\ncount = 1\nwidth = 64\nheight = 32\niters = 2\n";

/// `[train]` for the tests: `steps` steps of batch `batch` on 32x64 crops, two iterations,
/// logging every step, seeded `seed`, checkpoints every `checkpoint_every` steps, no validation
/// before the end; `extra` lines are added to the table.
pub fn tiny_train(steps: usize, batch: usize, seed: u64, checkpoint_every: usize, extra: &str) -> String {
    format!(
        "[train]\nsteps = {steps}\nbatch_size = {batch}\ncrop = [32, 64]\niters = 2\nseed = {seed}\nlog_every = 1\n\
         checkpoint_every = {checkpoint_every}\nvalidate_every = 0\n{extra}"
    )
}

/// Writes `dir/<file>`: run `name` of [`TINY_MODEL`], `train` and `data`, then `extra`.
pub fn write_experiment(dir: &Path, file: &str, name: &str, train: &str, data: &str, extra: &str) -> PathBuf {
    let path = dir.join(file);
    std::fs::write(&path, format!("name = \"{name}\"\n{TINY_MODEL}{train}{data}{extra}")).unwrap();
    path
}

/// `dgstereo verify MODEL --reference G` on the golden `golden` (a path under `../shared`) for
/// the test `test`: its output, and whether the command succeeded; `None` (with the skip notice)
/// where `../shared` is missing outside CI.
pub fn verify_on_golden(test: &str, model: &str, golden: &str) -> Option<Output> {
    let shared = dgstereo_core::shared::shared_dir_for_test(test, golden)?;
    Some(dgstereo(&["verify", model, "--reference", shared.join(golden).to_str().unwrap()]))
}

/// The checks every passing `verify` run gets: success, no line marked `FAIL`, and the last
/// line's final disparity error within `tolerance` pixels. Returns its stdout.
pub fn assert_verify_passed(out: &Output, model: &str, tolerance: f32) -> String {
    let all = text(out);
    println!("{all}");
    assert!(out.status.success(), "{model} deviates from the reference:\n{all}");
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(stdout.lines().all(|l| !l.ends_with("FAIL")), "{stdout}");
    let last = stdout.lines().last().unwrap_or_default();
    let error: f32 =
        last.strip_prefix("final flow max abs error: ").unwrap_or_else(|| panic!("{last}")).parse().unwrap();
    assert!(error <= tolerance, "{last}");
    stdout
}

/// The checks every refused `verify` run gets: failure without a panic, the file named on stderr.
/// Returns its stderr.
pub fn assert_verify_refused(out: &Output, file_name: &str) -> String {
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(!out.status.success(), "{}", text(out));
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert!(stderr.contains(file_name), "{stderr}");
    stderr
}

/// Writes `dir/<name>.toml`: run `name`, the zoo's `model` (`igev`, `defom`) trained with its
/// official recipe at smoke size: `base` is the zoo's architecture file
/// (`experiments/zoo/{model}.toml`), `[loss]` and `train.frozen` are read from the recipe file
/// (`{model}-train.toml`, whose ImageNet and Depth Anything starts and SceneFlow paths do not
/// exist here), then `steps` steps of batch `batch` ([`tiny_train`], seed `seed`, a checkpoint
/// at the end) on `data`. DEFOM-Stereo takes one scale iteration of its two.
pub fn write_zoo_experiment(
    dir: &Path,
    model: &str,
    name: &str,
    steps: usize,
    batch: usize,
    seed: u64,
    data: &str,
) -> PathBuf {
    let zoo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments/zoo");
    let (architecture, recipe, scale_iters) = match model {
        "igev" => ("igev.toml", "igev-train.toml", ""),
        "defom" => ("defom-vits.toml", "defom-vits-train.toml", "[model.updater.scale_update]\niters = 1\n"),
        _ => panic!("no zoo model {model}"),
    };
    let recipe: toml::Table = std::fs::read_to_string(zoo.join(recipe)).unwrap().parse().unwrap();
    let loss = toml::Table::from_iter([("loss".to_string(), recipe["loss"].clone())]);
    let frozen = recipe["train"].get("frozen").map(|f| format!("frozen = {f}\n")).unwrap_or_default();
    let path = dir.join(format!("{name}.toml"));
    let base = zoo.join(architecture).display().to_string();
    let train = tiny_train(steps, batch, seed, steps, &frozen);
    std::fs::write(&path, format!("base = {base:?}\nname = \"{name}\"\n{scale_iters}{loss}{train}{data}")).unwrap();
    path
}
