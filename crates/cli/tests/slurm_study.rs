//! Studies on Slurm, against a real single-node cluster (`scripts/slurm-local.sh start`; where
//! Slurm cannot be started the tests fail under `CI=true` and skip with a notice elsewhere).
//!
//! - Two tiny runs (a sweep of two seeds), IGEV-Stereo and DEFOM-Stereo (their official losses,
//!   at smoke size) submitted with `--launcher slurm --wait` write tables and models
//!   byte-identical to a local `ablate`'s.
//! - A task signalled with `scancel --signal=USR1 --batch` mid-run checkpoints, requeues, resumes
//!   and ends with a `model.safetensors` byte-identical to an uninterrupted local run's.
//! - The collecting job does not collect while a task of its array is still queued (as a
//!   requeued task is, where Slurm's `afterany` counted its first end).
//! - An invalid run among valid ones submits nothing and names the file and the key.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use common::{SYNTHETIC_SOURCE, TINY_VALIDATION, text, tiny_train, write_experiment, write_zoo_experiment};

/// The tests share one cluster of two CPUs: one at a time.
static CLUSTER: Mutex<()> = Mutex::new(());

/// `SLURM_CONF` of the local cluster, started when needed; `None` (with a notice) where it cannot
/// be, a failure under `CI=true`.
fn local_slurm() -> Option<String> {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/slurm-local.sh");
    let started = Command::new("bash").arg(&script).arg("start").output();
    let conf = started.as_ref().ok().filter(|o| o.status.success()).and_then(|o| {
        String::from_utf8_lossy(&o.stdout)
            .lines()
            .find_map(|l| l.strip_prefix("export SLURM_CONF=").map(str::to_string))
    });
    if conf.is_none() {
        let why = started.map(|o| text(&o)).unwrap_or_else(|e| e.to_string());
        assert!(std::env::var("CI").as_deref() != Ok("true"), "the local Slurm cluster did not start: {why}");
        eprintln!("skipped: no local Slurm cluster ({})", why.trim());
    }
    conf
}

/// `dgstereo` with `args`, with the cluster's configuration.
fn dgstereo(conf: &str, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dgstereo")).args(args).env("SLURM_CONF", conf).output().unwrap()
}

fn slurm(conf: &str, program: &str, args: &[&str]) -> String {
    let o = Command::new(program).args(args).env("SLURM_CONF", conf).output().unwrap();
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// A tiny experiment of `steps` steps, checkpointing only at its end, with `extra` appended.
fn experiment(dir: &Path, name: &str, steps: usize, extra: &str) -> PathBuf {
    let data = format!("{SYNTHETIC_SOURCE}{TINY_VALIDATION}");
    write_experiment(dir, &format!("{name}.toml"), name, &tiny_train(steps, 1, 3, 1000, ""), &data, extra)
}

/// Every `model.safetensors` under `dir`, relative to it.
fn models_under(dir: &Path, root: &Path, found: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.is_dir() {
            models_under(&path, root, found);
        } else if path.file_name().is_some_and(|n| n == "model.safetensors") {
            found.push(path.strip_prefix(root).unwrap().to_path_buf());
        }
    }
}

#[test]
fn a_slurm_study_writes_the_tables_of_a_local_one() {
    let _one = CLUSTER.lock().unwrap_or_else(|e| e.into_inner());
    let Some(conf) = local_slurm() else { return };
    let dir = tempfile::tempdir().unwrap();
    let data = format!("{SYNTHETIC_SOURCE}{TINY_VALIDATION}");
    let files = [
        experiment(dir.path(), "pair", 3, "[sweep]\n\"train.seed\" = [1, 2]\n"),
        write_zoo_experiment(dir.path(), "igev", "igev", 2, 1, 3, &data),
        write_zoo_experiment(dir.path(), "defom", "defom", 2, 1, 3, &data),
    ];
    let files: Vec<&str> = files.iter().map(|f| f.to_str().unwrap()).collect();
    let (local, cluster) = (dir.path().join("local"), dir.path().join("cluster"));
    let ablate = |out: &Path, more: &[&str]| {
        let args: Vec<&str> =
            ["ablate"].into_iter().chain(files.iter().copied()).chain(["--out", out.to_str().unwrap()]).collect();
        dgstereo(&conf, &[&args[..], more].concat())
    };
    let o = ablate(&local, &["--quiet"]);
    assert!(o.status.success(), "{}", text(&o));
    let o = ablate(&cluster, &["--launcher", "slurm", "--wait"]);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(said.contains("submitted array job"), "{said}");
    for table in ["ablation.md", "ablation.csv", "ablation.json"] {
        let (a, b) = (std::fs::read(local.join(table)).unwrap(), std::fs::read(cluster.join(table)).unwrap());
        assert!(a == b, "{table} differs between the local and the Slurm study:\n{}", String::from_utf8_lossy(&b));
    }
    let mut models = Vec::new();
    models_under(&local, &local, &mut models);
    assert_eq!(models.len(), 4, "a model for each run: {models:?}");
    for model in &models {
        let (a, b) = (std::fs::read(local.join(model)).unwrap(), std::fs::read(cluster.join(model)).unwrap());
        assert!(a == b, "{} differs between the local and the Slurm study", model.display());
    }
    assert!((0..4).all(|task| cluster.join(format!("slurm/task-{task}.out")).is_file()));
}

#[test]
fn a_preempted_task_requeues_and_ends_as_an_uninterrupted_run() {
    let _one = CLUSTER.lock().unwrap_or_else(|e| e.into_inner());
    let Some(conf) = local_slurm() else { return };
    let dir = tempfile::tempdir().unwrap();
    let steps = 40;
    let exp = experiment(dir.path(), "long", steps, "");
    let (study, whole) = (dir.path().join("study"), dir.path().join("whole"));
    let o =
        dgstereo(&conf, &["ablate", exp.to_str().unwrap(), "--out", study.to_str().unwrap(), "--launcher", "slurm"]);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    let array =
        said.split("submitted array job ").nth(1).and_then(|s| s.split_whitespace().next()).unwrap().to_string();
    let task = format!("{array}_0");
    let log = study.join("long/log.jsonl");
    let lines = || std::fs::read_to_string(&log).map_or(0, |l| l.lines().filter(|l| l.contains("\"train\"")).count());
    let started = Instant::now();
    while lines() < 2 {
        assert!(started.elapsed() < Duration::from_secs(180), "the task logged no step in 180 s");
        std::thread::sleep(Duration::from_millis(50));
    }
    slurm(&conf, "scancel", &["--signal=USR1", "--batch", &task]);
    // Requeued, the task waits for its begin time; let it start at once.
    let started = Instant::now();
    while !study.join("ablation.csv").is_file() {
        assert!(started.elapsed() < Duration::from_secs(300), "the study did not finish in 300 s");
        let _ = slurm(&conf, "scontrol", &["update", &format!("jobid={task}"), "starttime=now"]);
        std::thread::sleep(Duration::from_millis(500));
    }
    let task_log = std::fs::read_to_string(study.join("slurm/task-0.out")).unwrap();
    assert!(task_log.contains("SIGUSR1: stopped at step"), "{task_log}");
    assert!(task_log.contains("resuming at step"), "{task_log}");
    let o = dgstereo(&conf, &["train", exp.to_str().unwrap(), "--out", whole.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", text(&o));
    let (a, b) = (
        std::fs::read(study.join("long/model.safetensors")).unwrap(),
        std::fs::read(whole.join("model.safetensors")).unwrap(),
    );
    assert!(a == b, "the requeued run's model.safetensors differs from the uninterrupted run's");
}

#[test]
fn an_invalid_run_submits_nothing_and_names_the_file_and_key() {
    let _one = CLUSTER.lock().unwrap_or_else(|e| e.into_inner());
    let Some(conf) = local_slurm() else { return };
    let dir = tempfile::tempdir().unwrap();
    let good = experiment(dir.path(), "good", 3, "");
    let bad = experiment(dir.path(), "bad", 3, "[loss]\nkind = \"edge-aware\"\ntau = -1.0\n");
    let study = dir.path().join("study");
    let jobs = || slurm(&conf, "squeue", &["-h", "-o", "%i"]).lines().count();
    let before = jobs();
    let o = dgstereo(
        &conf,
        &[
            "ablate",
            good.to_str().unwrap(),
            bad.to_str().unwrap(),
            "--out",
            study.to_str().unwrap(),
            "--launcher",
            "slurm",
        ],
    );
    let said = text(&o);
    assert!(!o.status.success(), "{said}");
    assert!(said.contains("bad.toml") && said.contains("loss.tau"), "{said}");
    assert!(!study.join("slurm").exists(), "nothing is written");
    assert_eq!(jobs(), before, "nothing is submitted");
}

#[test]
fn the_collecting_job_waits_while_a_task_of_its_array_is_queued() {
    let _one = CLUSTER.lock().unwrap_or_else(|e| e.into_inner());
    let Some(conf) = local_slurm() else { return };
    let dir = tempfile::tempdir().unwrap();
    let exp = experiment(dir.path(), "pair", 3, "");
    let study = dir.path().join("study");
    let o = dgstereo(&conf, &["ablate", exp.to_str().unwrap(), "--out", study.to_str().unwrap(), "--quiet"]);
    assert!(o.status.success(), "{}", text(&o));
    let table = study.join("ablation.csv");
    std::fs::remove_file(&table).unwrap();
    // A held job stands in for a requeued task waiting for its begin time.
    let held = slurm(&conf, "sbatch", &["--parsable", "--hold", "--output=/dev/null", "--wrap", "true"]);
    let held = held.trim().to_string();
    assert!(!held.is_empty(), "sbatch --hold printed no job id");
    let script = study.join("slurm/collect.sbatch");
    std::fs::create_dir_all(script.parent().unwrap()).unwrap();
    let exe = Path::new(env!("CARGO_BIN_EXE_dgstereo"));
    std::fs::write(&script, dgstereo_study::slurm::collect_script(exe, &study)).unwrap();
    let collector = slurm(&conf, "sbatch", &["--parsable", script.to_str().unwrap(), &held]).trim().to_string();
    let state = || slurm(&conf, "squeue", &["-h", "-j", &collector, "-o", "%T"]).trim().to_string();
    let started = Instant::now();
    // Until it runs (or, collecting at once, has already ended).
    while !matches!(state().as_str(), "RUNNING" | "") {
        assert!(started.elapsed() < Duration::from_secs(180), "the collecting job did not start in 180 s: {}", state());
        std::thread::sleep(Duration::from_millis(200));
    }
    std::thread::sleep(Duration::from_secs(3));
    assert!(!table.exists(), "the collecting job wrote the tables while a task was queued");
    slurm(&conf, "scancel", &[&held]);
    let started = Instant::now();
    while !table.is_file() {
        assert!(
            started.elapsed() < Duration::from_secs(180),
            "the tables were not written in 180 s after the task ended"
        );
        std::thread::sleep(Duration::from_millis(200));
    }
}
