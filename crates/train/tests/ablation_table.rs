//! The ablation table's layout: best bold, second underlined, per column; CSV and JSON agree.

use dgstereo_eval::Metrics;
use dgstereo_train::ablation::AblationTable;

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

#[test]
fn best_is_bold_and_second_underlined_per_column() {
    let cols = vec![("synthetic".to_string(), "epe".to_string()), ("synthetic".to_string(), "bad-3".to_string())];
    let mut t = AblationTable::new(cols);
    let b = "synthetic".to_string();
    t.push("baseline", &[(b.clone(), metrics(2.0, 10.0))]);
    t.push("+dgia", &[(b.clone(), metrics(1.5, 12.0))]);
    t.push("+eals", &[(b.clone(), metrics(1.0, 11.0))]);
    assert_eq!(t.ranks(), vec![(Some(2), Some(1)), (Some(0), Some(2))]);
    let md = t.to_markdown();
    let line = |name: &str| md.lines().find(|l| l.starts_with(&format!("| {name} |"))).unwrap().to_string();
    assert_eq!(line("+eals"), "| +eals | **1.000** | <u>11.000</u> |");
    assert_eq!(line("+dgia"), "| +dgia | <u>1.500</u> | 12.000 |");
    assert_eq!(line("baseline"), "| baseline | 2.000 | **10.000** |");
    let csv = t.to_csv();
    assert_eq!(csv.lines().next().unwrap(), "run,synthetic epe,synthetic bad-3");
    assert_eq!(csv.lines().nth(2).unwrap(), "+dgia,1.5,12");
    let json = t.to_json();
    assert_eq!(json["rows"][2]["values"]["synthetic/epe"], 1.0);
}

#[test]
fn missing_values_are_not_ranked() {
    let mut t = AblationTable::new(vec![("kitti".into(), "epe".into())]);
    t.push("a", &[]);
    t.push("b", &[("kitti".into(), metrics(3.0, 1.0))]);
    assert_eq!(t.ranks(), vec![(Some(1), None)]);
    assert!(t.to_markdown().contains("| a | – |"));
    assert!(t.to_json()["rows"][0]["values"]["kitti/epe"].is_null());
}
