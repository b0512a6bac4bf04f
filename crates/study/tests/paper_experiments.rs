//! The experiments folder against the paper's tables: the paper's run trains with its batch and
//! scores the benchmarks its columns read, and every row of the tables is a run of the folder.

use std::path::{Path, PathBuf};

use dgstereo_experiment::{ExperimentConfig, load};

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

#[test]
fn the_paper_trains_with_batch_4_and_scores_its_seven_columns() {
    use dgstereo_eval::DatasetKind;
    use dgstereo_study::paper_tables::GENERALISATION_COLUMNS;
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
    let matches = dgstereo_study::paper_match::match_benchmarks(&paper.benchmarks);
    assert!(matches.iter().all(|m| m.found.is_some() && m.differences().is_empty()), "{matches:?}");
    let columns: Vec<(&str, &str)> = GENERALISATION_COLUMNS
        .iter()
        .map(|c| (dgstereo_study::paper_match::label_for(&matches, c.benchmark).unwrap_or("-"), c.metric))
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
    for table in &dgstereo_study::paper_tables::PAPER_TABLES {
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

#[test]
fn runs_are_placed_in_table1_by_their_network() {
    use dgstereo_study::paper_table1::table1_model;
    let model = |file: &str| table1_model(&one(file)).map(|r| r.method);
    assert_eq!(model("zoo/defom-vits.toml"), Some("DEFOM-Stereo"));
    assert_eq!(model("zoo/defom-vits-train.toml"), Some("DEFOM-Stereo"));
    assert_eq!(model("zoo/defom-vitl.toml"), Some("DEFOM-Stereo"));
    assert_eq!(model("zoo/igev.toml"), Some("IGEV-Stereo"));
    assert_eq!(model("baseline.toml"), Some("RAFT-Stereo"));
    assert_eq!(model("paper.toml"), Some("paper's model"));
    // Ablation rows that are none of the table's models.
    assert_eq!(model("depth-guided-gru.toml"), None);
    assert_eq!(model("+dgia.toml"), None);
}
