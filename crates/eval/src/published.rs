//! The published zero-shot figures of the paper's Table 1, so that `eval` of a model the table
//! has a row for prints the paper's figure beside ours.
//!
//! Source: Lin et al., "Rethinking Monocular Depth Embedding for Generalized Stereo Matching",
//! Table 1 (copied from `shared/reference/paper-tables.md`, which transcribes it): every model
//! trained on SceneFlow only, evaluated zero-shot with 32 iterations on complete disparity maps;
//! EPE in pixels, D1/D2/D3 the percentage of pixels whose error exceeds 1/2/3 px.
//!
//! Design decision: a row is found by the checkpoint that is the row's model (the official
//! SceneFlow-only weights, by their catalog names: [`Table1Row::checkpoints`]), never by the
//! architecture alone, since a fine-tuned checkpoint of the same network is no zero-shot figure;
//! a column by what a benchmark scores (data set kind and split or weather,
//! [`PaperBenchmark::matches`]), never by its name. A benchmark scored otherwise than the paper
//! (other iterations, a sample limit, a size limit) still shows the figure, saying how it differs.

use dgstereo_data::datasets::{DrivingStereoWeather, MiddleburySplit};

use crate::benchmark::{BenchmarkConfig, DatasetKind};
use crate::table::EvalTable;

/// Where the figures come from, for the lines that quote them.
pub const TABLE1_SOURCE: &str = "Lin et al., \"Rethinking Monocular Depth Embedding for Generalized Stereo Matching\", \
     Table 1 (trained on SceneFlow only, zero-shot, 32 iterations)";

/// The iterations of every figure of the table.
pub const TABLE1_ITERATIONS: usize = 32;

/// One of the table's data sets: a data set kind and the split or weather that selects it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PaperBenchmark {
    /// Middlebury's MiddEval3 training set at half resolution (`middlebury`, split `H`).
    MiddleburyH,
    /// One weather of DrivingStereo (`drivingstereo`, `weather`).
    DrivingStereo(DrivingStereoWeather),
    /// KITTI 2015's training set (`kitti2015`).
    Kitti2015,
    /// ETH3D's two-view training set (`eth3d`).
    Eth3d,
}

impl PaperBenchmark {
    /// The table's data sets in its column order.
    pub const ALL: [Self; 7] = [
        Self::MiddleburyH,
        Self::DrivingStereo(DrivingStereoWeather::Sunny),
        Self::DrivingStereo(DrivingStereoWeather::Cloudy),
        Self::DrivingStereo(DrivingStereoWeather::Foggy),
        Self::DrivingStereo(DrivingStereoWeather::Rainy),
        Self::Kitti2015,
        Self::Eth3d,
    ];

    /// Whether `benchmark` scores this data set (a DrivingStereo benchmark without a weather
    /// scores every weather, each a group of its table).
    pub fn matches(self, benchmark: &BenchmarkConfig) -> bool {
        match self {
            Self::MiddleburyH => {
                benchmark.dataset == DatasetKind::Middlebury && benchmark.split == Some(MiddleburySplit::H)
            }
            Self::DrivingStereo(weather) => {
                benchmark.dataset == DatasetKind::Drivingstereo && benchmark.weather.is_none_or(|w| w == weather)
            }
            Self::Kitti2015 => benchmark.dataset == DatasetKind::Kitti2015,
            Self::Eth3d => benchmark.dataset == DatasetKind::Eth3d,
        }
    }

    /// Whether `benchmark` scores this data set and nothing else, so that its aggregate is this
    /// data set's figure: as [`matches`](Self::matches), but a DrivingStereo benchmark must name
    /// this weather (a study keeps one aggregate per benchmark, which for all weathers together
    /// is none of the table's columns).
    pub fn matches_alone(self, benchmark: &BenchmarkConfig) -> bool {
        let whole_set = !matches!(self, Self::DrivingStereo(_)) || benchmark.weather.is_some();
        whole_set && self.matches(benchmark)
    }

    /// The `[[benchmarks]]` keys that select it alone (`dataset = "middlebury", split = "H"`).
    pub fn keys(self) -> String {
        match self {
            Self::MiddleburyH => "dataset = \"middlebury\", split = \"H\"".to_string(),
            Self::DrivingStereo(weather) => format!("dataset = \"drivingstereo\", weather = \"{weather}\""),
            Self::Kitti2015 => "dataset = \"kitti2015\"".to_string(),
            Self::Eth3d => "dataset = \"eth3d\"".to_string(),
        }
    }

    /// Its heading in the paper (`Midd-H`, `DS-Sunny`, ...).
    pub const fn heading(self) -> &'static str {
        match self {
            Self::MiddleburyH => "Midd-H",
            Self::DrivingStereo(DrivingStereoWeather::Sunny) => "DS-Sunny",
            Self::DrivingStereo(DrivingStereoWeather::Cloudy) => "DS-Cloudy",
            Self::DrivingStereo(DrivingStereoWeather::Foggy) => "DS-Foggy",
            Self::DrivingStereo(DrivingStereoWeather::Rainy) => "DS-Rainy",
            Self::Kitti2015 => "KITTI15",
            Self::Eth3d => "ETH3D",
        }
    }

    /// The bad-pixel rate the table reports beside EPE: our metric's name and the paper's heading.
    pub const fn rate(self) -> (&'static str, &'static str) {
        match self {
            Self::MiddleburyH => ("bad-2", "D2"),
            Self::DrivingStereo(_) | Self::Kitti2015 => ("bad-3", "D3"),
            Self::Eth3d => ("bad-1", "D1"),
        }
    }

    /// The aggregate row of an evaluation table that holds this data set's figures: a weather's
    /// group for DrivingStereo (`all` where the benchmark scored that weather alone), else `all`.
    fn aggregate_label(self, benchmark: &BenchmarkConfig) -> &'static str {
        match self {
            Self::DrivingStereo(weather) if benchmark.weather.is_none() => weather.name(),
            _ => "all",
        }
    }
}

/// A row of Table 1: the method, the checkpoints that are its model, its figures.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Table1Row {
    /// The row's label in the paper.
    pub method: &'static str,
    /// The catalog names of the official checkpoints trained on SceneFlow only that are this
    /// row's model (empty where the workspace has none). The paper does not say which DEFOM-Stereo
    /// encoder it ran; both SceneFlow checkpoints are listed (its 47.3 M parameters are nearer
    /// ViT-S's 43.3 M than ViT-L's).
    pub checkpoints: &'static [&'static str],
    /// `(EPE, rate)` per data set, in [`PaperBenchmark::ALL`]'s order.
    pub figures: [(f64, f64); 7],
}

/// Table 1, in the paper's row order.
pub const TABLE1: [Table1Row; 7] = [
    Table1Row {
        method: "RAFT-Stereo",
        checkpoints: &["raftstereo-sceneflow"],
        figures: [(1.43, 11.21), (1.89, 9.87), (1.89, 10.30), (1.93, 13.64), (4.31, 29.44), (1.13, 5.68), (0.27, 2.61)],
    },
    Table1Row {
        method: "IGEV-Stereo",
        checkpoints: &["igev-stereo-sceneflow"],
        figures: [
            (2.63, 11.92),
            (2.60, 10.73),
            (3.29, 12.64),
            (2.32, 16.27),
            (6.87, 33.83),
            (1.21, 6.03),
            (0.33, 4.05),
        ],
    },
    Table1Row {
        method: "Selective-IGEV",
        checkpoints: &[],
        figures: [
            (2.58, 11.79),
            (2.61, 11.73),
            (3.05, 11.51),
            (2.38, 15.20),
            (5.50, 32.95),
            (1.25, 6.05),
            (1.41, 6.08),
        ],
    },
    Table1Row {
        method: "DEFOM-Stereo",
        checkpoints: &["defomstereo-vits-sceneflow", "defomstereo-vitl-sceneflow"],
        figures: [(0.84, 6.03), (1.75, 8.73), (1.66, 9.11), (1.70, 10.78), (3.68, 33.68), (1.06, 4.99), (0.35, 2.38)],
    },
    Table1Row {
        method: "MonSter",
        checkpoints: &[],
        figures: [(1.92, 10.21), (1.98, 9.18), (2.15, 8.60), (2.12, 17.08), (3.60, 20.38), (0.89, 3.48), (0.22, 1.34)],
    },
    Table1Row {
        method: "MGStereo",
        checkpoints: &[],
        figures: [(1.16, 8.60), (1.83, 9.04), (2.07, 9.67), (3.19, 14.26), (3.99, 28.69), (1.12, 5.64), (0.25, 1.88)],
    },
    Table1Row {
        method: "paper's model",
        checkpoints: &[],
        figures: [(1.01, 7.22), (1.61, 6.81), (1.51, 6.63), (1.63, 9.31), (2.50, 26.77), (1.01, 4.62), (0.23, 1.81)],
    },
];

/// The row whose model is the checkpoint called `name` (a catalog name), if any.
pub fn table1_row(name: &str) -> Option<&'static Table1Row> {
    TABLE1.iter().find(|r| r.checkpoints.contains(&name))
}

/// One published figure beside ours.
#[derive(Debug, Clone, PartialEq)]
pub struct PublishedFigure {
    /// The data set.
    pub benchmark: PaperBenchmark,
    /// The paper's heading of the metric (`EPE`, `D2`).
    pub heading: &'static str,
    /// The published value.
    pub published: f64,
    /// Ours, from the evaluation table's aggregate row (`None` where it holds no such row).
    pub ours: Option<f64>,
}

/// How `benchmark` (its iterations, limit and size limit as the evaluation ran) is scored
/// otherwise than the paper's figures.
pub fn protocol_differences(benchmark: &BenchmarkConfig) -> Vec<String> {
    let mut d = Vec::new();
    if benchmark.iters != TABLE1_ITERATIONS {
        d.push(format!("{} iterations (the paper: {TABLE1_ITERATIONS})", benchmark.iters));
    }
    d.extend(benchmark.limit.map(|n| format!("only the first {n} samples")));
    d.extend(benchmark.max_size.map(|m| format!("pairs downscaled to at most {m} px")));
    d
}

/// The figures of `row` for the data sets `benchmark` scores, beside ours from `table` (EPE and
/// the rate of each data set, in the table's column order); empty where it scores none of them.
pub fn compare(row: &Table1Row, benchmark: &BenchmarkConfig, table: &EvalTable) -> Vec<PublishedFigure> {
    let aggregates = table.aggregates();
    let mut out = Vec::new();
    for (b, (epe, rate)) in PaperBenchmark::ALL.into_iter().zip(row.figures) {
        if !b.matches(benchmark) {
            continue;
        }
        let label = b.aggregate_label(benchmark);
        let ours = aggregates.iter().find(|a| a.label == label && a.images > 0).map(|a| a.all);
        let (metric, heading) = b.rate();
        out.push(PublishedFigure { benchmark: b, heading: "EPE", published: epe, ours: ours.map(|m| m.epe) });
        out.push(PublishedFigure { benchmark: b, heading, published: rate, ours: ours.and_then(|m| m.get(metric)) });
    }
    out
}

/// `figures` as lines: a heading naming the row, the checkpoint evaluated and the source, one
/// line per data set (`Midd-H: EPE 0.84 (ours 0.912), D2 6.03 % (ours 6.500 %)`), and how the
/// evaluation differs from the paper's protocol; empty without figures.
pub fn describe(row: &Table1Row, checkpoint: &str, figures: &[PublishedFigure], differences: &[String]) -> Vec<String> {
    if figures.is_empty() {
        return Vec::new();
    }
    let mut lines = vec![format!("published: {} (the model of {checkpoint}), {TABLE1_SOURCE}", row.method)];
    let mut benchmarks: Vec<PaperBenchmark> = figures.iter().map(|f| f.benchmark).collect();
    benchmarks.dedup();
    for b in benchmarks {
        let cells: Vec<String> = figures
            .iter()
            .filter(|f| f.benchmark == b)
            .map(|f| {
                let unit = if f.heading == "EPE" { "" } else { " %" };
                let ours = f.ours.map_or("ours: not scored".to_string(), |v| format!("ours {v:.3}{unit}"));
                format!("{} {:.2}{unit} ({ours})", f.heading, f.published)
            })
            .collect();
        lines.push(format!("  {}: {}", b.heading(), cells.join(", ")));
    }
    if !differences.is_empty() {
        lines.push(format!("  not the paper's protocol: {}", differences.join(", ")));
    }
    lines
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::metrics::MetricSums;
    use crate::protocol::Protocol;
    use crate::table::EvalRow;

    /// The figures are the transcription's (`shared/reference/paper-tables.md`), spot-checked
    /// at both ends of each row and for the two rows the workspace loads.
    #[test]
    fn rows_hold_the_published_figures_in_the_papers_column_order() {
        let raft = table1_row("raftstereo-sceneflow").unwrap();
        assert_eq!(raft.method, "RAFT-Stereo");
        assert_eq!(raft.figures[0], (1.43, 11.21));
        assert_eq!(raft.figures[6], (0.27, 2.61));
        let defom = table1_row("defomstereo-vitl-sceneflow").unwrap();
        assert_eq!((defom.method, defom.figures[0], defom.figures[5]), ("DEFOM-Stereo", (0.84, 6.03), (1.06, 4.99)));
        assert_eq!(table1_row("defomstereo-vits-sceneflow"), Some(defom));
        // Fine-tuned checkpoints are no zero-shot figures.
        for name in ["raftstereo-middlebury", "defomstereo-vitl-kitti", "defomstereo-vits-rvc"] {
            assert_eq!(table1_row(name), None, "{name}");
        }
        assert_eq!(TABLE1[6].figures[4], (2.50, 26.77));
        let headings: Vec<&str> = PaperBenchmark::ALL.iter().map(|b| b.heading()).collect();
        assert_eq!(headings, ["Midd-H", "DS-Sunny", "DS-Cloudy", "DS-Foggy", "DS-Rainy", "KITTI15", "ETH3D"]);
    }

    fn row(name: &str, group: Option<&str>, error: f32) -> EvalRow {
        let mut all = MetricSums::default();
        for gt in [10.0, 20.0, 30.0, 40.0] {
            all.add(gt + error, gt);
        }
        all.add(12.5, 10.0);
        EvalRow { name: name.into(), group: group.map(String::from), all, noc: None }
    }

    #[test]
    fn a_benchmark_is_matched_by_what_it_scores_and_its_aggregate_row_compared() {
        let defom = table1_row("defomstereo-vits-sceneflow").unwrap();
        let mut table = EvalTable::new(Protocol::Middlebury);
        table.push(row("Adirondack", None, 0.5));
        // MiddEval3 H: EPE and D2 of the `all` row.
        let h =
            BenchmarkConfig { split: Some(MiddleburySplit::H), ..BenchmarkConfig::new(DatasetKind::Middlebury, "m") };
        let figures = compare(defom, &h, &table);
        assert_eq!(figures.len(), 2);
        assert_eq!((figures[0].heading, figures[0].published), ("EPE", 0.84));
        assert!((figures[0].ours.unwrap() - 0.9).abs() < 1e-9, "{figures:?}");
        assert_eq!((figures[1].heading, figures[1].published, figures[1].ours), ("D2", 6.03, Some(20.0)));
        // Another split, or a folder named like the benchmark, is not the paper's data set.
        let q = BenchmarkConfig { split: Some(MiddleburySplit::Q), ..h.clone() };
        assert!(compare(defom, &q, &table).is_empty());
        let folder =
            BenchmarkConfig { name: Some("middlebury-h".into()), ..BenchmarkConfig::new(DatasetKind::Folder, "m") };
        assert!(compare(defom, &folder, &table).is_empty());
        let differences = protocol_differences(&BenchmarkConfig { iters: 2, ..h.clone() });
        let lines = describe(defom, "defomstereo-vits-sceneflow", &figures, &differences);
        assert!(
            lines[0].starts_with("published: DEFOM-Stereo (the model of defomstereo-vits-sceneflow), Lin"),
            "{lines:?}"
        );
        assert_eq!(lines[1], "  Midd-H: EPE 0.84 (ours 0.900), D2 6.03 % (ours 20.000 %)");
        assert_eq!(lines[2], "  not the paper's protocol: 2 iterations (the paper: 32)");
        assert!(protocol_differences(&h).is_empty());
    }

    #[test]
    fn a_benchmark_scores_a_weather_alone_only_when_it_names_it() {
        let sunny = PaperBenchmark::DrivingStereo(DrivingStereoWeather::Sunny);
        let all = BenchmarkConfig::new(DatasetKind::Drivingstereo, "ds");
        let one = BenchmarkConfig { weather: Some(DrivingStereoWeather::Sunny), ..all.clone() };
        let other = BenchmarkConfig { weather: Some(DrivingStereoWeather::Rainy), ..all.clone() };
        assert_eq!((sunny.matches(&all), sunny.matches(&one), sunny.matches(&other)), (true, true, false));
        assert_eq!(
            (sunny.matches_alone(&all), sunny.matches_alone(&one), sunny.matches_alone(&other)),
            (false, true, false)
        );
        let kitti = BenchmarkConfig::new(DatasetKind::Kitti2015, "k");
        assert!(PaperBenchmark::Kitti2015.matches_alone(&kitti) && !sunny.matches_alone(&kitti));
        assert_eq!(sunny.keys(), "dataset = \"drivingstereo\", weather = \"sunny\"");
    }

    #[test]
    fn every_weather_of_drivingstereo_is_its_own_group() {
        let raft = table1_row("raftstereo-sceneflow").unwrap();
        let mut table = EvalTable::new(Protocol::DrivingStereo);
        table.push(row("a", Some("sunny"), 0.5));
        table.push(row("b", Some("rainy"), 4.0));
        let all = BenchmarkConfig::new(DatasetKind::Drivingstereo, "ds");
        let figures = compare(raft, &all, &table);
        // Four weathers, two figures each; the ones not in the folder are not scored.
        assert_eq!(figures.len(), 8);
        let ours = |heading: &str, b: PaperBenchmark| {
            figures.iter().find(|f| f.heading == heading && f.benchmark == b).and_then(|f| f.ours)
        };
        let (sunny, rainy) = (DrivingStereoWeather::Sunny, DrivingStereoWeather::Rainy);
        assert!((ours("EPE", PaperBenchmark::DrivingStereo(sunny)).unwrap() - 0.9).abs() < 1e-9);
        assert_eq!(ours("D3", PaperBenchmark::DrivingStereo(rainy)), Some(80.0));
        assert_eq!(ours("EPE", PaperBenchmark::DrivingStereo(DrivingStereoWeather::Foggy)), None);
        // One weather alone: its figures from the `all` row.
        let mut sunny_only = EvalTable::new(Protocol::DrivingStereo);
        sunny_only.push(row("a", None, 0.5));
        let one = BenchmarkConfig { weather: Some(sunny), ..all };
        let figures = compare(raft, &one, &sunny_only);
        assert_eq!(figures.iter().map(|f| (f.heading, f.published)).collect::<Vec<_>>(), [("EPE", 1.89), ("D3", 9.87)]);
        assert!(figures.iter().all(|f| f.ours.is_some()));
    }
}
