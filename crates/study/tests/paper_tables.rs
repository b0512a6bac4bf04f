//! The paper's ablation tables: the published figures are there, in the paper's order (checked
//! against the shared transcription when it is present), fake run results land in the right
//! cells of the Markdown and CSV layouts, beside the paper's figures and their differences, and
//! a column takes the benchmark that scores its data set, whatever the benchmark's name.

use dgstereo_data::datasets::{DrivingStereoWeather, MiddleburySplit};
use dgstereo_eval::published::TABLE1;
use dgstereo_eval::{BenchmarkConfig, DatasetKind, Metrics};
use dgstereo_study::paper_match::{BenchmarkMatch, match_benchmarks};
use dgstereo_study::paper_report::{RunScores, compare_with_paper, paper_tables_markdown, write_paper_tables};
use dgstereo_study::paper_table1::{published_figures, table1_comparison};
use dgstereo_study::paper_tables::{DRIVINGSTEREO_COLUMNS, GENERALISATION_COLUMNS, PAPER_TABLES, PaperBenchmark};

/// The benchmarks of `experiments/paper.toml`: its names, data sets, splits and weathers.
fn paper_benchmarks() -> Vec<BenchmarkConfig> {
    let named =
        |name: &str, dataset| BenchmarkConfig { name: Some(name.into()), ..BenchmarkConfig::new(dataset, "/data") };
    let mut benchmarks =
        vec![BenchmarkConfig { split: Some(MiddleburySplit::H), ..named("middlebury-h", DatasetKind::Middlebury) }];
    for weather in DrivingStereoWeather::ALL {
        benchmarks.push(BenchmarkConfig {
            weather: Some(weather),
            ..named(&format!("drivingstereo-{weather}"), DatasetKind::Drivingstereo)
        });
    }
    benchmarks.push(named("kitti2015", DatasetKind::Kitti2015));
    benchmarks.push(named("eth3d", DatasetKind::Eth3d));
    benchmarks
}

fn paper_matches() -> Vec<BenchmarkMatch> {
    match_benchmarks(&paper_benchmarks())
}

/// Metrics with the given EPE and every bad-T rate at `rate` (so D1, D2 and D3 read `rate`).
fn metrics(epe: f64, rate: f64) -> Metrics {
    Metrics { epe, bad_0_5: rate, bad_1: rate, bad_2: rate, bad_3: rate, bad_4: rate, d1_all: rate, valid_pixels: 100 }
}

#[test]
fn the_published_tables_are_there_in_the_papers_order() {
    let numbers: Vec<u32> = PAPER_TABLES.iter().map(|t| t.number).collect();
    assert_eq!(numbers, [2, 3, 4, 5]);
    let labels = |n: usize| PAPER_TABLES[n].rows.iter().map(|r| r.label).collect::<Vec<_>>();
    assert_eq!(labels(0), ["Baseline", "+DGIA", "+DGIA +gradient-GRU", "+DGIA +gradient-GRU +EALS"]);
    assert_eq!(labels(1), ["Depth+CNN+both", "Depth+DCN+only (context)", "Depth+DCN+both"]);
    assert_eq!(labels(2), ["Depth-Guided", "Gradient-Guided"]);
    assert_eq!(labels(3), ["τ = 0.8", "τ = 0.9", "τ = 1.0"]);
    let runs = |n: usize| PAPER_TABLES[n].rows.iter().map(|r| r.run).collect::<Vec<_>>();
    assert_eq!(runs(0), ["baseline", "+dgia", "+dgia+gradient", "paper"]);
    assert_eq!(runs(1), ["depth-cnn-both", "depth-dcn-context-only", "+dgia"]);
    assert_eq!(runs(2), ["depth-guided-gru", "+dgia+gradient"]);
    assert_eq!(runs(3), ["tau-sweep/loss.tau=0.8", "tau-sweep/loss.tau=0.9", "tau-sweep/loss.tau=1.0"]);
    for table in &PAPER_TABLES {
        for row in table.rows {
            assert_eq!(row.values.len(), table.columns.len(), "Table {} {}", table.number, row.label);
        }
    }
    // The columns: Middlebury-H, the four weathers, KITTI 2015, ETH3D; EPE then D2/D3/D3/D1.
    let benchmarks: Vec<PaperBenchmark> = GENERALISATION_COLUMNS.iter().step_by(2).map(|c| c.benchmark).collect();
    let weathers = DrivingStereoWeather::ALL.map(PaperBenchmark::DrivingStereo);
    assert_eq!(
        benchmarks,
        [&[PaperBenchmark::MiddleburyH][..], &weathers, &[PaperBenchmark::Kitti2015, PaperBenchmark::Eth3d]].concat()
    );
    let rates: Vec<&str> = GENERALISATION_COLUMNS.iter().skip(1).step_by(2).map(|c| c.metric).collect();
    assert_eq!(rates, ["bad-2", "bad-3", "bad-3", "bad-3", "bad-3", "bad-3", "bad-1"]);
    assert!(GENERALISATION_COLUMNS.iter().step_by(2).all(|c| c.metric == "epe"));
    assert_eq!(DRIVINGSTEREO_COLUMNS[..], GENERALISATION_COLUMNS[2..10]);
    // A few figures as printed: the paper's model on rainy DrivingStereo, Depth+DCN+both on
    // Middlebury-H, tau = 1.0 on ETH3D.
    assert_eq!(PAPER_TABLES[0].rows[3].values[6..], [2.50, 26.76]);
    assert_eq!(PAPER_TABLES[1].rows[2].values[..2], [0.99, 7.55]);
    assert_eq!(PAPER_TABLES[3].rows[2].values[12..], [0.22, 1.86]);
    // Rows the paper repeats are the same run with the same figures.
    assert_eq!(PAPER_TABLES[1].rows[2].values[2..10], *PAPER_TABLES[0].rows[1].values);
    assert_eq!(PAPER_TABLES[2].rows[1].values[2..10], *PAPER_TABLES[0].rows[2].values);
}

/// The rows of `## Table N` in the shared transcription: `(label, values)`.
fn transcribed(text: &str, number: u32) -> Vec<(String, Vec<f64>)> {
    let start = text.find(&format!("## Table {number}:")).unwrap_or_else(|| panic!("Table {number} missing"));
    let section = &text[start..];
    let section = &section[..section[3..].find("\n## ").map_or(section.len(), |e| e + 3)];
    section
        .lines()
        .filter(|l| l.starts_with("| ") && !l.starts_with("| row") && !l.starts_with("| method"))
        .map(|l| {
            let cells: Vec<&str> = l.trim_matches('|').split('|').map(str::trim).collect();
            (cells[0].to_string(), cells[1..].iter().map(|c| c.parse().unwrap()).collect())
        })
        .collect()
}

#[test]
fn the_figures_equal_the_shared_transcription() {
    let relative = "reference/paper-tables.md";
    let Some(shared) = dgstereo_core::shared::shared_dir_for_test("paper_tables", relative) else { return };
    let text = std::fs::read_to_string(shared.join(relative)).unwrap();
    for table in &PAPER_TABLES {
        let rows = transcribed(&text, table.number);
        let ours: Vec<(String, Vec<f64>)> =
            table.rows.iter().map(|r| (r.label.to_string(), r.values.to_vec())).collect();
        assert_eq!(ours, rows, "Table {}", table.number);
    }
}

#[test]
fn table1_figures_equal_the_shared_transcription() {
    let relative = "reference/paper-tables.md";
    let Some(shared) = dgstereo_core::shared::shared_dir_for_test("paper_table1", relative) else { return };
    let text = std::fs::read_to_string(shared.join(relative)).unwrap();
    let ours: Vec<(String, Vec<f64>)> = TABLE1.iter().map(|r| (r.method.to_string(), published_figures(r))).collect();
    assert_eq!(ours, transcribed(&text, 1));
}

#[test]
fn runs_of_table1_models_fill_table1_beside_the_published_figures() {
    let row = |method: &str| TABLE1.iter().find(|r| r.method == method).unwrap();
    let models =
        [("zoo/defom-vits-train".to_string(), row("DEFOM-Stereo")), ("baseline".to_string(), row("RAFT-Stereo"))];
    let runs = [
        RunScores {
            run: "zoo/defom-vits-train".into(),
            scores: vec![("middlebury-h".into(), metrics(0.9, 6.5)), ("kitti2015".into(), metrics(1.1, 5.0))],
            spread: Vec::new(),
        },
        RunScores { run: "baseline".into(), scores: vec![("eth3d".into(), metrics(0.3, 2.0))], spread: Vec::new() },
    ];
    let table1 = table1_comparison(&models, &runs, &paper_matches()).expect("two runs of Table 1's models");
    assert_eq!(table1.number, 1);
    let labels: Vec<(&str, &str)> = table1.rows.iter().map(|r| (r.label.as_str(), r.run.as_str())).collect();
    assert_eq!(labels, [("DEFOM-Stereo", "zoo/defom-vits-train"), ("RAFT-Stereo", "baseline")]);
    assert_eq!(table1.found, [true, true]);
    assert_eq!((table1.ours[0][0], table1.ours[0][1], table1.ours[0][10], table1.ours[0][11]), (0.9, 6.5, 1.1, 5.0));
    assert!(table1.ours[0][2].is_nan() && table1.ours[1][0].is_nan());
    assert_eq!(table1.ours[1][12..], [0.3, 2.0]);
    let markdown = table1.to_markdown(true);
    assert!(markdown.starts_with("### Table 1: zero-shot generalisation"), "{markdown}");
    assert!(markdown.contains("| DEFOM-Stereo | `zoo/defom-vits-train` | ours | 0.90 | 6.50 | – |"), "{markdown}");
    assert!(markdown.contains("| | | paper | 0.84 | 6.03 | 1.75 |"), "{markdown}");
    assert!(markdown.contains("| | | difference | +0.06 | +0.47 | – |"), "{markdown}");
    assert!(markdown.contains("| RAFT-Stereo | `baseline` | ours | – |"), "{markdown}");
    assert!(markdown.contains("Published figures: Lin et al."), "{markdown}");
    let csv = table1.to_csv(true);
    let lines: Vec<&str> = csv.lines().collect();
    assert!(lines[0].starts_with("row,run,source,Midd-H EPE,Midd-H D2,DS-Sunny EPE"), "{csv}");
    assert!(lines[2].starts_with("DEFOM-Stereo,zoo/defom-vits-train,paper,0.84,6.03,1.75,8.73"), "{csv}");
    assert!(table1_comparison(&[], &runs, &paper_matches()).is_none());
}

#[test]
fn fake_runs_fill_the_papers_layout() {
    let weathers = ["sunny", "cloudy", "foggy", "rainy"];
    let mut paper_scores: Vec<(String, Metrics)> = weathers
        .iter()
        .enumerate()
        .map(|(i, w)| (format!("drivingstereo-{w}"), metrics(1.5 + i as f64 / 10.0, 7.0 + i as f64)))
        .collect();
    paper_scores.push(("middlebury-h".into(), metrics(1.234, 8.0)));
    paper_scores.push(("synthetic".into(), metrics(9.0, 9.0)));
    let runs = [
        RunScores { run: "paper".into(), scores: paper_scores, spread: Vec::new() },
        // A run the paper's tables do not name is ignored.
        RunScores {
            run: "smoke/baseline".into(),
            scores: vec![("middlebury-h".into(), metrics(5.0, 50.0))],
            spread: Vec::new(),
        },
    ];
    let tables = compare_with_paper(&runs, &paper_matches());
    assert_eq!(tables.len(), 4);
    let table2 = &tables[0];
    assert_eq!(table2.found, [false, false, false, true]);
    assert_eq!(table2.ours[3], [1.5, 7.0, 1.6, 8.0, 1.7, 9.0, 1.8, 10.0]);
    assert!(table2.ours[0].iter().all(|v| v.is_nan()));
    assert!(!tables[1].has_runs() && !tables[2].has_runs() && !tables[3].has_runs());
    assert_eq!(
        table2.headings(),
        ["DS-Sunny EPE", "D3", "DS-Cloudy EPE", "D3", "DS-Foggy EPE", "D3", "DS-Rainy EPE", "D3"]
    );

    let plain = table2.to_markdown(false);
    let lines: Vec<&str> = plain.lines().collect();
    assert_eq!(lines[0], "### Table 2: the components (DrivingStereo only)");
    assert_eq!(
        lines[2],
        "| row | run | DS-Sunny EPE | D3 | DS-Cloudy EPE | D3 | DS-Foggy EPE | D3 | DS-Rainy EPE | D3 |"
    );
    assert_eq!(lines[4], "| Baseline | `baseline` (not run) | – | – | – | – | – | – | – | – |");
    assert_eq!(
        lines[7],
        "| +DGIA +gradient-GRU +EALS | `paper` | 1.50 | 7.00 | 1.60 | 8.00 | 1.70 | 9.00 | 1.80 | 10.00 |"
    );
    assert_eq!(lines.len(), 8, "{plain}");

    let beside = table2.to_markdown(true);
    let lines: Vec<&str> = beside.lines().collect();
    assert!(lines[2].starts_with("| row | run | | DS-Sunny EPE |"), "{}", lines[2]);
    // Four rows of three lines each, after the title, a blank line and the two header lines.
    assert_eq!(
        lines[13],
        "| +DGIA +gradient-GRU +EALS | `paper` | ours | 1.50 | 7.00 | 1.60 | 8.00 | 1.70 | 9.00 | 1.80 | 10.00 |"
    );
    assert_eq!(lines[14], "| | | paper | 1.60 | 6.81 | 1.51 | 6.63 | 1.63 | 9.31 | 2.50 | 26.76 |");
    assert_eq!(lines[15], "| | | difference | -0.10 | +0.19 | +0.09 | +1.37 | +0.07 | -0.31 | -0.70 | -16.76 |");
    assert!(beside.contains("Published figures: Lin et al."), "{beside}");

    // Table 3: Middlebury-H is filled, the benchmarks the run lacks are not.
    let table3 = &tables[1];
    let md = table3.to_markdown(false);
    assert!(md.contains("| Midd-H EPE | D2 | DS-Sunny EPE | D3 |"), "{md}");
    assert!(md.contains("| KITTI15 EPE | D3 | ETH3D EPE | D1 |"), "{md}");

    let csv = table2.to_csv(true);
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(
        lines[0],
        "row,run,source,DS-Sunny EPE,DS-Sunny D3,DS-Cloudy EPE,DS-Cloudy D3,DS-Foggy EPE,DS-Foggy D3,DS-Rainy EPE,DS-Rainy D3"
    );
    assert_eq!(lines.len(), 1 + 4 * 3);
    assert_eq!(lines[1], "Baseline,baseline,ours,,,,,,,,");
    assert_eq!(lines[2], "Baseline,baseline,paper,1.81,8.34,1.68,8.85,1.83,12.73,3.79,32.36");
    assert_eq!(lines[10], "+DGIA +gradient-GRU +EALS,paper,ours,1.5,7,1.6,8,1.7,9,1.8,10");
    assert!(lines[12].starts_with("+DGIA +gradient-GRU +EALS,paper,difference,-0.100000,0.190000,"), "{}", lines[12]);
    let only_ours = table2.to_csv(false);
    assert_eq!(only_ours.lines().count(), 1 + 4);
    assert!(only_ours.lines().skip(1).all(|l| l.split(',').nth(2) == Some("ours")));
}

#[test]
fn the_tables_are_written_as_markdown_and_csv() {
    let dir = tempfile::tempdir().unwrap();
    let runs = [RunScores {
        run: "+dgia".into(),
        scores: vec![("eth3d".into(), metrics(0.25, 2.0))],
        spread: vec![("eth3d".into(), metrics(0.05, 0.5))],
    }];
    let matches = paper_matches();
    let tables = compare_with_paper(&runs, &matches);
    write_paper_tables(&tables, &matches, dir.path(), true).unwrap();
    let md = std::fs::read_to_string(dir.path().join("paper-tables.md")).unwrap();
    assert_eq!(md, paper_tables_markdown(&tables, &matches, true));
    assert!(md.contains("- ETH3D: benchmark 'eth3d' (eth3d at /data, 32 iterations)\n"), "{md}");
    let titles: Vec<&str> = md.lines().filter(|l| l.starts_with("### Table")).collect();
    assert_eq!(
        titles,
        [
            "### Table 2: the components (DrivingStereo only)",
            "### Table 3: DGIA's fusion",
            "### Table 4: the GRU's guidance",
            "### Table 5: EALS's threshold tau"
        ]
    );
    for n in 2..=5 {
        let csv = std::fs::read_to_string(dir.path().join(format!("paper-table{n}.csv"))).unwrap();
        assert!(csv.starts_with("row,run,source,"), "table {n}: {csv}");
    }
    // +DGIA is Table 3's Depth+DCN+both: its ETH3D cells are ours (0.25, 2.00) beside 0.21, 1.75.
    let table3 = std::fs::read_to_string(dir.path().join("paper-table3.csv")).unwrap();
    let ours = table3.lines().find(|l| l.starts_with("Depth+DCN+both,+dgia,ours")).unwrap();
    assert!(ours.ends_with(",0.25,2"), "{ours}");
    let difference = table3.lines().find(|l| l.starts_with("Depth+DCN+both,+dgia,difference")).unwrap();
    assert!(difference.ends_with(",0.040000,0.250000"), "{difference}");
    // A row of several seeds: its spread is a line of the CSV and `± std` in the Markdown.
    let std = table3.lines().find(|l| l.starts_with("Depth+DCN+both,+dgia,ours std")).unwrap();
    assert!(std.ends_with(",0.05,0.5"), "{std}");
    assert!(md.contains("0.25 ± 0.05 | 2.00 ± 0.50 |"), "{md}");
}

#[test]
fn columns_take_the_benchmark_of_their_data_set_whatever_its_name() {
    // A folder named like a DrivingStereo weather, DrivingStereo's foggy weather under another
    // name, a Middlebury benchmark without the half-resolution split, and KITTI 2015 scored
    // with fewer iterations on a few downscaled samples.
    let folder = BenchmarkConfig {
        name: Some("drivingstereo-sunny".into()),
        ..BenchmarkConfig::new(DatasetKind::Folder, "/cones")
    };
    let foggy = BenchmarkConfig {
        name: Some("fog".into()),
        weather: Some(DrivingStereoWeather::Foggy),
        ..BenchmarkConfig::new(DatasetKind::Drivingstereo, "/ds")
    };
    let middlebury =
        BenchmarkConfig { name: Some("middlebury-h".into()), ..BenchmarkConfig::new(DatasetKind::Middlebury, "/mb") };
    let kitti = BenchmarkConfig {
        iters: 4,
        limit: Some(10),
        max_size: Some(320),
        ..BenchmarkConfig::new(DatasetKind::Kitti2015, "/kitti")
    };
    let matches = match_benchmarks(&[folder, foggy, middlebury, kitti]);
    let found: Vec<(&str, Option<&str>)> = matches.iter().map(|m| (m.heading, m.label())).collect();
    assert_eq!(
        found,
        [
            ("DS-Sunny", None),
            ("DS-Cloudy", None),
            ("DS-Foggy", Some("fog")),
            ("DS-Rainy", None),
            ("Midd-H", None),
            ("KITTI15", Some("kitti2015")),
            ("ETH3D", None)
        ]
    );
    assert_eq!(
        matches[0].describe(),
        "DS-Sunny: no benchmark of the study (dataset = \"drivingstereo\", weather = \"sunny\")"
    );
    assert_eq!(matches[2].describe(), "DS-Foggy: benchmark 'fog' (drivingstereo at /ds, weather foggy, 32 iterations)");
    assert_eq!(matches[4].describe(), "Midd-H: no benchmark of the study (dataset = \"middlebury\", split = \"H\")");
    assert!(
        matches[5].describe().ends_with(
            "; not the paper's protocol: 4 iterations (the paper: 32), only the first 10 samples, pairs downscaled to at most 320 px"
        ),
        "{}",
        matches[5].describe()
    );

    // Scores land by the match: the folder's are never DrivingStereo's, the fog's are.
    let runs = [RunScores {
        run: "paper".into(),
        scores: vec![("drivingstereo-sunny".into(), metrics(9.0, 90.0)), ("fog".into(), metrics(1.7, 9.0))],
        spread: Vec::new(),
    }];
    let table2 = &compare_with_paper(&runs, &matches)[0];
    assert!(table2.ours[3][..2].iter().all(|v| v.is_nan()), "{:?}", table2.ours[3]);
    assert_eq!(table2.ours[3][4..6], [1.7, 9.0]);
}
