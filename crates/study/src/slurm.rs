//! A study as one Slurm array job, a task per run, and a job that collects the tables once every
//! task has ended.
//!
//! Design decision: a task is `dgstereo ablate --task I` on the same files and output folder, so
//! it trains exactly what the local loop trains (with `--resume` semantics: a requeued task
//! continues from its checkpoint) and stores its scores in its own run folder; the collecting job
//! (`--collect`, dependency `afterany`, then waiting while a requeued task is queued) builds the
//! tables from those folders as the local loop does ([`mod@crate::collect`]). Preemption and a time limit's warning (`--signal=B:USR1@120`) reach
//! the batch shell, which passes USR1 to the trainer; the trainer finishes its step, writes a
//! checkpoint and exits 138 (SIGTERM: 143), and the shell turns either into `scontrol requeue`.
//! The scripts are written into `slurm/` of the study's folder beside the task logs, so a study
//! can be inspected and resubmitted by hand.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use dgstereo_core::{Error, Result};
use dgstereo_experiment::ResolvedRun;

/// What a Slurm study is submitted with.
pub struct Submission<'a> {
    /// The `dgstereo` binary the jobs run.
    pub exe: PathBuf,
    /// The experiment files, in order.
    pub files: &'a [PathBuf],
    /// The study's folder.
    pub out: &'a Path,
    /// The steps every run trains instead of its file's `train.steps`, when given.
    pub steps: Option<u64>,
    /// The tasks' device (`cpu`, `gpu`).
    pub device: &'static str,
    /// `sbatch` options beyond those of the files' `[launcher]` tables, as one string.
    pub sbatch: Option<&'a str>,
    /// Whether to wait for the collecting job.
    pub wait: bool,
}

/// The array job, once submitted.
pub struct ArrayJob {
    /// Slurm's job id.
    pub id: String,
    /// The number of tasks (runs).
    pub tasks: usize,
    /// Where the scripts and the task logs are.
    pub dir: PathBuf,
    /// The study's folder, absolute.
    pub out: PathBuf,
}

/// The collecting job, once submitted (and, with `wait`, ended).
pub struct CollectingJob {
    /// Slurm's job id.
    pub id: String,
    /// Whether it was submitted and, with `wait`, ended with success.
    pub success: bool,
    /// With `wait`: its log, the tables as it printed them.
    pub log: Option<String>,
}

/// `text` as one word of a POSIX shell.
fn quoted(text: &str) -> String {
    format!("'{}'", text.replace('\'', "'\\''"))
}

/// The `sbatch` options of the study: every file's `[launcher] sbatch` (each option once), then
/// `extra`.
pub fn sbatch_options(runs: &[ResolvedRun], extra: Option<&str>) -> Vec<String> {
    let mut options: Vec<String> = Vec::new();
    for option in runs.iter().flat_map(|r| &r.config.launcher.sbatch) {
        if !options.contains(option) {
            options.push(option.clone());
        }
    }
    options.extend(extra.unwrap_or_default().split_whitespace().map(str::to_string));
    options
}

/// The batch script of the array's tasks: task `I` runs `ablate --task I`.
pub fn task_script(a: &Submission<'_>, count: usize, out: &Path) -> String {
    let mut command =
        vec![quoted(&a.exe.display().to_string()), "ablate".into(), "--task".into(), "\"$SLURM_ARRAY_TASK_ID\"".into()];
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

/// The batch script of the collecting job: `ablate --collect`, once no task of the array job
/// given as its argument is queued or running.
///
/// `afterany` alone is not enough: a task that requeues itself can count as ended for a moment,
/// and the dependency then lets this job start while the task waits to run again, so the tables
/// would miss its run. `squeue` on an ended (or purged) array prints nothing.
pub fn collect_script(exe: &Path, out: &Path) -> String {
    // Slurm's states of a job that has not ended (squeue's short names).
    const ACTIVE: &str = "PD,R,S,CG,CF,RQ,RH,RF,SI,SO,ST";
    format!(
        "#!/bin/bash\n#SBATCH --job-name=dgstereo-collect\n#SBATCH --output={}\n\
         # $1: the array job. Wait while any of its tasks is queued or running (a requeued one too;\n\
         # the states are named, as some versions list ended jobs too when given their ids).\n\
         while [ -n \"${{1:-}}\" ] && [ -n \"$(squeue -h -j \"$1\" -t {ACTIVE} -o %i 2> /dev/null)\" ]; do sleep 5; done\n\
         {} ablate --collect --out {}\n",
        out.join("slurm").join("collect.out").display(),
        quoted(&exe.display().to_string()),
        quoted(&out.display().to_string()),
    )
}

fn sbatch(args: &[String]) -> Result<Output> {
    Command::new("sbatch").args(args).output().map_err(|e| {
        let reason = format!("cannot run it (is Slurm installed and SLURM_CONF set?): {e}");
        Error::io("sbatch", std::io::Error::new(e.kind(), reason))
    })
}

/// The job id `sbatch --parsable` printed.
fn job_id(output: &Output) -> String {
    String::from_utf8_lossy(&output.stdout).trim().split(';').next().unwrap_or_default().to_string()
}

/// `sbatch`'s refusal, with the command and what it said.
fn refused(args: &[String], output: &Output) -> Error {
    let said = String::from_utf8_lossy(&output.stderr).trim().to_string();
    Error::io("sbatch", std::io::Error::other(said)).context(format!("sbatch {}", args.join(" ")))
}

/// Writes the scripts and submits the array, then the collecting job; `submitted` sees the array
/// job before the collecting job is submitted (with `wait`, that call returns only once the
/// tables are written).
///
/// # Errors
/// A script cannot be written, `sbatch` cannot run, or it refuses the array (or, without
/// `wait`, the collecting job).
pub fn submit(runs: &[ResolvedRun], a: &Submission<'_>, submitted: impl FnOnce(&ArrayJob)) -> Result<CollectingJob> {
    let out = std::path::absolute(a.out).unwrap_or_else(|_| a.out.to_path_buf());
    let dir = out.join("slurm");
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    let tasks = dir.join("study.sbatch");
    let collect = dir.join("collect.sbatch");
    dgstereo_train::checkpoint::write_atomic(&tasks, task_script(a, runs.len(), &out).as_bytes())?;
    dgstereo_train::checkpoint::write_atomic(&collect, collect_script(&a.exe, &out).as_bytes())?;

    let options = sbatch_options(runs, a.sbatch);
    let mut args: Vec<String> = vec!["--parsable".into()];
    args.extend(options.iter().cloned());
    args.push(tasks.display().to_string());
    let array = sbatch(&args)?;
    if !array.status.success() {
        return Err(refused(&args, &array));
    }
    let array = ArrayJob { id: job_id(&array), tasks: runs.len(), dir, out };
    // The collecting job needs no GPU: it gets only where and on whose account to run.
    let placement =
        options.iter().filter(|o| ["--partition", "-p", "--account", "-A", "--qos"].iter().any(|p| o.starts_with(p)));
    let mut args: Vec<String> = vec!["--parsable".into(), format!("--dependency=afterany:{}", array.id)];
    args.extend(placement.cloned());
    if a.wait {
        args.push("--wait".into());
    }
    args.push(collect.display().to_string());
    args.push(array.id.clone());
    submitted(&array);
    let collected = sbatch(&args)?;
    if !a.wait && !collected.status.success() {
        return Err(refused(&args, &collected));
    }
    let log = a.wait.then(|| std::fs::read_to_string(array.dir.join("collect.out")).unwrap_or_default());
    Ok(CollectingJob { id: job_id(&collected), success: collected.status.success(), log })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_scripts_run_this_binary_on_the_study_as_tasks_and_collector() {
        let files = [PathBuf::from("/e/it's.toml")];
        let out = Path::new("/runs/study");
        let a = Submission {
            exe: "/bin/dgstereo".into(),
            files: &files,
            out,
            steps: Some(5),
            device: "gpu",
            sbatch: None,
            wait: false,
        };
        let tasks = task_script(&a, 3, out);
        assert!(tasks.contains("#SBATCH --array=0-2"), "{tasks}");
        assert!(
            tasks.contains(
                "'/bin/dgstereo' ablate --task \"$SLURM_ARRAY_TASK_ID\" --out '/runs/study' --quiet --device gpu \
                 --steps 5 '/e/it'\\''s.toml'"
            ),
            "{tasks}"
        );
        let collect = collect_script(&a.exe, out);
        assert!(collect.ends_with("'/bin/dgstereo' ablate --collect --out '/runs/study'\n"), "{collect}");
        assert!(collect.contains("squeue -h -j \"$1\""), "{collect}");
        assert_eq!(sbatch_options(&[], Some("--partition=gpu  --time=1:00:00")), ["--partition=gpu", "--time=1:00:00"]);
    }
}
