//! `dgstereo ablate --launcher slurm`: a study as one Slurm array job, a task per run, and a job
//! that collects the tables once every task has ended.
//!
//! Design decision: a task is `dgstereo ablate --task I` on the same files and output folder, so
//! it trains exactly what the local loop trains (with `--resume` semantics: a requeued task
//! continues from its checkpoint) and stores its scores in its own run folder; the collecting job
//! (`--collect`, dependency `afterany`) builds the tables from those folders as the local loop
//! does. Preemption and a time limit's warning (`--signal=B:USR1@120`) reach the batch shell,
//! which passes USR1 to the trainer; the trainer finishes its step, writes a checkpoint and exits
//! 138 (SIGTERM: 143), and the shell turns either into `scontrol requeue`. The scripts are written
//! into `--out/slurm/` beside the task logs, so a study can be inspected and resubmitted by hand.

use std::path::Path;
use std::process::{Command, ExitCode};

use anyhow::{Context, bail};
use dgstereo_experiment::ResolvedRun;

/// What a Slurm study is submitted with (from `ablate`'s arguments).
pub struct Submission<'a> {
    /// The experiment files, in order.
    pub files: &'a [std::path::PathBuf],
    /// The output folder.
    pub out: &'a Path,
    /// `--steps`.
    pub steps: Option<u64>,
    /// `--device`, as the tasks' flag (`cpu`, `gpu`).
    pub device: &'static str,
    /// `--sbatch`.
    pub sbatch: Option<&'a str>,
    /// `--wait`.
    pub wait: bool,
}

/// `text` as one word of a POSIX shell.
fn quoted(text: &str) -> String {
    format!("'{}'", text.replace('\'', "'\\''"))
}

/// The `sbatch` options of the study: every file's `[launcher] sbatch` (each option once), then
/// `--sbatch`.
fn sbatch_options(runs: &[ResolvedRun], extra: Option<&str>) -> Vec<String> {
    let mut options: Vec<String> = Vec::new();
    for option in runs.iter().flat_map(|r| &r.config.launcher.sbatch) {
        if !options.contains(option) {
            options.push(option.clone());
        }
    }
    options.extend(extra.unwrap_or_default().split_whitespace().map(str::to_string));
    options
}

/// The batch script of the array's tasks.
fn task_script(a: &Submission<'_>, count: usize, exe: &Path, out: &Path) -> String {
    let mut command =
        vec![quoted(&exe.display().to_string()), "ablate".into(), "--task".into(), "\"$SLURM_ARRAY_TASK_ID\"".into()];
    command.extend(["--out".into(), quoted(&out.display().to_string()), "--quiet".into()]);
    command.extend(["--device".into(), a.device.into()]);
    if let Some(steps) = a.steps {
        command.extend(["--steps".into(), steps.to_string()]);
    }
    command.extend(
        a.files.iter().map(|f| quoted(&std::path::absolute(f).unwrap_or_else(|_| f.clone()).display().to_string())),
    );
    format!(
        r#"#!/bin/bash
#SBATCH --job-name=dgstereo-study
#SBATCH --array=0-{last}
#SBATCH --requeue
#SBATCH --open-mode=append
#SBATCH --output={log}
# One run of the study per task. USR1 (preemption notice, --signal=B:USR1@120) reaches this
# shell and is passed to the trainer; SIGTERM reaches the trainer itself. Either way it finishes
# its step, writes a checkpoint and exits 138 or 143, which requeues the task: it resumes there.
trap 'kill -USR1 "$child" 2> /dev/null' USR1
trap ':' TERM
{command} &
child=$!
while true; do
    wait "$child"
    status=$?
    kill -0 "$child" 2> /dev/null || break
done
case "$status" in
    138 | 143) scontrol requeue "$SLURM_JOB_ID"; exit 0 ;;
esac
exit "$status"
"#,
        last = count.saturating_sub(1),
        log = quoted(&out.join("slurm").join("task-%a.out").display().to_string()).trim_matches('\''),
        command = command.join(" "),
    )
}

/// The batch script of the collecting job.
fn collect_script(exe: &Path, out: &Path) -> String {
    format!(
        "#!/bin/bash\n#SBATCH --job-name=dgstereo-collect\n#SBATCH --output={}\n{} ablate --collect --out {}\n",
        out.join("slurm").join("collect.out").display(),
        quoted(&exe.display().to_string()),
        quoted(&out.display().to_string()),
    )
}

fn sbatch(args: &[String]) -> anyhow::Result<std::process::Output> {
    Command::new("sbatch").args(args).output().context("cannot run sbatch (is Slurm installed and SLURM_CONF set?)")
}

/// Writes the scripts and submits the array and the collecting job; with `--wait`, returns the
/// collecting job's status once the tables are written.
pub fn submit(runs: &[ResolvedRun], a: &Submission<'_>) -> anyhow::Result<ExitCode> {
    let out = std::path::absolute(a.out).unwrap_or_else(|_| a.out.to_path_buf());
    let dir = out.join("slurm");
    std::fs::create_dir_all(&dir).map_err(|e| dgstereo_core::Error::io(&dir, e))?;
    let exe = std::env::current_exe().context("cannot find this dgstereo binary")?;
    let tasks = dir.join("study.sbatch");
    let collect = dir.join("collect.sbatch");
    dgstereo_train::checkpoint::write_atomic(&tasks, task_script(a, runs.len(), &exe, &out).as_bytes())?;
    dgstereo_train::checkpoint::write_atomic(&collect, collect_script(&exe, &out).as_bytes())?;

    let options = sbatch_options(runs, a.sbatch);
    let mut args: Vec<String> = vec!["--parsable".into()];
    args.extend(options.iter().cloned());
    args.push(tasks.display().to_string());
    let submitted = sbatch(&args)?;
    if !submitted.status.success() {
        bail!("sbatch {}: {}", args.join(" "), String::from_utf8_lossy(&submitted.stderr).trim());
    }
    let array = String::from_utf8_lossy(&submitted.stdout).trim().split(';').next().unwrap_or_default().to_string();
    // The collecting job needs no GPU: it gets only where and on whose account to run.
    let placement =
        options.iter().filter(|o| ["--partition", "-p", "--account", "-A", "--qos"].iter().any(|p| o.starts_with(p)));
    let mut args: Vec<String> = vec!["--parsable".into(), format!("--dependency=afterany:{array}")];
    args.extend(placement.cloned());
    if a.wait {
        args.push("--wait".into());
    }
    args.push(collect.display().to_string());
    println!(
        "submitted array job {array} ({} tasks, logs in {}/task-<i>.out); the tables follow in {}",
        runs.len(),
        dir.display(),
        out.display()
    );
    let collected = sbatch(&args)?;
    let job = String::from_utf8_lossy(&collected.stdout).trim().split(';').next().unwrap_or_default().to_string();
    if !a.wait {
        if !collected.status.success() {
            bail!("sbatch {}: {}", args.join(" "), String::from_utf8_lossy(&collected.stderr).trim());
        }
        println!("collecting job {job} runs after the array (dgstereo ablate --collect --out {})", out.display());
        return Ok(ExitCode::SUCCESS);
    }
    let log = std::fs::read_to_string(dir.join("collect.out")).unwrap_or_default();
    print!("{log}");
    Ok(if collected.status.success() { ExitCode::SUCCESS } else { ExitCode::FAILURE })
}
