//! The experiment files of the repository: they resolve, validate, encode the paper's ablation
//! rows, and the paper's model has RAFT-Stereo's parameters plus its modules'.

use std::path::{Path, PathBuf};

use dgstereo_experiment::{ExperimentConfig, ResolvedRun, load, smoke_test, trainable_parameters};
use dgstereo_fusion::{FusionConfig, FusionTarget};
use dgstereo_loss::LossConfig;
use dgstereo_prior::PriorConfig;
use dgstereo_updater::GuidanceKind;

fn experiments_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../experiments")
}

fn toml_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for entry in std::fs::read_dir(dir).unwrap_or_else(|e| panic!("{}: {e}", dir.display())) {
        let path = entry.unwrap().path();
        if path.is_dir() {
            toml_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "toml") {
            out.push(path);
        }
    }
    out.sort();
}

fn one(relative: &str) -> ExperimentConfig {
    let path = experiments_dir().join(relative);
    let mut runs = load(&path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(runs.len(), 1, "{relative}");
    runs.remove(0).config
}

/// The modules of a row: (fusion kind, fusion target, guidance, edge-aware loss, has a prior).
fn modules(config: &ExperimentConfig) -> (&'static str, FusionTarget, GuidanceKind, bool, bool) {
    let fusion = match config.model.fusion {
        FusionConfig::None {} => "none",
        FusionConfig::Deformable { .. } => "deformable",
        FusionConfig::Conv { .. } => "conv",
    };
    let eals = matches!(config.loss, LossConfig::EdgeAware { .. });
    (fusion, config.model.fusion.target(), config.model.updater.guidance, eals, config.prior.gives_prior())
}

#[test]
fn every_file_resolves_and_validates() {
    let mut files = Vec::new();
    toml_files(&experiments_dir(), &mut files);
    assert!(files.len() >= 12, "{files:?}");
    let mut runs: Vec<ResolvedRun> = Vec::new();
    for file in &files {
        let resolved = load(file).unwrap_or_else(|e| panic!("{e}"));
        assert!(!resolved.is_empty());
        for run in &resolved {
            run.config.validate().unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            assert!(run.config.description.is_some(), "{}: give every experiment a description", file.display());
        }
        runs.extend(resolved);
    }
    let mut names: Vec<&str> = runs.iter().map(|r| r.name.as_str()).collect();
    names.sort();
    let count = names.len();
    names.dedup();
    assert_eq!(names.len(), count, "run names must be unique: {names:?}");
}

#[test]
fn the_ablation_rows_add_one_module_each() {
    use GuidanceKind::{Depth, Gradient, None};
    let both = FusionTarget::Both;
    for (prefix, rows) in [
        ("", ["baseline.toml", "+dgia.toml", "+dgia+gradient.toml", "paper.toml"]),
        ("smoke/", ["baseline.toml", "+dgia.toml", "+gradient-gru.toml", "+eals.toml"]),
    ] {
        let configs: Vec<_> = rows.iter().map(|r| one(&format!("{prefix}{r}"))).collect();
        assert_eq!(modules(&configs[0]), ("none", both, None, false, false), "{prefix}");
        assert_eq!(modules(&configs[1]), ("deformable", both, None, false, true), "{prefix}");
        assert_eq!(modules(&configs[2]), ("deformable", both, Gradient, false, true), "{prefix}");
        assert_eq!(modules(&configs[3]), ("deformable", both, Gradient, true, true), "{prefix}");
        // Everything else is shared by the rows.
        for config in &configs[1..] {
            assert_eq!(config.train, configs[0].train, "{prefix}");
            assert_eq!(config.data, configs[0].data, "{prefix}");
            assert_eq!(config.model.updater.hidden_dims, configs[0].model.updater.hidden_dims);
            assert_eq!(config.model.encoder, configs[0].model.encoder);
        }
    }
    assert_eq!(modules(&one("depth-cnn-both.toml")), ("conv", both, None, false, true));
    assert_eq!(
        modules(&one("depth-dcn-context-only.toml")),
        ("deformable", FusionTarget::ContextOnly, None, false, true)
    );
    assert_eq!(modules(&one("depth-guided-gru.toml")), ("deformable", both, Depth, false, true));
}

#[test]
fn the_paper_uses_depth_anything_v2_vitb_and_eals_at_tau_0_9() {
    let paper = one("paper.toml");
    let PriorConfig::DepthAnythingV2 { encoder, .. } = &paper.prior else { panic!("{:?}", paper.prior) };
    assert_eq!(*encoder, Some(dgstereo_prior::DepthAnythingV2Encoder::Vitb));
    assert_eq!(paper.loss, LossConfig::edge_aware());
    assert_eq!(paper.model.fusion, FusionConfig::deformable());
    // The smoke rows use the simulated prior and small models.
    let smoke = one("smoke/+eals.toml");
    assert!(matches!(smoke.prior, PriorConfig::Simulated(_)));
    assert!(smoke.model.updater.hidden_dims.iter().all(|&d| d <= 64));
}

#[test]
fn the_tau_sweep_gives_three_runs() {
    let runs = load(&experiments_dir().join("tau-sweep.toml")).unwrap();
    let taus: Vec<f64> = runs
        .iter()
        .map(|r| match r.config.loss {
            LossConfig::EdgeAware { tau, .. } => tau,
            ref other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(taus, [0.8, 0.9, 1.0]);
    assert_eq!(runs[0].name, "tau-sweep/loss.tau=0.8");
    let paper = one("paper.toml");
    for run in &runs {
        assert_eq!(run.config.model, paper.model);
        assert_eq!(run.config.train, paper.train);
    }
}

/// Parameters the paper's modules add, from their layer shapes in the paper (not from the code).
fn paper_module_parameters() -> usize {
    let conv = |cin: usize, cout: usize, k: usize| cin * cout * k * k + cout;
    // DGIA: 1x1 image 3->8, 1x1 depth 1->8, 3x3 offsets 8->18, 3x3 deformable 16->3 (one module
    // for both views).
    let dgia = conv(3, 8, 1) + conv(1, 8, 1) + conv(8, 18, 3) + conv(16, 3, 3);
    // Gradient-GRU: guidance branch 7x7 3->64 and 3x3 64->64; the motion encoder's merge conv
    // (3x3 to 126 channels) takes 64 more input channels.
    let gradient = conv(3, 64, 7) + conv(64, 64, 3) + 64 * 126 * 3 * 3;
    dgia + gradient
}

#[test]
fn the_paper_adds_about_a_tenth_of_a_million_parameters_to_raft_stereo() {
    let device = dgstereo_core::default_device();
    let count = |file: &str| trainable_parameters(&one(file).model.init(&device).unwrap());
    let baseline = count("baseline.toml");
    let paper = count("paper.toml");
    // RAFT-Stereo's count in the official code (shared/reference facts, section 1.8).
    assert_eq!(baseline, 11_116_176);
    assert_eq!(paper - baseline, paper_module_parameters());
    let added = (paper - baseline) as f64 / 1e6;
    assert!((0.05..0.2).contains(&added), "{added} M");
    // The depth-guided GRU differs only in the 1-channel input of the guidance branch.
    let depth = count("depth-guided-gru.toml");
    assert_eq!(paper - depth, 2 * 64 * 7 * 7);
}

#[test]
fn smoke_files_build_and_run() {
    let device = dgstereo_core::default_device();
    let mut files = Vec::new();
    toml_files(&experiments_dir().join("smoke"), &mut files);
    // The four rows of the smoke ablation and the two of the three-seed study (seeds/).
    assert_eq!(files.len(), 6);
    let mut counts = Vec::new();
    for file in files {
        for run in load(&file).unwrap() {
            let report = smoke_test(&run.config, [40, 72], 2, &device).unwrap_or_else(|e| panic!("{}: {e}", run.name));
            assert_eq!(report.iterations, 2);
            assert!(report.max_abs_disparity.is_finite());
            counts.push((run.name, report.parameters));
        }
    }
    // The smoke models are a fraction of RAFT-Stereo's size.
    assert!(counts.iter().all(|(_, n)| *n < 11_116_176), "{counts:?}");
}
