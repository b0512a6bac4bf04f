//! The runs of a study and their folders: each run trains into a folder of its own under the
//! study's output folder, named after the run, from the trainer's parts of its configuration.

use std::path::{Path, PathBuf};

use dgstereo_core::{Error, Result};
use dgstereo_experiment::{ExperimentConfig, ResolvedRun};
use dgstereo_train::TrainParts;
use dgstereo_train::run::checkpoint_dir;

/// A run name as a folder name: characters other than letters, digits, `-`, `_`, `.`, `=`, `,`
/// and `+` become `_`.
pub fn folder_name(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || "-_.=,+".contains(c) { c } else { '_' }).collect()
}

/// The folder of run `name` in the study folder `out`.
pub fn run_folder(out: &Path, name: &str) -> PathBuf {
    out.join(folder_name(name))
}

/// The trainer's parts of a resolved experiment, with `steps` (when given) replacing
/// `train.steps` before the configuration is resolved into text.
pub fn parts_of(mut config: ExperimentConfig, steps: Option<u64>) -> TrainParts {
    if let Some(s) = steps {
        config.train.steps = s as usize;
    }
    TrainParts::from(config)
}

/// Checks that no two runs train into one folder: two runs of one name (from two files, or one
/// file given twice), or names that differ only in characters a folder name replaces.
///
/// # Errors
/// [`Error::Config`] keyed `name`, naming both runs and their files.
pub fn check_distinct_folders(runs: &[ResolvedRun]) -> Result<()> {
    for (i, run) in runs.iter().enumerate() {
        let folder = folder_name(&run.name);
        let Some(other) = runs[..i].iter().find(|r| folder_name(&r.name) == folder) else { continue };
        let (a, b) = (other.source.display(), run.source.display());
        let reason = if other.name == run.name {
            format!(
                "run name '{}' is given twice ({a}, {b}): each run needs a name of its own, since it names the \
                 run's folder and its row; set `name` in one of the files",
                run.name
            )
        } else {
            format!(
                "runs '{}' ({a}) and '{}' ({b}) would train into one folder, '{folder}': rename one",
                other.name, run.name
            )
        };
        return Err(Error::config("name", reason));
    }
    Ok(())
}

/// Whether run folder `out` holds checkpoints to resume from.
///
/// # Errors
/// The checkpoint folder cannot be listed.
pub fn has_checkpoints(out: &Path) -> Result<bool> {
    let dir = checkpoint_dir(out);
    Ok(dir.is_dir() && !dgstereo_train::checkpoint::list_checkpoints(&dir)?.is_empty())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(name: &str, source: &str) -> ResolvedRun {
        let config: ExperimentConfig = toml::from_str(&format!("name = \"{name}\"")).unwrap();
        ResolvedRun { name: name.into(), source: source.into(), config }
    }

    #[test]
    fn runs_that_would_share_a_folder_are_refused_naming_both() {
        assert_eq!(folder_name("a/b=1,c+"), "a_b=1,c+");
        check_distinct_folders(&[run("a", "x.toml"), run("b", "x.toml")]).unwrap();
        let twice = check_distinct_folders(&[run("a", "x.toml"), run("a", "y.toml")]).unwrap_err().to_string();
        assert!(
            twice.contains("'a' is given twice") && twice.contains("x.toml") && twice.contains("y.toml"),
            "{twice}"
        );
        let shared = check_distinct_folders(&[run("a/b", "x.toml"), run("a_b", "x.toml")]).unwrap_err().to_string();
        assert!(shared.contains("one folder, 'a_b'"), "{shared}");
    }
}
