//! The ablation table's layout: seeds of one configuration form one row (mean ± std, `n`); the
//! best and second-best marks follow the rule of the legend; CSV and JSON agree.

use dgstereo_eval::Metrics;
use dgstereo_study::ablation_table::AblationTable;
use dgstereo_study::ablation_table::{mean_metrics, row_name};

fn metrics(epe: f64, bad_3: f64) -> Metrics {
    Metrics {
        epe,
        bad_0_5: f64::NAN,
        bad_1: f64::NAN,
        bad_2: f64::NAN,
        bad_3,
        bad_4: f64::NAN,
        d1_all: f64::NAN,
        valid_pixels: 10,
    }
}

fn columns() -> Vec<(String, String)> {
    vec![("synthetic".to_string(), "epe".to_string()), ("synthetic".to_string(), "bad-3".to_string())]
}

#[test]
fn best_is_bold_and_second_underlined_per_column() {
    let mut t = AblationTable::new(columns());
    let b = "synthetic".to_string();
    t.push("baseline", 1, 30, &[(b.clone(), metrics(2.0, 10.0))]);
    t.push("+dgia", 1, 30, &[(b.clone(), metrics(1.5, 12.0))]);
    t.push("+eals", 1, 30, &[(b.clone(), metrics(1.0, 11.0))]);
    assert_eq!(t.ranks(), vec![(Some(2), Some(1)), (Some(0), Some(2))]);
    let md = t.to_markdown();
    let line = |name: &str| md.lines().find(|l| l.starts_with(&format!("| {name} |"))).unwrap().to_string();
    assert_eq!(line("+eals"), "| +eals | 1 | 30 | **1.000** | <u>11.000</u> |");
    assert_eq!(line("+dgia"), "| +dgia | 1 | 30 | <u>1.500</u> | 12.000 |");
    assert_eq!(line("baseline"), "| baseline | 1 | 30 | 2.000 | **10.000** |");
    assert!(md.contains("| run | n | steps | synthetic epe (px) | synthetic bad-3 (%) |"), "{md}");
    assert!(md.contains("Lower is better"), "{md}");
    let csv = t.to_csv();
    assert_eq!(
        csv.lines().next().unwrap(),
        "run,n,steps,synthetic epe,synthetic epe std,synthetic bad-3,synthetic bad-3 std"
    );
    assert_eq!(csv.lines().nth(2).unwrap(), "+dgia,1,30,1.5,0,12,0");
    let json = t.to_json();
    assert_eq!(json["rows"][2]["values"]["synthetic/epe"], 1.0);
}

#[test]
fn missing_values_are_not_ranked_and_a_lone_row_beats_nobody() {
    let mut t = AblationTable::new(vec![("kitti".into(), "epe".into())]);
    t.push("a", 1, 3, &[]);
    t.push("b", 1, 3, &[("kitti".into(), metrics(3.0, 1.0))]);
    assert_eq!(t.ranks(), vec![(None, None)]);
    assert!(t.to_markdown().contains("| a | 1 | 3 | – |"));
    assert!(t.to_json()["rows"][0]["values"]["kitti/epe"].is_null());
}

#[test]
fn seeds_of_a_sweep_form_one_row_with_mean_std_and_n() {
    assert_eq!(row_name("smoke/baseline/train.seed=3"), "smoke/baseline");
    assert_eq!(row_name("x/loss.tau=0.8,train.seed=2"), "x/loss.tau=0.8");
    assert_eq!(row_name("x/loss.tau=0.8"), "x/loss.tau=0.8");
    assert_eq!(row_name("smoke/+dgia"), "smoke/+dgia");

    let b = "synthetic".to_string();
    let mut t = AblationTable::new(columns());
    t.set_pairs("synthetic", 4);
    // Baseline seeds spread widely (2.24, 4.18, 2.68), wider than the gap to the other row.
    for (seed, epe) in [(1, 2.24), (2, 4.18), (3, 2.68)] {
        t.push(&format!("smoke/baseline/train.seed={seed}"), seed, 30, &[(b.clone(), metrics(epe, 10.0))]);
    }
    for (seed, epe) in [(1, 3.5), (2, 3.6), (3, 3.7)] {
        t.push(&format!("smoke/+dgia/train.seed={seed}"), seed, 30, &[(b.clone(), metrics(epe, 20.0 + seed as f64))]);
    }
    assert_eq!(t.rows.len(), 2);
    assert_eq!(t.rows[0].n(), 3);
    let mean = (2.24 + 4.18 + 2.68) / 3.0;
    assert!((t.rows[0].mean(0) - mean).abs() < 1e-12);
    let std = (((2.24f64 - mean).powi(2) + (4.18 - mean).powi(2) + (2.68 - mean).powi(2)) / 2.0).sqrt();
    assert!((t.rows[0].std(0) - std).abs() < 1e-12);
    // EPE: 3.03 ± 1.02 against 3.60 ± 0.10 is no win; bad-3: 10 ± 0 against 22 ± 1 is.
    assert_eq!(t.ranks(), vec![(None, None), (Some(0), None)]);
    let md = t.to_markdown();
    assert!(md.contains(&format!("| smoke/baseline | 3 | 30 | {mean:.3} ± {std:.3} | **10.000 ± 0.000** |")), "{md}");
    assert!(md.contains("Pairs scored: synthetic 4."), "{md}");
    let csv = t.to_csv();
    assert!(csv.lines().nth(1).unwrap().starts_with("smoke/baseline,3,30,"), "{csv}");
    let json = t.to_json();
    assert_eq!(json["rows"][0]["n"], 3);
    assert_eq!(json["rows"][0]["seeds"].as_array().unwrap().len(), 3);
    assert_eq!(json["rows"][0]["seeds"][1]["values"]["synthetic/epe"], 4.18);
    assert_eq!(json["columns"][0]["pairs"], 4);
    let m = mean_metrics(&[metrics(1.0, 2.0), metrics(3.0, 4.0)]);
    assert_eq!((m.epe, m.bad_3, m.valid_pixels), (2.0, 3.0, 20));
}
