//! What a study's folders record: `study.json` (the study itself, for collecting it later) and,
//! in each run's folder, what its log and summary say about how far it got.

use std::path::{Path, PathBuf};

use dgstereo_core::{Error, Result};
use dgstereo_train::run::is_finished;
use serde::{Deserialize, Serialize};

/// What `study.json` records of a study.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Study {
    /// The experiment files (absolute), in order.
    pub files: Vec<PathBuf>,
    /// The steps every run trains instead of its file's `train.steps`, when given.
    pub steps: Option<u64>,
    /// Whether the paper's published figures go beside ours.
    pub paper: bool,
}

impl Study {
    /// Writes `out/study.json`.
    ///
    /// # Errors
    /// The file cannot be written.
    pub fn write(&self, out: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self).map_err(|e| Error::encode("the study record", e))?;
        dgstereo_train::checkpoint::write_atomic(&out.join("study.json"), format!("{text}\n").as_bytes())
    }

    /// Reads `out/study.json`.
    ///
    /// # Errors
    /// [`Error::Io`] where there is none (no study was started in `out`), [`Error::Format`]
    /// where it is not a study record.
    pub fn read(out: &Path) -> Result<Self> {
        let path = out.join("study.json");
        let text = std::fs::read_to_string(&path).map_err(|e| {
            let reason = format!("no study here (a study writes study.json into its output folder): {e}");
            Error::io(&path, std::io::Error::new(e.kind(), reason))
        })?;
        serde_json::from_str(&text).map_err(|e| Error::format(&path, format!("not a study record: {e}")))
    }
}

/// Why run folder `out` has no scores, with its log's path: finished but not scored, failed
/// (with the error its log records last), or not finished.
pub fn why_missing(out: &Path) -> String {
    let log = out.join("log.jsonl");
    let error = std::fs::read_to_string(&log).ok().and_then(|text| {
        text.lines()
            .rev()
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
            .find(|v| v["kind"] == "error")
            .and_then(|v| v["message"].as_str().map(str::to_string))
    });
    match (is_finished(out), error) {
        (true, _) => format!("finished, not scored (log: {})", log.display()),
        (false, Some(message)) => format!("failed: {message} (log: {})", log.display()),
        (false, None) => format!("not finished (log: {})", log.display()),
    }
}

/// The steps the run in folder `out` trained, from its own record: `summary.json`'s `steps` for
/// a finished run, else its `config.toml`'s `train.steps`.
pub fn recorded_steps(out: &Path) -> Option<usize> {
    let summary = std::fs::read_to_string(out.join("summary.json")).ok();
    let finished =
        summary.and_then(|t| serde_json::from_str::<serde_json::Value>(&t).ok()).and_then(|v| v["steps"].as_u64());
    let configured = || {
        let text = std::fs::read_to_string(out.join("config.toml")).ok()?;
        text.parse::<toml::Table>().ok()?.get("train")?.get("steps")?.as_integer()
    };
    finished.or_else(|| configured().and_then(|s| u64::try_from(s).ok())).map(|s| s as usize)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_study_record_round_trips_and_a_missing_one_names_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let e = Study::read(dir.path()).unwrap_err();
        assert!(matches!(&e, Error::Io { path, .. } if path.ends_with("study.json")), "{e}");
        assert!(e.to_string().contains("no study here"), "{e}");
        let study = Study { files: vec!["/a.toml".into()], steps: Some(3), paper: true };
        study.write(dir.path()).unwrap();
        assert_eq!(Study::read(dir.path()).unwrap(), study);
    }

    #[test]
    fn a_run_folder_says_why_it_has_no_scores_and_how_far_it_trained() {
        let dir = tempfile::tempdir().unwrap();
        assert!(why_missing(dir.path()).starts_with("not finished"));
        std::fs::write(
            dir.path().join("log.jsonl"),
            "{\"kind\":\"train\"}\n{\"kind\":\"error\",\"message\":\"boom\"}\n",
        )
        .unwrap();
        assert!(why_missing(dir.path()).starts_with("failed: boom"));
        assert_eq!(recorded_steps(dir.path()), None);
        std::fs::write(dir.path().join("config.toml"), "[train]\nsteps = 7\n").unwrap();
        assert_eq!(recorded_steps(dir.path()), Some(7));
        std::fs::write(dir.path().join("summary.json"), "{\"steps\": 5}").unwrap();
        assert_eq!(recorded_steps(dir.path()), Some(5));
    }
}
