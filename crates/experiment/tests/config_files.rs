//! Experiment files: inheritance, sweeps, round trips, and errors that name the file and the key.

use std::path::{Path, PathBuf};

use dgstereo_experiment::{ExperimentConfig, load};
use dgstereo_fusion::{FusionConfig, FusionTarget};
use dgstereo_loss::LossConfig;
use dgstereo_prior::PriorConfig;
use dgstereo_updater::GuidanceKind;

/// A folder of experiment files written from `(name, text)` pairs.
struct Files {
    dir: tempfile::TempDir,
}

impl Files {
    fn new(files: &[(&str, &str)]) -> Self {
        let dir = tempfile::tempdir().expect("temp dir");
        for (name, text) in files {
            let path = dir.path().join(name);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(path, text).unwrap();
        }
        Self { dir }
    }

    fn path(&self, name: &str) -> PathBuf {
        self.dir.path().join(name)
    }

    /// The error message of loading `name`, which must fail.
    fn error(&self, name: &str) -> String {
        match load(&self.path(name)) {
            Ok(runs) => panic!("{name} loaded: {:?}", runs.iter().map(|r| &r.name).collect::<Vec<_>>()),
            Err(e) => e.to_string(),
        }
    }

    fn one(&self, name: &str) -> ExperimentConfig {
        let mut runs = load(&self.path(name)).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(runs.len(), 1);
        runs.remove(0).config
    }
}

/// Asserts that `message` names `file` (as a path ending) and `key`.
fn names(message: &str, file: &str, key: &str) {
    let file_named = message.split(':').next().is_some_and(|first| Path::new(first.trim()).ends_with(file));
    assert!(file_named, "the message does not start with the file {file}: {message}");
    assert!(message.contains(key), "the message does not name the key {key}: {message}");
}

const PAPER_LIKE: &str = r#"
name = "main"
description = "fusion, guidance, EALS"
[model.fusion]
kind = "deformable"
[model.updater]
guidance = "gradient"
hidden_dims = [64, 64, 64]
[prior]
kind = "simulated"
[loss]
kind = "edge-aware"
tau = 0.7
[train]
steps = 10
"#;

#[test]
fn an_empty_file_is_raft_stereo_with_every_default() {
    let files = Files::new(&[("empty.toml", "")]);
    let config = files.one("empty.toml");
    assert_eq!(config.name, "empty");
    assert_eq!(config.description, None);
    assert_eq!(config.model, Default::default());
    assert_eq!(config.prior, PriorConfig::None {});
    assert_eq!(config.loss, LossConfig::default());
    assert_eq!(config.train, Default::default());
}

#[test]
fn inheritance_merges_tables_and_the_child_wins() {
    let files = Files::new(&[
        ("main.toml", PAPER_LIKE),
        (
            "sub/child.toml",
            r#"
base = "../main.toml"
[model.updater]
guidance = "depth"
[loss]
gamma = 0.8
"#,
        ),
    ]);
    let config = files.one("sub/child.toml");
    // name and description are the file's own.
    assert_eq!(config.name, "child");
    assert_eq!(config.description, None);
    assert_eq!(config.model.updater.guidance, GuidanceKind::Depth);
    // Untouched keys of a merged table survive.
    assert_eq!(config.model.updater.hidden_dims, [64, 64, 64]);
    assert_eq!(config.model.fusion, FusionConfig::deformable());
    assert_eq!(config.loss, LossConfig::EdgeAware { tau: 0.7, gamma: 0.8, max_disparity: 700.0 });
    assert_eq!(config.train.steps, 10);
}

#[test]
fn chains_of_bases_are_followed() {
    let files = Files::new(&[
        ("a.toml", PAPER_LIKE),
        ("b.toml", "base = \"a.toml\"\n[train]\nsteps = 20\n"),
        ("c.toml", "base = \"b.toml\"\nname = \"third\"\n[train]\nbatch_size = 3\n"),
    ]);
    let config = files.one("c.toml");
    assert_eq!(config.name, "third");
    assert_eq!((config.train.steps, config.train.batch_size), (20, 3));
    assert_eq!(config.model.updater.guidance, GuidanceKind::Gradient);
}

#[test]
fn a_new_kind_replaces_the_whole_table() {
    let files = Files::new(&[
        ("main.toml", PAPER_LIKE),
        (
            "plain.toml",
            r#"
base = "main.toml"
[loss]
kind = "sequence-l1"
[model.fusion]
kind = "conv"
target = "context-only"
"#,
        ),
    ]);
    // `tau` of the edge-aware loss is not carried into the sequence loss (it would be unknown).
    let config = files.one("plain.toml");
    assert_eq!(config.loss, LossConfig::default());
    assert_eq!(config.model.fusion, FusionConfig::Conv { target: FusionTarget::ContextOnly, features: 8 });
}

#[test]
fn sweeps_expand_to_the_cartesian_product() {
    let files = Files::new(&[
        ("main.toml", PAPER_LIKE),
        (
            "sweep.toml",
            r#"
base = "main.toml"
name = "grid"
[sweep]
"loss.tau" = [0.8, 1.0]
"model.fusion.target" = ["both", "context-only"]
"loss.gamma" = [0.9]
"#,
        ),
    ]);
    let runs = load(&files.path("sweep.toml")).unwrap();
    let names: Vec<&str> = runs.iter().map(|r| r.name.as_str()).collect();
    assert_eq!(
        names,
        [
            "grid/loss.gamma=0.9,loss.tau=0.8,model.fusion.target=both",
            "grid/loss.gamma=0.9,loss.tau=0.8,model.fusion.target=context-only",
            "grid/loss.gamma=0.9,loss.tau=1.0,model.fusion.target=both",
            "grid/loss.gamma=0.9,loss.tau=1.0,model.fusion.target=context-only",
        ]
    );
    for run in &runs {
        assert_eq!(run.config.name, run.name);
        assert_eq!(run.source, files.path("sweep.toml"));
        let LossConfig::EdgeAware { tau, gamma, .. } = run.config.loss else { panic!("{:?}", run.config.loss) };
        assert!(run.name.contains(&format!("loss.tau={tau:?}")), "{} vs {tau}", run.name);
        assert_eq!(gamma, 0.9);
        let target = match run.config.model.fusion.target() {
            FusionTarget::Both => "both",
            FusionTarget::ContextOnly => "context-only",
        };
        assert!(run.name.ends_with(&format!("target={target}")), "{}", run.name);
    }
}

#[test]
fn a_sweep_may_name_a_key_that_only_the_defaults_hold() {
    // `loss.max_disparity` is written by no file: it exists through the loss's default.
    let files = Files::new(&[("s.toml", &format!("{PAPER_LIKE}\n[sweep]\n\"loss.max_disparity\" = [192.0, 700.0]\n"))]);
    let runs = load(&files.path("s.toml")).unwrap();
    let limits: Vec<f64> = runs
        .iter()
        .map(|r| match r.config.loss {
            LossConfig::EdgeAware { max_disparity, .. } => max_disparity,
            _ => panic!(),
        })
        .collect();
    assert_eq!(limits, [192.0, 700.0]);
}

#[test]
fn the_resolved_toml_loads_back_to_the_same_configuration() {
    let files = Files::new(&[
        ("main.toml", PAPER_LIKE),
        ("sweep.toml", "base = \"main.toml\"\n[sweep]\n\"loss.tau\" = [0.8, 1.0]\n"),
    ]);
    for run in load(&files.path("sweep.toml")).unwrap() {
        let text = run.config.to_toml();
        // Every section is written out in full.
        for section in ["[model.updater]", "[model.correlation]", "[prior]", "[loss]", "[train]", "[data]"] {
            assert!(text.contains(section), "{section} missing from\n{text}");
        }
        let written = files.path("resolved.toml");
        std::fs::write(&written, &text).unwrap();
        let again = load(&written).unwrap_or_else(|e| panic!("{e}\n{text}"));
        assert_eq!(again.len(), 1);
        assert_eq!(again[0].config, run.config);
    }
}

#[test]
fn unknown_keys_name_the_file_and_the_key() {
    let files = Files::new(&[
        ("main.toml", PAPER_LIKE),
        ("top.toml", "modle = 3\n"),
        ("loss.toml", "base = \"main.toml\"\n[loss]\ntaux = 0.9\n"),
        ("nested.toml", "[model.updater]\nhidden_dim = [1, 2, 3]\n"),
        // Keys beside a kind without fields.
        ("none.toml", "[prior]\nkind = \"none\"\nweights = \"x.pth\"\n"),
        ("fusion.toml", "[model.fusion]\nkind = \"none\"\ntarget = \"both\"\n"),
        ("bad_base.toml", "[loss]\nkind = \"edge-aware\"\ntua = 1.0\n"),
        ("child.toml", "base = \"bad_base.toml\"\n"),
    ]);
    names(&files.error("top.toml"), "top.toml", "modle");
    names(&files.error("loss.toml"), "loss.toml", "loss.taux");
    names(&files.error("nested.toml"), "nested.toml", "model.updater.hidden_dim");
    names(&files.error("none.toml"), "none.toml", "prior.weights");
    names(&files.error("fusion.toml"), "fusion.toml", "model.fusion.target");
    // The key is reported against the base file that wrote it.
    names(&files.error("child.toml"), "bad_base.toml", "loss.tua");
}

/// The encoder layout is one key: a file that names it by `shared_backbone` or
/// `feature_network` is refused by that key, and the message names `layout`, the key to write.
#[test]
fn the_encoder_layout_is_one_key() {
    let files = Files::new(&[
        ("shared.toml", "[model.encoder]\nshared_backbone = true\n"),
        ("pyramid.toml", "[model.encoder]\nfeature_network = \"mobilenet-pyramid\"\n"),
        ("layout.toml", "[model.encoder]\nlayout = \"shared-backbone\"\n"),
    ]);
    for (name, key) in
        [("shared.toml", "model.encoder.shared_backbone"), ("pyramid.toml", "model.encoder.feature_network")]
    {
        let message = files.error(name);
        names(&message, name, key);
        assert!(message.contains("`layout`"), "{message}");
    }
    let layout = files.one("layout.toml").model.encoder.layout;
    assert_eq!(layout, dgstereo_model::encoder::EncoderLayout::SharedBackbone);
}

#[test]
fn missing_keys_and_wrong_types_name_the_file_and_the_key() {
    let files = Files::new(&[
        ("no_weights.toml", "[model.fusion]\nkind = \"deformable\"\n[prior]\nkind = \"depth-anything-v2\"\n"),
        ("no_kind.toml", "[loss]\ntau = 0.9\n"),
        ("bad_kind.toml", "[loss]\nkind = \"edgy\"\n"),
        ("type.toml", "[train]\nsteps = \"many\"\n"),
        ("array.toml", "[model.updater]\nhidden_dims = [1, 2]\n"),
        ("name.toml", "name = 3\n"),
        ("base_type.toml", "base = 3\n"),
        ("syntax.toml", "[loss\nkind = 1\n"),
        ("tagged_type.toml", "[loss]\nkind = \"edge-aware\"\ntau = \"0.8\"\n"),
        ("flattened_type.toml", "[data.validation]\ncount = 2\nwidth = \"wide\"\n"),
        ("source_type.toml", "[[data.sources]]\nkind = \"synthetic\"\nheight = \"tall\"\n"),
    ]);
    names(&files.error("no_weights.toml"), "no_weights.toml", "prior.weights");
    names(&files.error("no_kind.toml"), "no_kind.toml", "kind");
    names(&files.error("no_kind.toml"), "no_kind.toml", "loss");
    names(&files.error("bad_kind.toml"), "bad_kind.toml", "loss.kind");
    names(&files.error("type.toml"), "type.toml", "train.steps");
    names(&files.error("array.toml"), "array.toml", "model.updater.hidden_dims");
    names(&files.error("name.toml"), "name.toml", "name");
    names(&files.error("base_type.toml"), "base_type.toml", "base");
    names(&files.error("syntax.toml"), "syntax.toml", "TOML");
    // Inside a table serde reads as a whole (a tagged `kind`, flattened scene keys), the key
    // named is the one holding the value, not the table's first key.
    names(&files.error("tagged_type.toml"), "tagged_type.toml", "loss.tau");
    names(&files.error("flattened_type.toml"), "flattened_type.toml", "data.validation.width");
    let message = files.error("source_type.toml");
    names(&message, "source_type.toml", "data.sources");
    assert!(message.contains("tall"), "{message}");
}

#[test]
fn missing_files_bases_and_cycles_are_errors() {
    let files = Files::new(&[
        ("orphan.toml", "base = \"nowhere.toml\"\n"),
        ("a.toml", "base = \"b.toml\"\n"),
        ("b.toml", "base = \"c.toml\"\n"),
        ("c.toml", "base = \"a.toml\"\n"),
        ("me.toml", "base = \"me.toml\"\n"),
    ]);
    let message = files.error("orphan.toml");
    names(&message, "orphan.toml", "base");
    assert!(message.contains("nowhere.toml"), "{message}");
    let message = files.error("a.toml");
    assert!(message.contains("cycle"), "{message}");
    for file in ["a.toml", "b.toml", "c.toml"] {
        assert!(message.contains(file), "{message}");
    }
    assert!(files.error("me.toml").contains("cycle"));
    assert!(files.error("absent.toml").contains("absent.toml"));
}

#[test]
fn sweep_errors_name_the_file_and_the_key() {
    let files = Files::new(&[
        ("main.toml", PAPER_LIKE),
        ("unknown.toml", "base = \"main.toml\"\n[sweep]\n\"loss.taux\" = [0.8]\n"),
        ("deep.toml", "base = \"main.toml\"\n[sweep]\n\"loss.tau.x\" = [0.8]\n"),
        ("empty.toml", "base = \"main.toml\"\n[sweep]\n\"loss.tau\" = []\n"),
        ("scalar.toml", "base = \"main.toml\"\n[sweep]\n\"loss.tau\" = 0.8\n"),
        ("reserved.toml", "base = \"main.toml\"\n[sweep]\n\"name\" = [\"a\", \"b\"]\n"),
        ("type.toml", "base = \"main.toml\"\n[sweep]\n\"train.steps\" = [1, \"two\"]\n"),
        ("invalid.toml", "base = \"main.toml\"\n[sweep]\n\"loss.tau\" = [0.5, -1.0]\n"),
        ("child.toml", "base = \"unknown.toml\"\n"),
    ]);
    let message = files.error("unknown.toml");
    names(&message, "unknown.toml", "loss.taux");
    assert!(message.contains("tau"), "the known keys are listed: {message}");
    names(&files.error("deep.toml"), "deep.toml", "loss.tau.x");
    names(&files.error("empty.toml"), "empty.toml", "loss.tau");
    names(&files.error("scalar.toml"), "scalar.toml", "loss.tau");
    names(&files.error("reserved.toml"), "reserved.toml", "name");
    names(&files.error("type.toml"), "type.toml", "train.steps");
    names(&files.error("invalid.toml"), "invalid.toml", "loss.tau");
    // A sweep inherited from a base is reported against the base.
    names(&files.error("child.toml"), "unknown.toml", "loss.taux");
}

#[test]
fn nonsense_combinations_name_the_file_and_the_key() {
    let files = Files::new(&[
        ("main.toml", PAPER_LIKE),
        ("guidance.toml", "[model.updater]\nguidance = \"gradient\"\n"),
        ("depth.toml", "[model.updater]\nguidance = \"depth\"\n"),
        ("fusion.toml", "[model.fusion]\nkind = \"conv\"\n"),
        ("unused.toml", "[prior]\nkind = \"simulated\"\n"),
        // Dropping the prior of a base that uses it is reported against the dropping file.
        ("dropped.toml", "base = \"main.toml\"\n[prior]\nkind = \"none\"\n"),
        (
            "cache.toml",
            "[model.fusion]\nkind = \"conv\"\n[prior]\nkind = \"cache\"\ndir = \"c\"\n[prior.inner]\nkind = \"none\"\n",
        ),
    ]);
    names(&files.error("guidance.toml"), "guidance.toml", "model.updater.guidance");
    names(&files.error("depth.toml"), "depth.toml", "model.updater.guidance");
    names(&files.error("fusion.toml"), "fusion.toml", "model.fusion.kind");
    names(&files.error("unused.toml"), "unused.toml", "prior.kind");
    let message = files.error("dropped.toml");
    assert!(message.contains("model.fusion.kind") || message.contains("model.updater.guidance"), "{message}");
    names(&files.error("cache.toml"), "cache.toml", "prior.inner.kind");
}

#[test]
fn invalid_values_name_the_file_and_the_key() {
    let files = Files::new(&[
        ("main.toml", PAPER_LIKE),
        ("layers.toml", "[model.updater]\nn_gru_layers = 4\n"),
        ("features.toml", "base = \"main.toml\"\n[model.fusion]\nfeatures = 2\n"),
        ("gamma.toml", "[loss]\nkind = \"sequence-l1\"\ngamma = 1.5\n"),
        ("lr.toml", "base = \"main.toml\"\n[train]\nlr = 0.0\n"),
        ("prior.toml", "base = \"main.toml\"\n[prior]\nscale = [2.0, 1.0]\n"),
        ("name.toml", "name = \"a b\"\n"),
        ("dots.toml", "name = \"../escape\"\n"),
        ("crop.toml", "[model.updater]\nn_downsample = 3\n[train]\ncrop = [320, 724]\n"),
    ]);
    names(&files.error("layers.toml"), "layers.toml", "model.updater.n_gru_layers");
    names(&files.error("features.toml"), "features.toml", "model.fusion.features");
    names(&files.error("gamma.toml"), "gamma.toml", "loss.gamma");
    names(&files.error("lr.toml"), "lr.toml", "train.lr");
    names(&files.error("prior.toml"), "prior.toml", "prior.scale");
    names(&files.error("name.toml"), "name.toml", "name");
    names(&files.error("dots.toml"), "dots.toml", "name");
    names(&files.error("crop.toml"), "crop.toml", "train.crop");
    // `validate` reports the same without a file.
    let mut config = files.one("main.toml");
    config.loss = LossConfig::EdgeAware { tau: -1.0, gamma: 0.9, max_disparity: 700.0 };
    let message = config.validate().unwrap_err().to_string();
    assert!(message.contains("loss.tau"), "{message}");
    assert!(files.one("main.toml").validate().is_ok());
}

#[test]
fn checkpoint_paths_need_not_exist_to_validate() {
    let files = Files::new(&[(
        "dav2.toml",
        "[model.updater]\nguidance = \"gradient\"\n[prior]\nkind = \"depth-anything-v2\"\nweights = \"no/such/file.pth\"\n",
    )]);
    let config = files.one("dav2.toml");
    assert!(matches!(config.prior, PriorConfig::DepthAnythingV2 { .. }));
    // Building the provider is where the file must exist.
    let device = dgstereo_core::default_device();
    assert!(config.prior.init(&device).is_err());
}

#[test]
fn benchmark_options_belong_to_their_data_set() {
    let files = Files::new(&[
        (
            "wrong.toml",
            "name = \"wrong\"\n[[benchmarks]]\nname = \"k\"\ndataset = \"kitti2015\"\nroot = \"x\"\nweather = \"sunny\"\n",
        ),
        (
            "right.toml",
            "name = \"right\"\n[[benchmarks]]\ndataset = \"middlebury\"\nroot = \"MiddEval3\"\nsplit = \"H\"\n",
        ),
        (
            "typo.toml",
            "name = \"typo\"\n[[benchmarks]]\ndataset = \"drivingstereo\"\nroot = \"x\"\nweather = \"snowy\"\n",
        ),
    ]);
    let message = files.error("wrong.toml");
    names(&message, "wrong.toml", "benchmarks[0].weather");
    assert!(message.contains("drivingstereo"), "{message}");
    assert_eq!(files.one("right.toml").benchmarks[0].split.map(|s| s.name()), Some("H"));
    let message = files.error("typo.toml");
    names(&message, "typo.toml", "benchmarks");
    assert!(message.contains("snowy") && message.contains("rainy"), "{message}");
}
