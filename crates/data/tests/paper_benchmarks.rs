//! The readers of the paper's benchmarks on small fake trees: MiddEval3 with its split and
//! scene list, DrivingStereo's weathers one by one, and RAFT-Stereo's 400 FlyingThings3D TEST
//! pairs.

mod common;

use std::path::Path;

use dgstereo_data::datasets::{
    DrivingStereoWeather, FlyingThingsTestSubset, MiddleburySplit, SceneFlowPass, drivingstereo, flyingthings_test,
    middeval3,
};
use dgstereo_data::{Dataset, DisparityMap, RgbImage, ValidRule, save_rgb, write_disparity};

fn img(p: &Path, width: usize) {
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    save_rgb(p, &RgbImage::from_fn(width, 3, |x, y| [x as f32, y as f32, 9.0])).unwrap();
}

fn disp(p: &Path, width: usize, v: f32) {
    std::fs::create_dir_all(p.parent().unwrap()).unwrap();
    let mut d = DisparityMap::filled(width, 3, v);
    d.set(0, 0, if p.extension().unwrap() == "pfm" { f32::INFINITY } else { 0.0 });
    write_disparity(p, &d).unwrap();
}

/// A MiddEval3 folder with the three splits of two scenes (width 8, 4 and 2 for F, H, Q) and a
/// scene of H only.
fn fake_middeval3(root: &Path) {
    for (split, width) in [("F", 8), ("H", 4), ("Q", 2)] {
        for scene in ["Adirondack", "Jadeplant"] {
            let dir = root.join(format!("training{split}/{scene}"));
            img(&dir.join("im0.png"), width);
            img(&dir.join("im1.png"), width);
            disp(&dir.join("disp0GT.pfm"), width, 3.5);
        }
    }
    let extra = root.join("trainingH/Extra");
    img(&extra.join("im0.png"), 4);
    img(&extra.join("im1.png"), 4);
}

#[test]
fn middeval3_reads_the_split_of_the_middeval3_folder() {
    let parent = common::scratch("middeval3");
    let root = parent.join("MiddEval3");
    fake_middeval3(&root);
    let h = middeval3(&root, MiddleburySplit::H).unwrap();
    let names: Vec<&str> = h.files.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(names, ["Adirondack", "Extra", "Jadeplant"]);
    assert_eq!(h.rule, ValidRule::Finite);
    let s = h.get(0).unwrap();
    assert_eq!(s.left.width, 4, "the H images, not F's or Q's");
    let valid = s.valid.unwrap();
    assert!(!valid.get(0, 0) && valid.get(1, 0), "inf is unknown ground truth");
    assert_eq!(middeval3(&root, MiddleburySplit::Q).unwrap().get(1).unwrap().left.width, 2);
    // RAFT-Stereo's root (the folder holding MiddEval3) and the split folder itself work too.
    assert_eq!(middeval3(&parent, MiddleburySplit::F).unwrap().get(0).unwrap().left.width, 8);
    assert_eq!(middeval3(&root.join("trainingH"), MiddleburySplit::H).unwrap().len(), 3);

    // official_train.txt keeps the scenes it names, and each must exist.
    std::fs::write(root.join("official_train.txt"), "Adirondack\nJadeplant\n").unwrap();
    let listed = middeval3(&root, MiddleburySplit::H).unwrap();
    assert_eq!(listed.files.iter().map(|f| f.name.as_str()).collect::<Vec<_>>(), ["Adirondack", "Jadeplant"]);
    std::fs::write(root.join("official_train.txt"), "Adirondack\nPiano\n").unwrap();
    let e = middeval3(&root, MiddleburySplit::H).unwrap_err().to_string();
    assert!(e.contains("official_train.txt") && e.contains("Piano"), "{e}");
}

#[test]
fn middeval3_errors_say_what_root_it_expects() {
    let root = common::scratch("middeval3-errors").join("MiddEval3");
    let dir = root.join("trainingQ/Adirondack");
    img(&dir.join("im0.png"), 2);
    img(&dir.join("im1.png"), 2);
    let e = middeval3(&root, MiddleburySplit::H).unwrap_err().to_string();
    assert!(e.contains("trainingH") && e.contains("trainingQ"), "{e}");
    let e = middeval3(&root.join("trainingQ"), MiddleburySplit::F).unwrap_err().to_string();
    assert!(e.contains("MiddEval3's Q split") && e.contains("trainingF"), "{e}");
    let e = middeval3(&root.join("trainingQ/Adirondack"), MiddleburySplit::Q).unwrap_err().to_string();
    assert!(e.contains("expected the MiddEval3 folder holding trainingQ/"), "{e}");
    std::fs::create_dir_all(root.join("trainingF/empty")).unwrap();
    let e = middeval3(&root, MiddleburySplit::F).unwrap_err().to_string();
    assert!(e.contains("trainingF") && e.contains("no scene folder"), "{e}");
    assert_eq!("h".parse::<MiddleburySplit>().unwrap(), MiddleburySplit::H);
    assert!("X".parse::<MiddleburySplit>().unwrap_err().to_string().contains("Q, H or F"));
}

#[test]
fn drivingstereo_weathers_one_by_one() {
    let root = common::scratch("drivingstereo-weathers");
    for (weather, size, ext) in
        [("sunny", "full-size", "png"), ("foggy", "half-size", "jpg"), ("rainy", "full-size", "png")]
    {
        for frame in ["2018-10-19-09-30-39_2018-10-19-09-31-18-395", "2018-10-19-09-30-39_2018-10-19-09-31-18-495"] {
            img(&root.join(format!("{weather}/left-image-{size}/{frame}.{ext}")), 4);
            img(&root.join(format!("{weather}/right-image-{size}/{frame}.{ext}")), 4);
            disp(&root.join(format!("{weather}/disparity-map-{size}/{frame}.png")), 4, 30.5);
        }
    }
    let all = drivingstereo(&root, &[]).unwrap();
    let groups: Vec<&str> = all.files.iter().filter_map(|f| f.group.as_deref()).collect();
    assert_eq!(groups, ["sunny", "sunny", "foggy", "foggy", "rainy", "rainy"], "the paper's order");
    let foggy = drivingstereo(&root, &[DrivingStereoWeather::Foggy]).unwrap();
    assert_eq!(foggy.len(), 2);
    assert_eq!(foggy.files[0].name, "foggy/2018-10-19-09-30-39_2018-10-19-09-31-18-395");
    let s = foggy.get(1).unwrap();
    assert_eq!(s.disparity.as_ref().unwrap().get(3, 2), 30.5);
    assert!(!s.valid.unwrap().get(0, 0), "0 is unknown ground truth");
    let e = drivingstereo(&root, &[DrivingStereoWeather::Cloudy]).unwrap_err().to_string();
    assert!(e.contains("cloudy") && e.contains("not found"), "{e}");
    // One weather's folder given as the root is named as such.
    let e = drivingstereo(&root.join("sunny"), &[]).unwrap_err().to_string();
    assert!(e.contains("one DrivingStereo weather's folder"), "{e}");
    assert_eq!("rainy".parse::<DrivingStereoWeather>().unwrap(), DrivingStereoWeather::Rainy);
    assert!("snowy".parse::<DrivingStereoWeather>().is_err());
}

/// `sorted(np.random.permutation(450)[400:])` after `np.random.seed(1000)`: the indices of the
/// pairs of a 450-pair TEST folder that RAFT-Stereo's rule leaves out (computed with NumPy 2.4).
const LEFT_OUT_OF_450: [usize; 50] = [
    7, 11, 14, 40, 45, 69, 71, 87, 100, 128, 138, 144, 148, 156, 188, 192, 204, 205, 210, 213, 219, 221, 228, 233, 244,
    251, 257, 277, 282, 286, 292, 298, 306, 314, 317, 331, 343, 344, 345, 348, 350, 361, 370, 412, 414, 420, 423, 425,
    435, 443,
];

#[test]
fn flyingthings_test_raft_stereo_400() {
    let root = common::scratch("things400");
    // 450 left images in A/B/C x 15 sequences x 10 frames; the files need only exist to be listed.
    let mut names = Vec::new();
    for letter in ["A", "B", "C"] {
        for sequence in 0..15 {
            let dir = root.join(format!("frames_finalpass/TEST/{letter}/{sequence:04}"));
            std::fs::create_dir_all(dir.join("left")).unwrap();
            std::fs::create_dir_all(dir.join("right")).unwrap();
            for frame in 6..16 {
                std::fs::write(dir.join(format!("left/{frame:04}.png")), b"").unwrap();
                std::fs::write(dir.join(format!("right/{frame:04}.png")), b"").unwrap();
                names.push(format!("TEST/{letter}/{sequence:04}/left/{frame:04}.png"));
            }
        }
    }
    // Files RAFT-Stereo's glob does not see: a hidden file, a .webp and a deeper folder.
    std::fs::write(root.join("frames_finalpass/TEST/A/0000/left/.0001.png"), b"").unwrap();
    std::fs::write(root.join("frames_finalpass/TEST/A/0000/left/0001.webp"), b"").unwrap();
    std::fs::create_dir_all(root.join("frames_finalpass/TEST/A/0000/extra/left")).unwrap();
    std::fs::write(root.join("frames_finalpass/TEST/A/0000/extra/left/0001.png"), b"").unwrap();
    names.sort();
    let subset = flyingthings_test(&root, SceneFlowPass::Final, FlyingThingsTestSubset::RaftStereo400).unwrap();
    assert_eq!(subset.len(), 400);
    let expected: Vec<&str> =
        names.iter().enumerate().filter(|(i, _)| !LEFT_OUT_OF_450.contains(i)).map(|(_, n)| n.as_str()).collect();
    let listed: Vec<&str> = subset.files.iter().map(|f| f.name.as_str()).collect();
    assert_eq!(listed, expected);
    let first = &subset.files[0];
    assert!(first.right.ends_with("frames_finalpass/TEST/A/0000/right/0006.png"), "{}", first.right.display());
    assert!(first.disparity.as_ref().unwrap().ends_with("disparity/TEST/A/0000/left/0006.pfm"));
    assert_eq!(subset.rule, ValidRule::Below(512.0));
    let all = flyingthings_test(&root, SceneFlowPass::Final, FlyingThingsTestSubset::All).unwrap();
    assert_eq!(all.len(), 450);
    let e = flyingthings_test(&root, SceneFlowPass::Clean, FlyingThingsTestSubset::RaftStereo400).unwrap_err();
    assert!(e.to_string().contains("frames_cleanpass/TEST"), "{e}");
    assert_eq!("raft-stereo-400".parse::<FlyingThingsTestSubset>().unwrap(), FlyingThingsTestSubset::RaftStereo400);
}
