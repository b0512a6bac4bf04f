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

#[test]
fn the_paper_trains_with_batch_4_and_scores_its_seven_columns() {
    use dgstereo_eval::DatasetKind;
    use dgstereo_train::paper_tables::GENERALISATION_COLUMNS;
    let paper = one("paper.toml");
    assert_eq!(paper.train.batch_size, 4, "the paper: \"we set batch size to 4\"");
    let benchmarks: Vec<(&str, DatasetKind, Option<&str>, Option<&str>)> = paper
        .benchmarks
        .iter()
        .map(|b| (b.label(), b.dataset, b.split.map(|s| s.name()), b.weather.map(|w| w.name())))
        .collect();
    use DatasetKind::{Drivingstereo, Eth3d, Kitti2015, Middlebury};
    assert_eq!(
        benchmarks,
        [
            ("middlebury-h", Middlebury, Some("H"), None),
            ("drivingstereo-sunny", Drivingstereo, None, Some("sunny")),
            ("drivingstereo-cloudy", Drivingstereo, None, Some("cloudy")),
            ("drivingstereo-foggy", Drivingstereo, None, Some("foggy")),
            ("drivingstereo-rainy", Drivingstereo, None, Some("rainy")),
            ("kitti2015", Kitti2015, None, None),
            ("eth3d", Eth3d, None, None),
        ]
    );
    // The paper's tables read these benchmarks (each matched by its data set), in this order,
    // with the metrics they show, as the paper scores them.
    let matches = dgstereo_train::paper_match::match_benchmarks(&paper.benchmarks);
    assert!(matches.iter().all(|m| m.found.is_some() && m.differences().is_empty()), "{matches:?}");
    let columns: Vec<(&str, &str)> = GENERALISATION_COLUMNS
        .iter()
        .map(|c| (dgstereo_train::paper_match::label_for(&matches, c.benchmark).unwrap_or("-"), c.metric))
        .collect();
    let shown: Vec<(&str, &str)> =
        paper.benchmarks.iter().flat_map(|b| b.table_metrics().into_iter().map(move |m| (b.label(), m))).collect();
    let shown_in_paper: Vec<(&str, &str)> = shown.into_iter().filter(|(_, m)| *m != "d1-all").collect();
    assert_eq!(shown_in_paper, columns);
    assert!(paper.benchmarks.iter().all(|b| b.iters == 32));
    // The resolved file (what a run folder keeps) loads back with its splits and weathers.
    let dir = tempfile::tempdir().unwrap();
    let resolved = dir.path().join("paper.toml");
    std::fs::write(&resolved, paper.to_toml()).unwrap();
    assert_eq!(load(&resolved).unwrap()[0].config, paper);
    // Every row inherits the benchmarks.
    for file in ["baseline.toml", "+dgia.toml", "depth-guided-gru.toml"] {
        assert_eq!(one(file).benchmarks, paper.benchmarks, "{file}");
    }
}

#[test]
fn every_row_of_the_papers_tables_is_a_run_of_the_folder() {
    let mut files = Vec::new();
    toml_files(&experiments_dir(), &mut files);
    let runs: Vec<String> = files.iter().flat_map(|f| load(f).unwrap()).map(|r| r.name).collect();
    for table in &dgstereo_train::paper_tables::PAPER_TABLES {
        for row in table.rows {
            assert!(
                runs.iter().any(|r| r == row.run),
                "Table {} row {}: no run '{}'",
                table.number,
                row.label,
                row.run
            );
        }
    }
}
