//! A benchmark's split, weather and subset: parsed from TOML, checked against the data set they
//! belong to, and applied when the samples are listed (fake trees in a scratch folder).

use std::path::{Path, PathBuf};

use dgstereo_data::datasets::{DrivingStereoWeather, FlyingThingsTestSubset, MiddleburySplit};
use dgstereo_data::{DisparityMap, RgbImage, save_rgb, write_disparity};
use dgstereo_eval::{BenchmarkConfig, DatasetKind};

fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("dgstereo-eval-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn pair(left: &Path, right: &Path, disparity: &Path) {
    for p in [left, right, disparity] {
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    }
    save_rgb(left, &RgbImage::from_fn(4, 3, |x, _| [x as f32, 0.0, 0.0])).unwrap();
    save_rgb(right, &RgbImage::from_fn(4, 3, |x, _| [x as f32, 0.0, 0.0])).unwrap();
    write_disparity(disparity, &DisparityMap::filled(4, 3, 2.0)).unwrap();
}

fn parse(text: &str) -> BenchmarkConfig {
    toml::from_str(text).unwrap_or_else(|e| panic!("{text}: {e}"))
}

#[test]
fn options_parse_from_toml_and_belong_to_their_data_set() {
    let b = parse("dataset = 'middlebury'\nroot = 'x'\nsplit = 'H'");
    assert_eq!(b.split, Some(MiddleburySplit::H));
    let b = parse("dataset = 'drivingstereo'\nroot = 'x'\nweather = 'foggy'");
    assert_eq!(b.weather, Some(DrivingStereoWeather::Foggy));
    let b = parse("dataset = 'sceneflow'\nroot = 'x'\nsubset = 'raft-stereo-400'");
    assert_eq!(b.subset, Some(FlyingThingsTestSubset::RaftStereo400));
    assert!(b.option_problems().is_empty());
    assert!(toml::from_str::<BenchmarkConfig>("dataset = 'middlebury'\nroot = 'x'\nsplit = 'half'").is_err());
    assert!(toml::from_str::<BenchmarkConfig>("dataset = 'drivingstereo'\nroot = 'x'\nweather = 'snowy'").is_err());

    let b = parse("dataset = 'kitti2015'\nroot = 'x'\nsplit = 'H'\nweather = 'sunny'");
    let problems = b.option_problems();
    let keys: Vec<&str> = problems.iter().map(|(k, _)| *k).collect();
    assert_eq!(keys, ["split", "weather"]);
    assert!(problems[0].1.contains("middlebury") && problems[0].1.contains("kitti2015"), "{}", problems[0].1);
    let e = b.load().unwrap_err().to_string();
    assert!(e.contains("split") && e.contains("kitti2015"), "{e}");
    // Written back, the options keep their spelling; unset ones are left out.
    let text = toml::to_string(&parse("dataset = 'middlebury'\nroot = 'x'\nsplit = 'h'")).unwrap();
    assert!(text.contains("split = \"H\"") && !text.contains("weather"), "{text}");
}

#[test]
fn a_middeval3_folder_needs_a_split_and_a_split_folder_still_works() {
    let root = scratch("middeval3").join("MiddEval3");
    for split in ["H", "Q"] {
        let scene = root.join(format!("training{split}/Piano"));
        pair(&scene.join("im0.png"), &scene.join("im1.png"), &scene.join("disp0GT.pfm"));
    }
    let mut b = BenchmarkConfig::new(DatasetKind::Middlebury, &root);
    let e = b.dataset().unwrap_err().to_string();
    assert!(e.contains("MiddEval3 folder") && e.contains("split") && e.contains("Q, H"), "{e}");
    b.split = Some(MiddleburySplit::H);
    let (dataset, indices) = b.dataset().unwrap();
    assert_eq!(indices, [0]);
    assert!(dataset.files[0].left.ends_with("trainingH/Piano/im0.png"));
    // The split folder as the root, with or without the split.
    let split_folder = BenchmarkConfig::new(DatasetKind::Middlebury, root.join("trainingQ"));
    assert_eq!(split_folder.dataset().unwrap().0.files[0].name, "Piano");
    b.split = Some(MiddleburySplit::F);
    let e = b.dataset().unwrap_err().to_string();
    assert!(e.contains("trainingF"), "{e}");
}

#[test]
fn one_drivingstereo_weather_is_one_group() {
    let root = scratch("drivingstereo");
    for weather in ["sunny", "cloudy", "foggy", "rainy"] {
        let frame = "2018-10-19-09-30-39_2018-10-19-09-31-18-395";
        pair(
            &root.join(format!("{weather}/left-image-full-size/{frame}.png")),
            &root.join(format!("{weather}/right-image-full-size/{frame}.png")),
            &root.join(format!("{weather}/disparity-map-full-size/{frame}.png")),
        );
    }
    let mut b = BenchmarkConfig::new(DatasetKind::Drivingstereo, &root);
    assert_eq!(b.dataset().unwrap().0.files.len(), 4);
    b.weather = Some(DrivingStereoWeather::Rainy);
    let (dataset, _) = b.dataset().unwrap();
    let groups: Vec<Option<&str>> = dataset.files.iter().map(|f| f.group.as_deref()).collect();
    assert_eq!(groups, [Some("rainy")]);
    assert_eq!(b.table_metrics(), ["epe", "bad-3"], "the paper's EPE and D3");
}

#[test]
fn the_sceneflow_subset_is_applied() {
    let root = scratch("things");
    for frame in 0..3 {
        let dir = root.join("frames_finalpass/TEST/A/0000");
        pair(
            &dir.join(format!("left/{frame:04}.png")),
            &dir.join(format!("right/{frame:04}.png")),
            &root.join(format!("disparity/TEST/A/0000/left/{frame:04}.pfm")),
        );
    }
    let mut b = BenchmarkConfig::new(DatasetKind::Sceneflow, &root);
    assert_eq!(b.dataset().unwrap().0.files.len(), 3);
    // Fewer than 400 pairs: RAFT-Stereo's rule keeps them all, in sorted order.
    b.subset = Some(FlyingThingsTestSubset::RaftStereo400);
    let (dataset, _) = b.dataset().unwrap();
    let names: Vec<&str> = dataset.files.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["TEST/A/0000/left/0000.png", "TEST/A/0000/left/0001.png", "TEST/A/0000/left/0002.png"]);
}
