//! Metrics against hand-computed values, protocol aggregation, tables, and file scoring on the
//! Middlebury 2003 Cones pair.

use std::path::{Path, PathBuf};

use dgstereo_data::{DisparityMap, Mask, read_disparity, write_disparity};
use dgstereo_eval::{EvalRow, EvalTable, MetricSums, Metrics, Protocol, ValidOptions, evaluate, metrics_json};

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() < 1e-5
}

fn check(m: &Metrics, want: [f64; 7], n: u64) {
    for (name, (got, w)) in dgstereo_eval::METRIC_NAMES.iter().zip(m.values().iter().zip(want)) {
        assert!(close(*got, w), "{name}: got {got}, want {w}");
    }
    assert_eq!(m.valid_pixels, n);
}

fn tiny() -> (DisparityMap, DisparityMap) {
    let gt = vec![1.0, 2.0, 10.0, 100.0, 0.0, f32::NAN, f32::INFINITY, 5.0];
    let pred = vec![1.4, 3.5, 13.5, 104.0, 7.0, 1.0, 1.0, f32::NAN];
    (DisparityMap::from_vec(4, 2, pred).unwrap(), DisparityMap::from_vec(4, 2, gt).unwrap())
}

#[test]
fn metrics_match_hand_computed_values() {
    let (pred, gt) = tiny();
    // Valid: gt 1, 2, 10, 100, 5 (0, NaN, inf excluded). Errors 0.4, 1.5, 3.5, 4, 5 (NaN
    // prediction counts as 0). EPE 14.4/5; >0.5: 4; >1: 4; >2: 3; >3: 3; >4: 1;
    // D1 (>3 and >5 % of gt): 3.5 (gt 10) and 5 (gt 5), not 4 (gt 100).
    let m = evaluate(&pred, &gt, None, ValidOptions::default()).unwrap();
    check(&m, [2.88, 80.0, 80.0, 60.0, 60.0, 20.0, 40.0], 5);
    // A mask dropping the last pixel: errors 0.4, 1.5, 3.5, 4.
    let mut mask = Mask::filled(4, 2, true);
    mask.data[7] = false;
    let m = evaluate(&pred, &gt, Some(&mask), ValidOptions::default()).unwrap();
    check(&m, [2.35, 75.0, 75.0, 50.0, 50.0, 0.0, 25.0], 4);
    // max-disp 50 drops gt 100: errors 0.4, 1.5, 3.5, 5.
    let m = evaluate(&pred, &gt, None, ValidOptions { max_disp: Some(50.0) }).unwrap();
    check(&m, [2.6, 75.0, 75.0, 50.0, 50.0, 25.0, 50.0], 4);
}

#[test]
fn thresholds_are_strict() {
    let gt = DisparityMap::from_vec(5, 1, vec![10.0; 5]).unwrap();
    let pred = DisparityMap::from_vec(5, 1, vec![10.5, 11.0, 12.0, 13.0, 14.0]).unwrap();
    let m = evaluate(&pred, &gt, None, ValidOptions::default()).unwrap();
    // Errors exactly 0.5, 1, 2, 3, 4: each threshold excludes its own value.
    check(&m, [2.1, 80.0, 60.0, 40.0, 20.0, 0.0, 20.0], 5);
}

#[test]
fn no_valid_pixel_gives_null_metrics() {
    let gt = DisparityMap::filled(2, 2, 0.0);
    let m = evaluate(&gt, &gt, None, ValidOptions::default()).unwrap();
    assert_eq!(m.valid_pixels, 0);
    let j = m.to_json();
    assert!(j["epe"].is_null() && j["bad-3"].is_null());
    assert_eq!(j["valid_pixels"], 0);
}

#[test]
fn size_mismatch_is_an_error() {
    let a = DisparityMap::filled(2, 2, 1.0);
    let b = DisparityMap::filled(3, 2, 1.0);
    assert!(evaluate(&a, &b, None, ValidOptions::default()).is_err());
    assert!(evaluate(&a, &a, Some(&Mask::filled(1, 1, true)), ValidOptions::default()).is_err());
}

fn sums(errors: &[f32]) -> MetricSums {
    let mut s = MetricSums::default();
    for e in errors {
        s.add(10.0 + e, 10.0);
    }
    s
}

#[test]
fn protocols_pool_or_average_as_documented() {
    // Image A: one pixel, error 4 (bad-1..3: 100 %). Image B: three pixels, error 0.
    let (a, b) = (sums(&[4.0]), sums(&[0.0, 0.0, 0.0]));
    let kitti = Protocol::Kitti.aggregate(&[a, b]);
    assert!(close(kitti.bad_3, 25.0) && close(kitti.epe, 2.0) && kitti.valid_pixels == 4);
    let midd = Protocol::Middlebury.aggregate(&[a, b]);
    assert!(close(midd.bad_2, 50.0) && close(midd.epe, 2.0));
    let eth = Protocol::Eth3d.aggregate(&[a, b, MetricSums::default()]);
    assert!(close(eth.bad_1, 50.0), "images without valid pixels are skipped");
    assert_eq!(Protocol::Eth3d.valid_options().max_disp, Some(512.0));
    assert_eq!(Protocol::Kitti.headline(), &["bad-3", "d1-all"]);
}

#[test]
fn table_writes_csv_json_and_text() {
    let mut t = EvalTable::new(Protocol::DrivingStereo);
    t.push(EvalRow { name: "sunny/0".into(), group: Some("sunny".into()), all: sums(&[4.0]), noc: None });
    t.push(EvalRow {
        name: "sunny/1".into(),
        group: Some("sunny".into()),
        all: sums(&[0.0, 0.0]),
        noc: Some(sums(&[0.0])),
    });
    t.push(EvalRow { name: "rainy,0".into(), group: Some("rainy".into()), all: sums(&[2.0]), noc: None });
    let aggs = t.aggregates();
    assert_eq!(aggs.iter().map(|a| a.label.as_str()).collect::<Vec<_>>(), ["all", "sunny", "rainy"]);
    assert!(close(aggs[1].all.bad_3, 50.0) && close(aggs[1].all.epe, 2.0));
    assert!(close(aggs[0].all.epe, 2.0) && close(aggs[2].all.epe, 2.0));
    let csv = t.to_csv();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 1 + 3 + 3);
    assert!(
        lines[0]
            .starts_with("name,group,valid_pixels,epe,bad-0.5,bad-1,bad-2,bad-3,bad-4,d1-all,noc-valid_pixels,noc-epe")
    );
    assert!(lines[3].starts_with("\"rainy,0\",rainy,1,2.000000"));
    assert!(lines[4].starts_with("mean:all,,4,"));
    let j = t.to_json();
    assert_eq!(j["protocol"], "drivingstereo");
    assert_eq!(j["rows"][0]["all"]["bad-3"], 100.0);
    assert!(j["rows"][0]["noc"].is_null() && j["rows"][1]["noc"]["epe"] == 0.0);
    let text = t.to_string();
    assert!(text.contains("mean:sunny") && text.contains("sunny/1"));
    let dir = std::env::temp_dir().join(format!("dgstereo-eval-table-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    t.write_csv(dir.join("t.csv")).unwrap();
    t.write_json(dir.join("t.json")).unwrap();
    let back: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.join("t.json")).unwrap()).unwrap();
    assert_eq!(back, j);
    assert!(t.write_csv(dir.join("missing/t.csv")).unwrap_err().to_string().contains("missing"));
}

fn cones() -> Option<PathBuf> {
    dgstereo_core::shared::shared_dir_for_test("cones_metrics", "data/middlebury2003-cones-quarter")
        .map(|s| s.join("data/middlebury2003-cones-quarter"))
}

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("dgstereo-eval-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn num(j: &serde_json::Value, k: &str) -> f64 {
    j[k].as_f64().unwrap_or_else(|| panic!("{k} missing in {j}"))
}

#[test]
fn cones_against_itself_and_shifted_by_one_pixel() {
    let Some(dir) = cones() else { return };
    let gt_path = dir.join("disp_left.pfm");
    let gt = read_disparity(&gt_path).unwrap();
    assert_eq!((gt.width, gt.height), (450, 375));
    let known = gt.data.iter().filter(|v| v.is_finite() && **v > 0.0).count() as u64;
    assert!(known > 150_000);

    let j = metrics_json(&gt_path, &gt_path, None, None).unwrap();
    for k in dgstereo_eval::METRIC_NAMES {
        assert_eq!(num(&j, k), 0.0, "{k}");
    }
    assert_eq!(j["valid_pixels"].as_u64(), Some(known));

    // +1 px everywhere, in each prediction format: the error is exactly 1 on every pixel.
    let out = scratch("cones");
    let plus1 = DisparityMap { data: gt.data.iter().map(|v| v + 1.0).collect(), ..gt.clone() };
    for ext in ["pfm", "png", "npy"] {
        let p = out.join(format!("plus1.{ext}"));
        write_disparity(&p, &plus1).unwrap();
        let j = metrics_json(&p, &gt_path, None, None).unwrap();
        let want = [
            ("epe", 1.0),
            ("bad-0.5", 100.0),
            ("bad-1", 0.0),
            ("bad-2", 0.0),
            ("bad-3", 0.0),
            ("bad-4", 0.0),
            ("d1-all", 0.0),
        ];
        for (k, w) in want {
            assert!(close(num(&j, k), w), "{ext} {k}: {}", j[k]);
        }
        assert_eq!(j["valid_pixels"].as_u64(), Some(known));
    }

    // With the occlusion mask only pixels visible in both views count.
    let occ = dir.join("occlusion.png");
    let mask = dgstereo_data::load_mask(&occ).unwrap();
    let noc = gt.data.iter().zip(&mask.data).filter(|(v, m)| **m && v.is_finite() && **v > 0.0).count() as u64;
    assert!(noc < known && noc > known / 2);
    let p = out.join("plus1.pfm");
    let j = metrics_json(&p, &gt_path, Some(&occ), None).unwrap();
    assert_eq!(j["valid_pixels"].as_u64(), Some(noc));
    assert!(close(num(&j, "epe"), 1.0) && close(num(&j, "bad-0.5"), 100.0));

    // +3.5 px: bad-3 100 %, and D1 too since 3.5 > 5 % of any gt below 70.
    let plus35 = DisparityMap { data: gt.data.iter().map(|v| v + 3.5).collect(), ..gt.clone() };
    let p35 = out.join("plus35.pfm");
    write_disparity(&p35, &plus35).unwrap();
    let j = metrics_json(&p35, &gt_path, None, Some(30.0)).unwrap();
    assert!(close(num(&j, "bad-3"), 100.0) && close(num(&j, "d1-all"), 100.0) && close(num(&j, "bad-4"), 0.0));
    let below30 = gt.data.iter().filter(|v| v.is_finite() && **v > 0.0 && **v < 30.0).count() as u64;
    assert_eq!(j["valid_pixels"].as_u64(), Some(below30));
}

#[test]
fn file_errors_name_the_file() {
    let out = scratch("errors");
    let gt = out.join("gt.pfm");
    write_disparity(&gt, &DisparityMap::filled(4, 3, 2.0)).unwrap();
    let small = out.join("small.pfm");
    write_disparity(&small, &DisparityMap::filled(3, 3, 2.0)).unwrap();
    let e = metrics_json(&small, &gt, None, None).unwrap_err().to_string();
    assert!(e.contains("small.pfm") && e.contains("3x3"), "{e}");
    let missing = out.join("nope.pfm");
    let e = metrics_json(&missing, &gt, None, None).unwrap_err().to_string();
    assert!(e.contains("nope.pfm"), "{e}");
    let m = out.join("m.png");
    dgstereo_data::save_mask(&m, &Mask::filled(2, 2, true)).unwrap();
    let e = metrics_json(&gt, &gt, Some(Path::new(&m)), None).unwrap_err().to_string();
    assert!(e.contains("m.png"), "{e}");
}

#[test]
fn metrics_read_back_from_their_json() {
    let (pred, gt) = tiny();
    let m = evaluate(&pred, &gt, None, ValidOptions::default()).unwrap();
    let back = Metrics::from_json(&m.to_json()).unwrap();
    for (a, b) in m.values().iter().zip(back.values()) {
        assert!(close(*a, b), "{a} vs {b}");
    }
    assert_eq!(back.valid_pixels, m.valid_pixels);
    // No valid pixel: nulls read back as NaN; a missing metric is no metrics at all.
    let none = evaluate(&pred, &gt, Some(&Mask::filled(4, 2, false)), ValidOptions::default()).unwrap();
    let back = Metrics::from_json(&none.to_json()).unwrap();
    assert!(back.epe.is_nan() && back.valid_pixels == 0);
    let mut partial = m.to_json();
    partial.as_object_mut().unwrap().remove("bad-2");
    assert!(Metrics::from_json(&partial).is_none());
}
