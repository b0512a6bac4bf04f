//! Dataset layouts on small fake trees, the shared Cones folder, and the prefetching loader.

mod common;

use std::path::Path;
use std::sync::Arc;

use dgstereo_data::datasets::{
    DrivingStereoWeather, KittiVersion, SceneFlowPass, SceneFlowSubset, drivingstereo, eth3d, folder_pairs, kitti,
    middlebury2014, sceneflow,
};
use dgstereo_data::{
    Dataset, DisparityMap, Mask, PrefetchLoader, RgbImage, SyntheticConfig, SyntheticDataset, ValidRule, save_mask,
    save_rgb, write_disparity,
};

fn img(p: &Path) {
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    save_rgb(p, &RgbImage::from_fn(4, 3, |x, y| [x as f32, y as f32, 9.0])).unwrap();
}

fn disp(p: &Path, v: f32) {
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    let mut d = DisparityMap::filled(4, 3, v);
    d.set(0, 0, if p.extension().unwrap() == "pfm" { f32::INFINITY } else { 0.0 });
    write_disparity(p, &d).unwrap();
}

#[test]
fn middlebury_2014_layout() {
    let root = common::scratch("midd");
    for scene in ["Adirondack", "Jadeplant"] {
        img(&root.join(scene).join("im0.png"));
        img(&root.join(scene).join("im1.png"));
        disp(&root.join(scene).join("disp0GT.pfm"), 7.5);
    }
    save_mask(root.join("Adirondack/mask0nocc.png"), &Mask::filled(4, 3, true)).unwrap();
    std::fs::create_dir_all(root.join("empty")).unwrap();
    let ds = middlebury2014(&root).unwrap();
    assert_eq!(ds.len(), 2);
    assert_eq!(ds.rule, ValidRule::Finite);
    let s = ds.get(0).unwrap();
    assert_eq!(s.name, "Adirondack");
    assert!(s.nonoccluded.is_some() && ds.get(1).unwrap().nonoccluded.is_none());
    let valid = s.valid.unwrap();
    assert!(!valid.get(0, 0) && valid.get(1, 0), "inf is invalid");
}

#[test]
fn eth3d_layout_with_separate_gt_folder() {
    let root = common::scratch("eth3d");
    img(&root.join("two_view_training/delivery_area_1l/im0.png"));
    img(&root.join("two_view_training/delivery_area_1l/im1.png"));
    disp(&root.join("two_view_training_gt/delivery_area_1l/disp0GT.pfm"), 3.0);
    let ds = eth3d(&root).unwrap();
    assert_eq!(ds.len(), 1);
    assert_eq!(ds.rule, ValidRule::Below(512.0));
    assert!(ds.files[0].disparity.as_ref().unwrap().ends_with("two_view_training_gt/delivery_area_1l/disp0GT.pfm"));
    assert_eq!(ds.get(0).unwrap().disparity.unwrap().get(1, 1), 3.0);
}

#[test]
fn sceneflow_layouts() {
    let root = common::scratch("sceneflow");
    for (split, seq) in [("TRAIN", "A/0000"), ("TRAIN", "B/0001"), ("TEST", "A/0000")] {
        for f in ["0006", "0007"] {
            img(&root.join(format!("frames_cleanpass/{split}/{seq}/left/{f}.png")));
            img(&root.join(format!("frames_cleanpass/{split}/{seq}/right/{f}.png")));
            disp(&root.join(format!("disparity/{split}/{seq}/left/{f}.pfm")), 20.0);
        }
    }
    let train = sceneflow(&root, SceneFlowSubset::FlyingThingsTrain, SceneFlowPass::Clean).unwrap();
    assert_eq!(train.len(), 4);
    assert_eq!(train.files[0].name, "TRAIN/A/0000/left/0006.png");
    let s = train.get(3).unwrap();
    assert_eq!(s.disparity.unwrap().get(2, 2), 20.0);
    assert_eq!(sceneflow(&root, SceneFlowSubset::FlyingThingsTest, SceneFlowPass::Clean).unwrap().len(), 2);
    let e = sceneflow(&root, SceneFlowSubset::FlyingThingsTrain, SceneFlowPass::Final).unwrap_err();
    assert!(e.to_string().contains("frames_finalpass"), "{e}");
    // Driving: deeper tree, same rule.
    let d = common::scratch("driving");
    img(&d.join("frames_finalpass/15mm_focallength/scene_forwards/fast/left/0001.png"));
    img(&d.join("frames_finalpass/15mm_focallength/scene_forwards/fast/right/0001.png"));
    let ds = sceneflow(&d, SceneFlowSubset::Driving, SceneFlowPass::Final).unwrap();
    assert_eq!(ds.len(), 1);
    // Its disparity file is missing: loading names it.
    let e = ds.get(0).unwrap_err().to_string();
    assert!(e.contains("disparity/15mm_focallength/scene_forwards/fast/left/0001.pfm"), "{e}");
}

#[test]
fn kitti_layouts() {
    for (version, l, r, occ, noc) in [
        (KittiVersion::K2015, "image_2", "image_3", "disp_occ_0", "disp_noc_0"),
        (KittiVersion::K2012, "colored_0", "colored_1", "disp_occ", "disp_noc"),
    ] {
        let root = common::scratch(&format!("kitti{version:?}"));
        for n in ["000000", "000001"] {
            img(&root.join(l).join(format!("{n}_10.png")));
            img(&root.join(l).join(format!("{n}_11.png")));
            img(&root.join(r).join(format!("{n}_10.png")));
            disp(&root.join(occ).join(format!("{n}_10.png")), 12.25);
            disp(&root.join(noc).join(format!("{n}_10.png")), 12.25);
        }
        let ds = kitti(&root, version).unwrap();
        assert_eq!(ds.len(), 2);
        let s = ds.get(1).unwrap();
        assert_eq!(s.name, "000001_10");
        let d = s.disparity.unwrap();
        assert_eq!((d.get(0, 0), d.get(1, 0)), (0.0, 12.25));
        assert!(!s.valid.as_ref().unwrap().get(0, 0) && s.valid.unwrap().get(1, 0));
        let nocc = s.nonoccluded.unwrap();
        assert!(!nocc.get(0, 0) && nocc.get(3, 2));
    }
}

#[test]
fn drivingstereo_weathers() {
    let root = common::scratch("drivingstereo");
    for w in ["sunny", "rainy"] {
        for n in ["2018-10-19-09-30-39_2018-10-19-09-31-18-395", "2018-10-19-09-30-39_2018-10-19-09-31-18-495"] {
            img(&root.join(format!("{w}/left-image-full-size/{n}.png")));
            img(&root.join(format!("{w}/right-image-full-size/{n}.png")));
            disp(&root.join(format!("{w}/disparity-map-full-size/{n}.png")), 30.5);
        }
    }
    let all = drivingstereo(&root, &[]).unwrap();
    assert_eq!(all.len(), 4);
    assert_eq!(all.files[0].group.as_deref(), Some("sunny"));
    let rainy = drivingstereo(&root, &[DrivingStereoWeather::Rainy]).unwrap();
    assert_eq!(rainy.len(), 2);
    assert_eq!(rainy.get(0).unwrap().disparity.unwrap().get(3, 2), 30.5);
    assert!(drivingstereo(&root, &[DrivingStereoWeather::Foggy]).unwrap_err().to_string().contains("foggy"));
}

#[test]
fn folder_of_pairs() {
    let root = common::scratch("folder");
    for n in ["desk", "stairs"] {
        img(&root.join(format!("{n}_left.png")));
        img(&root.join(format!("{n}_right.png")));
    }
    disp(&root.join("desk_disp.pfm"), 2.0);
    img(&root.join("scene/im0.png"));
    img(&root.join("scene/im1.png"));
    disp(&root.join("scene/disp0GT.pfm"), 4.0);
    img(&root.join("cones/left_rgb.png"));
    img(&root.join("cones/right_rgb.png"));
    disp(&root.join("cones/disp_left.pfm"), 5.0);
    disp(&root.join("cones/disp_right.pfm"), 5.0);
    save_mask(root.join("cones/occlusion.png"), &Mask::filled(4, 3, true)).unwrap();
    img(&root.join("lonely_left.png"));
    let ds = folder_pairs(&root).unwrap();
    let names: Vec<&str> = ds.files.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["cones/left_rgb", "desk_left", "scene/im0", "stairs_left"]);
    assert!(ds.files[0].disparity.as_ref().unwrap().ends_with("cones/disp_left.pfm"));
    assert!(ds.files[0].nonoccluded.is_some());
    assert!(ds.files[1].disparity.as_ref().unwrap().ends_with("desk_disp.pfm"));
    assert!(ds.files[2].disparity.as_ref().unwrap().ends_with("scene/disp0GT.pfm"));
    assert!(ds.files[3].disparity.is_none());
    assert_eq!(ds.get(2).unwrap().disparity.unwrap().get(1, 1), 4.0);
}

#[test]
fn shared_cones_and_oakd_folders_load() {
    let Some(shared) = dgstereo_core::shared::shared_dir_for_test("cones_folder", "data/middlebury2003-cones-quarter")
    else {
        return;
    };
    let ds = folder_pairs(&shared.join("data/middlebury2003-cones-quarter")).unwrap();
    assert_eq!(ds.len(), 1);
    let s = ds.get(0).unwrap();
    assert_eq!((s.left.width, s.left.height), (450, 375));
    let d = s.disparity.unwrap();
    assert!(d.data.iter().all(|v| v.is_finite() && (0.0..=56.0).contains(v)));
    assert!(s.nonoccluded.unwrap().count() < 450 * 375);
    if shared.join("data/oakd-pairs").is_dir() {
        let oak = folder_pairs(&shared.join("data/oakd-pairs")).unwrap();
        assert_eq!(oak.len(), 3);
        let s = oak.get(0).unwrap();
        assert_eq!((s.left.width, s.left.height), (640, 480));
        assert_eq!(s.left.plane(0), s.left.plane(1), "grayscale loads as equal channels");
    }
}

#[test]
fn prefetch_loader_yields_in_order_and_ahead() {
    use std::sync::atomic::{AtomicUsize, Ordering};
    let produced = Arc::new(AtomicUsize::new(0));
    let p = produced.clone();
    let mut loader = PrefetchLoader::new((0..20).collect(), 4, move |i| {
        p.fetch_add(1, Ordering::SeqCst);
        i * 10
    });
    assert_eq!(loader.next(), Some(0));
    // While the consumer holds item 0, the feeder has already produced the next items.
    let t = std::time::Instant::now();
    while produced.load(Ordering::SeqCst) < 5 && t.elapsed().as_secs() < 5 {
        std::thread::yield_now();
    }
    assert!(produced.load(Ordering::SeqCst) >= 5);
    assert_eq!(loader.size_hint(), (19, Some(19)));
    let rest: Vec<usize> = loader.collect();
    assert_eq!(rest, (1..20).map(|i| i * 10).collect::<Vec<_>>());
    // Dropping early stops the feeder.
    let mut early = PrefetchLoader::new((0..1000).collect(), 2, |i| i);
    assert_eq!(early.next(), Some(0));
    drop(early);
}

#[test]
fn synthetic_dataset_through_the_loader() {
    let ds: Arc<dyn Dataset> =
        Arc::new(SyntheticDataset { config: SyntheticConfig::with_size(48, 32), seed: 100, len: 6 });
    let samples: Vec<_> = PrefetchLoader::for_dataset(ds.clone(), vec![5, 0, 3], 2).map(Result::unwrap).collect();
    assert_eq!(
        samples.iter().map(|s| s.name.as_str()).collect::<Vec<_>>(),
        ["synthetic/105", "synthetic/100", "synthetic/103"]
    );
    assert!(samples[0] == ds.get(5).unwrap());
    // Errors come through the loader too.
    let bad: Arc<dyn Dataset> = Arc::new(dgstereo_data::FileDataset {
        files: vec![dgstereo_data::SampleFiles {
            name: "x".into(),
            group: None,
            left: "/nonexistent/l.png".into(),
            right: "/nonexistent/r.png".into(),
            disparity: None,
            nonoccluded: None,
        }],
        rule: ValidRule::Positive,
    });
    let r: Vec<_> = PrefetchLoader::for_dataset(bad, vec![0], 1).collect();
    assert!(r[0].as_ref().unwrap_err().to_string().contains("/nonexistent/l.png"));
}
