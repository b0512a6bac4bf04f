//! What the binary and the Python package read from their users' words alike: a prior
//! specification, the run of an experiment file, and an error with its causes on one line. Their
//! messages name option fields (`` `prior` ``, `` `run` ``); each front end writes the field as its
//! own flag or argument.

use std::path::Path;

use dgstereo_core::{Error, Result};
use dgstereo_model::ModelConfig;
use dgstereo_prior::{DEFAULT_INPUT_SIZE, PriorConfig};

/// Parses a prior specification: `none`, `file:DIR` (precomputed `{name}_left`/`{name}_right`
/// maps), `depth-anything-v2:WEIGHTS` (also `dav2:WEIGHTS`).
pub fn parse_prior(spec: &str) -> Result<PriorConfig> {
    let (kind, arg) = spec.split_once(':').unwrap_or((spec, ""));
    Ok(match (kind.to_ascii_lowercase().as_str(), arg) {
        ("none", _) => PriorConfig::None {},
        ("file", dir) if !dir.is_empty() => PriorConfig::File {
            dir: dir.into(),
            left: dgstereo_prior::file::DEFAULT_LEFT_PATTERN.into(),
            right: dgstereo_prior::file::DEFAULT_RIGHT_PATTERN.into(),
        },
        ("depth-anything-v2" | "dav2", w) if !w.is_empty() => {
            PriorConfig::DepthAnythingV2 { weights: w.into(), encoder: None, input_size: DEFAULT_INPUT_SIZE }
        }
        _ => {
            return Err(Error::config(
                "prior",
                format!("'{spec}': expected none, file:DIR or depth-anything-v2:WEIGHTS"),
            ));
        }
    })
}

/// The model and prior configurations of an experiment file's run: the only run, or the one
/// named `run` when the file resolves to several (a sweep).
pub fn experiment_configs(path: &Path, run: Option<&str>) -> Result<(ModelConfig, PriorConfig)> {
    let runs = dgstereo_experiment::load(path)?;
    let names = || runs.iter().map(|r| r.name.as_str()).collect::<Vec<_>>().join(", ");
    let chosen = match (run, runs.len()) {
        (Some(name), _) => runs.iter().find(|r| r.name == name).ok_or_else(|| {
            Error::config("run", format!("{}: no run named '{name}' (runs: {})", path.display(), names()))
        })?,
        (None, 1) => &runs[0],
        (None, 0) => return Err(Error::config("run", format!("{}: the experiment defines no run", path.display()))),
        (None, n) => {
            let reason = format!("{}: the experiment has {n} runs; pick one ({})", path.display(), names());
            return Err(Error::config("run", reason));
        }
    };
    Ok((chosen.config.model.clone(), chosen.config.prior.clone()))
}

/// An error and its causes on one line, without repeating a cause its parent already quotes
/// (the library errors embed their I/O cause in their own message). Takes any error, so a front
/// end passes its own (an `anyhow::Error` dereferences to one).
pub fn error_chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut line = String::new();
    for cause in std::iter::successors(Some(e), |cause| cause.source()) {
        let text = cause.to_string();
        if line.contains(&text) {
            continue;
        }
        if !line.is_empty() {
            line.push_str(": ");
        }
        line.push_str(&text);
    }
    line
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prior_specs_parse() {
        assert_eq!(parse_prior("none").unwrap(), PriorConfig::None {});
        assert!(matches!(parse_prior("file:/tmp/p").unwrap(), PriorConfig::File { .. }));
        assert!(matches!(parse_prior("dav2:w.pth").unwrap(), PriorConfig::DepthAnythingV2 { .. }));
        let e = parse_prior("magic").unwrap_err().to_string();
        assert!(e.contains("prior: 'magic'"), "{e}");
        assert!(parse_prior("file:").is_err());
    }

    #[test]
    fn error_chains_do_not_repeat_causes() {
        let io = std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "unexpected end of file");
        // A caller's context over a library error over its I/O cause.
        #[derive(Debug)]
        struct Pair(dgstereo_core::Error);
        impl std::fmt::Display for Pair {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("pair a")
            }
        }
        impl std::error::Error for Pair {
            fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
                Some(&self.0)
            }
        }
        let e = Pair(dgstereo_core::Error::io("a.png", io));
        assert_eq!(error_chain(&e), "pair a: a.png: unexpected end of file");
    }
}
