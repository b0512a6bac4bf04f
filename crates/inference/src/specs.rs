//! What the binary and the Python package read from their users' words alike: a prior
//! specification, the run of an experiment file, and an error with its causes on one line. Their
//! messages name option fields (`` `prior` ``, `` `run` ``); each front end writes the field as its
//! own flag or argument.

use std::path::Path;

use anyhow::{Context, bail};
use dgstereo_model::ModelConfig;
use dgstereo_prior::{DEFAULT_INPUT_SIZE, PriorConfig};

/// Parses a prior specification: `none`, `file:DIR` (precomputed `{name}_left`/`{name}_right`
/// maps), `depth-anything-v2:WEIGHTS` (also `dav2:WEIGHTS`).
pub fn parse_prior(spec: &str) -> anyhow::Result<PriorConfig> {
    let (kind, arg) = spec.split_once(':').unwrap_or((spec, ""));
    Ok(match (kind.to_ascii_lowercase().as_str(), arg) {
        ("none", _) => PriorConfig::None,
        ("file", dir) if !dir.is_empty() => PriorConfig::File {
            dir: dir.into(),
            left: dgstereo_prior::file::DEFAULT_LEFT_PATTERN.into(),
            right: dgstereo_prior::file::DEFAULT_RIGHT_PATTERN.into(),
        },
        ("depth-anything-v2" | "dav2", w) if !w.is_empty() => {
            PriorConfig::DepthAnythingV2 { weights: w.into(), encoder: None, input_size: DEFAULT_INPUT_SIZE }
        }
        _ => bail!("`prior` '{spec}': expected none, file:DIR or depth-anything-v2:WEIGHTS"),
    })
}

/// The model and prior configurations of an experiment file's run: the only run, or the one
/// named `run` when the file resolves to several (a sweep).
pub fn experiment_configs(path: &Path, run: Option<&str>) -> anyhow::Result<(ModelConfig, PriorConfig)> {
    let runs = dgstereo_experiment::load(path)?;
    let names = || runs.iter().map(|r| r.name.as_str()).collect::<Vec<_>>().join(", ");
    let chosen = match (run, runs.len()) {
        (Some(name), _) => runs
            .iter()
            .find(|r| r.name == name)
            .with_context(|| format!("{}: no run named '{name}' (runs: {})", path.display(), names()))?,
        (None, 1) => &runs[0],
        (None, 0) => bail!("{}: the experiment defines no run", path.display()),
        (None, n) => bail!("{}: the experiment has {n} runs; pick one with `run` ({})", path.display(), names()),
    };
    Ok((chosen.config.model.clone(), chosen.config.prior.clone()))
}

/// An error and its causes on one line, without repeating a cause its parent already quotes
/// (the library errors embed their I/O cause in their own message).
pub fn error_chain(e: &anyhow::Error) -> String {
    let mut line = String::new();
    for cause in e.chain() {
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
        assert_eq!(parse_prior("none").unwrap(), PriorConfig::None);
        assert!(matches!(parse_prior("file:/tmp/p").unwrap(), PriorConfig::File { .. }));
        assert!(matches!(parse_prior("dav2:w.pth").unwrap(), PriorConfig::DepthAnythingV2 { .. }));
        let e = parse_prior("magic").unwrap_err().to_string();
        assert!(e.starts_with("`prior` 'magic'"), "{e}");
        assert!(parse_prior("file:").is_err());
    }

    #[test]
    fn error_chains_do_not_repeat_causes() {
        let io = std::io::Error::new(std::io::ErrorKind::UnexpectedEof, "unexpected end of file");
        let e = anyhow::Error::from(dgstereo_core::Error::io("a.png", io)).context("pair a");
        assert_eq!(error_chain(&e), "pair a: a.png: unexpected end of file");
    }
}
