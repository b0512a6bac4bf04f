//! The paper's Table 1 from a study's runs: each run of a model the table has a row for, beside
//! that model's published zero-shot figures.
//!
//! Design decision: Table 1 compares models, not ablation rows, so a run is placed by its network
//! ([`table1_model`]), never by its name: DEFOM-Stereo is a network with a monocular network and
//! the scale update, IGEV-Stereo one with the geometry encoding volume, the paper's model one with
//! DGIA's deformable fusion and the gradient guidance, RAFT-Stereo one with none of these (the
//! stage variants that make the others). Every
//! such run is a row of its own (method, run), so two recipes or checkpoints of one model are two
//! rows beside the same published figures. The figures are `dgstereo_eval::published`'s (the one
//! copy `eval` also prints), the columns Tables 3 to 5's, which are Table 1's.

use dgstereo_eval::published::{TABLE1, TABLE1_SOURCE, Table1Row};
use dgstereo_experiment::ExperimentConfig;

use crate::paper_match::BenchmarkMatch;
use crate::paper_report::{ComparedRow, PaperComparison, RunScores};
use crate::paper_tables::GENERALISATION_COLUMNS;

/// The row of Table 1 whose method is `method`.
fn method(method: &str) -> Option<&'static Table1Row> {
    TABLE1.iter().find(|r| r.method == method)
}

/// The row of Table 1 whose model the network of `config` is, if any (see the module doc).
/// The other rows' networks (Selective-IGEV, MonSter, ...) are not in the workspace, so no run
/// is theirs.
pub fn table1_model(config: &ExperimentConfig) -> Option<&'static Table1Row> {
    let m = &config.model;
    let monocular = m.monocular.feature_channels().is_some();
    let scale_update = m.updater.scale_update.is_some();
    let geometry = m.correlation.geometry.is_some();
    if monocular && scale_update && !geometry {
        return method("DEFOM-Stereo");
    }
    if geometry && !monocular && !scale_update && m.fusion.kind() == "none" {
        return method("IGEV-Stereo");
    }
    if geometry || monocular || scale_update || m.initial_disparity.needs_monocular() {
        return None;
    }
    match (m.fusion.kind(), m.updater.guidance.name()) {
        ("deformable", "gradient") => method("paper's model"),
        ("none", "none") => method("RAFT-Stereo"),
        _ => None,
    }
}

/// `row`'s published figures in the column order of [`GENERALISATION_COLUMNS`] (EPE and the
/// data set's rate, for each of [`dgstereo_eval::published::PaperBenchmark::ALL`]).
pub fn published_figures(row: &Table1Row) -> Vec<f64> {
    row.figures.iter().flat_map(|&(epe, rate)| [epe, rate]).collect()
}

/// Table 1 with one row per `(run, model)` of `models` (a study's rows, each with the Table 1
/// row of its network: [`table1_model`]), filled from `runs` and the benchmarks `matches`
/// gives the columns; `None` when no run is one of the table's models.
pub fn table1_comparison(
    models: &[(String, &'static Table1Row)],
    runs: &[RunScores],
    matches: &[BenchmarkMatch],
) -> Option<PaperComparison> {
    if models.is_empty() {
        return None;
    }
    let rows = models
        .iter()
        .map(|(run, row)| ComparedRow { label: row.method.into(), run: run.clone(), published: published_figures(row) })
        .collect();
    let title = "zero-shot generalisation of the models trained on SceneFlow";
    Some(PaperComparison::filled(1, title, TABLE1_SOURCE, &GENERALISATION_COLUMNS, rows, runs, matches))
}

#[cfg(test)]
mod tests {
    use super::*;
    use dgstereo_eval::published::PaperBenchmark;

    /// Table 1's figures pair with the columns: column `2i` is EPE of data set `i`, column
    /// `2i + 1` the rate the table reports for it.
    #[test]
    fn the_published_figures_follow_the_columns() {
        assert_eq!(GENERALISATION_COLUMNS.len(), 2 * PaperBenchmark::ALL.len());
        for (i, b) in PaperBenchmark::ALL.into_iter().enumerate() {
            let (epe, rate) = (GENERALISATION_COLUMNS[2 * i], GENERALISATION_COLUMNS[2 * i + 1]);
            assert_eq!((epe.benchmark, epe.metric), (b, "epe"));
            assert_eq!((rate.benchmark, rate.metric, rate.metric_heading), (b, b.rate().0, b.rate().1));
            assert_eq!(epe.heading, b.heading());
        }
        let defom = method("DEFOM-Stereo").unwrap();
        let figures = published_figures(defom);
        assert_eq!((figures[0], figures[1], figures[13]), (0.84, 6.03, 2.38));
    }
}
