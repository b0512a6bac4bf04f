//! What the binary and the Python package read from their users' words alike: a prior
//! specification and a prior's weights, the model a front end's options choose ([`ModelChoice`]),
//! the run of an experiment file, a model configuration
//! file, a byte size, and an error with its causes on one line. Their
//! messages name option fields (`` `prior` ``, `` `run` ``); each front end writes the field as its
//! own flag or argument.

use std::path::{Path, PathBuf};

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

/// The configurations a front end's options choose beside the weights: an experiment file's run
/// for the model and prior, and a prior given apart (a specification, [`parse_prior`], or Depth
/// Anything V2 weights for the experiment's prior, [`prior_with_weights`]).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ModelChoice {
    /// The experiment file whose model and prior configurations the weights were trained with.
    pub experiment: Option<PathBuf>,
    /// The run of a sweep experiment.
    pub run: Option<String>,
    /// A prior specification, replacing the experiment's prior.
    pub prior: Option<String>,
    /// Depth Anything V2 weights for the experiment's prior (or a plain one).
    pub prior_weights: Option<PathBuf>,
}

impl ModelChoice {
    /// The model configuration (the experiment's; `None`: the weights' own) and the prior.
    ///
    /// # Errors
    /// A `run` without an `experiment` (keyed `run`), the experiment's errors
    /// ([`experiment_configs`]), a prior specification that does not parse (keyed `prior`).
    pub fn configs(&self) -> Result<(Option<ModelConfig>, PriorConfig)> {
        let (model, experiment_prior) = match &self.experiment {
            Some(path) => {
                let (model, prior) = experiment_configs(path, self.run.as_deref())?;
                (Some(model), prior)
            }
            None if self.run.is_some() => {
                return Err(Error::config("run", "names a run of an experiment: give `experiment` too"));
            }
            None => (None, PriorConfig::None {}),
        };
        let prior = match (&self.prior, &self.prior_weights) {
            (Some(spec), _) => parse_prior(spec)?,
            (None, Some(weights)) => prior_with_weights(experiment_prior, weights),
            (None, None) => experiment_prior,
        };
        Ok((model, prior))
    }
}

/// A model configuration file: a `ModelConfig` TOML, or the `[model]` of an experiment file or
/// model card (its only run, [`experiment_configs`]).
///
/// # Errors
/// The file cannot be read, is not TOML, or is neither ([`Error::Io`], [`Error::Format`]).
pub fn model_config_file(path: &Path) -> Result<ModelConfig> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let table: toml::Table = toml::from_str(&text).map_err(|e| Error::format(path, format!("not TOML: {e}")))?;
    if table.contains_key("model") || table.contains_key("base") {
        return Ok(experiment_configs(path, None)?.0);
    }
    toml::from_str::<ModelConfig>(&text).map_err(|e| {
        Error::format(path, format!("neither a model configuration nor an experiment file with a [model] table: {e}"))
    })
}

/// `config` with the Depth Anything V2 `weights`: the configuration's own Depth Anything V2
/// prior (kept inside a cache) with these weights, or a plain Depth Anything V2 prior when it
/// names none.
pub fn prior_with_weights(config: PriorConfig, weights: &Path) -> PriorConfig {
    match config {
        PriorConfig::DepthAnythingV2 { encoder, input_size, .. } => {
            PriorConfig::DepthAnythingV2 { weights: weights.to_path_buf(), encoder, input_size }
        }
        PriorConfig::Cache { dir, inner } => {
            PriorConfig::Cache { dir, inner: Box::new(prior_with_weights(*inner, weights)) }
        }
        _ => PriorConfig::DepthAnythingV2 {
            weights: weights.to_path_buf(),
            encoder: None,
            input_size: DEFAULT_INPUT_SIZE,
        },
    }
}

/// Parses a byte size (the `memory_budget` option): a number with an optional `B`, `KB`/`KiB`,
/// `MB`/`MiB`, `GB`/`GiB`, `TB`/`TiB` (any case).
///
/// # Errors
/// Not a number with a known unit (keyed `memory_budget`).
pub fn parse_byte_size(s: &str) -> Result<u64> {
    let t = s.trim();
    let split = t.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let value: f64 = num.parse().map_err(|_| Error::config("memory_budget", format!("'{s}': not a size like 4GiB")))?;
    let mult: f64 = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "k" | "kb" => 1e3,
        "kib" => 1024.0,
        "m" | "mb" => 1e6,
        "mib" => 1024f64.powi(2),
        "g" | "gb" => 1e9,
        "gib" => 1024f64.powi(3),
        "t" | "tb" => 1e12,
        "tib" => 1024f64.powi(4),
        other => {
            let reason = format!("'{s}': unknown unit '{other}' (use B, MiB, GiB, ...)");
            return Err(Error::config("memory_budget", reason));
        }
    };
    Ok((value * mult) as u64)
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

    #[test]
    fn byte_sizes_parse_with_units() {
        assert_eq!(parse_byte_size("4GiB").unwrap(), 4 << 30);
        assert_eq!(parse_byte_size("512 MiB").unwrap(), 512 << 20);
        assert_eq!(parse_byte_size("1.5kb").unwrap(), 1500);
        for bad in ["lots", "3 parsecs"] {
            let e = parse_byte_size(bad).unwrap_err();
            assert!(matches!(&e, Error::Config(p) if p.key == "memory_budget" && p.reason.contains(bad)), "{e}");
        }
    }

    #[test]
    fn prior_weights_replace_the_experiments_or_make_a_prior() {
        let w = Path::new("vitb.pth");
        let cached = PriorConfig::Cache {
            dir: "cache".into(),
            inner: Box::new(PriorConfig::DepthAnythingV2 { weights: "old.pth".into(), encoder: None, input_size: 322 }),
        };
        match prior_with_weights(cached, w) {
            PriorConfig::Cache { inner, .. } => {
                assert!(
                    matches!(*inner, PriorConfig::DepthAnythingV2 { ref weights, input_size: 322, .. } if weights == w)
                )
            }
            other => panic!("{other:?}"),
        }
        assert!(matches!(
            prior_with_weights(PriorConfig::None {}, w),
            PriorConfig::DepthAnythingV2 { ref weights, input_size: DEFAULT_INPUT_SIZE, .. } if weights == w
        ));
    }

    #[test]
    fn a_model_configuration_file_is_read_or_named() {
        let dir = tempfile::tempdir().unwrap();
        let plain = dir.path().join("model.toml");
        std::fs::write(&plain, "").unwrap();
        assert_eq!(model_config_file(&plain).unwrap(), ModelConfig::default());
        std::fs::write(&plain, "nonsense = [").unwrap();
        let e = model_config_file(&plain).unwrap_err();
        assert!(
            matches!(&e, Error::Format { path, message } if path == &plain && message.starts_with("not TOML")),
            "{e}"
        );
        std::fs::write(&plain, "unknown_key = 1").unwrap();
        assert!(model_config_file(&plain).unwrap_err().to_string().contains("neither a model configuration"));
    }

    #[test]
    fn a_choice_takes_the_prior_given_apart_over_the_experiments() {
        let dir = tempfile::tempdir().unwrap();
        let experiment = dir.path().join("e.toml");
        let text = "name = \"e\"\n[model.updater]\nguidance = \"depth\"\n[prior]\nkind = \"file\"\ndir = \"priors\"\n";
        std::fs::write(&experiment, text).unwrap();
        let choice = ModelChoice { experiment: Some(experiment), ..ModelChoice::default() };
        let (model, prior) = choice.configs().unwrap();
        assert!(model.is_some_and(|m| m.needs_prior()));
        assert!(matches!(prior, PriorConfig::File { .. }), "{prior:?}");
        let spec = ModelChoice { prior: Some("none".into()), ..choice.clone() };
        assert_eq!(spec.configs().unwrap().1, PriorConfig::None {});
        let weights = ModelChoice { prior_weights: Some("w.pth".into()), ..choice };
        assert!(matches!(weights.configs().unwrap().1, PriorConfig::DepthAnythingV2 { .. }));
        let lone_run = ModelChoice { run: Some("a".into()), ..ModelChoice::default() };
        assert!(matches!(lone_run.configs().unwrap_err(), Error::Config(p) if p.key == "run"));
    }
}
