//! A sample's files checked by their headers alone (`SampleFiles::check_headers`), and the same
//! faults met when a sample is read: views of different sizes, a ground truth of another size or
//! cut short, in each disparity format. Every fault is an error naming the files, never a panic.

mod common;

use std::path::{Path, PathBuf};

use dgstereo_data::headers::{disparity_size, image_size};
use dgstereo_data::{DisparityMap, FileDataset, RgbImage, SampleFiles, ValidRule, save_rgb, write_disparity};

fn picture(path: &Path, w: usize, h: usize) -> PathBuf {
    save_rgb(path, &RgbImage::from_fn(w, h, |x, y| [x as f32, y as f32, 7.0])).unwrap();
    path.to_path_buf()
}

fn ground_truth(path: &Path, w: usize, h: usize) -> PathBuf {
    write_disparity(path, &DisparityMap::from_vec(w, h, (0..w * h).map(|i| 1.0 + i as f32).collect()).unwrap())
        .unwrap();
    path.to_path_buf()
}

fn sample(left: &Path, right: &Path, disparity: Option<&Path>) -> SampleFiles {
    SampleFiles {
        name: "pair".into(),
        group: None,
        left: left.to_path_buf(),
        right: right.to_path_buf(),
        disparity: disparity.map(Path::to_path_buf),
        nonoccluded: None,
    }
}

/// The first `keep` bytes of `path`, written to `to`.
fn truncated(path: &Path, to: &Path, keep: usize) -> PathBuf {
    std::fs::write(to, &std::fs::read(path).unwrap()[..keep]).unwrap();
    to.to_path_buf()
}

#[test]
fn good_samples_pass_and_sizes_come_from_the_headers() {
    let dir = common::scratch("headers_good");
    let (left, right) = (picture(&dir.join("l.png"), 12, 5), picture(&dir.join("r.png"), 12, 5));
    assert_eq!(image_size(&left).unwrap(), (12, 5));
    for ext in ["pfm", "png", "npy"] {
        let gt = ground_truth(&dir.join(format!("d.{ext}")), 12, 5);
        assert_eq!(disparity_size(&gt).unwrap(), (12, 5), "{ext}");
        let files = sample(&left, &right, Some(&gt));
        assert_eq!(files.check_headers().unwrap(), (12, 5));
        assert!(FileDataset::load(&files, ValidRule::Positive).is_ok(), "{ext}");
    }
}

#[test]
fn views_of_different_sizes_name_both_files_when_checked_and_when_read() {
    let dir = common::scratch("headers_views");
    let (left, right) = (picture(&dir.join("left.png"), 12, 5), picture(&dir.join("right.png"), 11, 5));
    let files = sample(&left, &right, None);
    for e in [files.check_headers().unwrap_err(), FileDataset::load(&files, ValidRule::Positive).unwrap_err()] {
        let said = e.to_string();
        assert!(said.contains(&right.display().to_string()) && said.contains(&left.display().to_string()), "{said}");
        assert!(said.contains("11x5") && said.contains("12x5"), "{said}");
    }
    // A ground truth of another size than the left view.
    let right = picture(&dir.join("right.png"), 12, 5);
    let gt = ground_truth(&dir.join("disp.pfm"), 12, 6);
    let files = sample(&left, &right, Some(&gt));
    for e in [files.check_headers().unwrap_err(), FileDataset::load(&files, ValidRule::Finite).unwrap_err()] {
        let said = e.to_string();
        assert!(said.contains("disp.pfm") && said.contains("left.png") && said.contains("12x6"), "{said}");
    }
}

#[test]
fn a_ground_truth_cut_short_is_found_by_its_header_in_every_format() {
    let dir = common::scratch("headers_truncated");
    let (left, right) = (picture(&dir.join("l.png"), 40, 30), picture(&dir.join("r.png"), 40, 30));
    for ext in ["pfm", "npy", "png"] {
        let whole = ground_truth(&dir.join(format!("whole.{ext}")), 40, 30);
        let length = std::fs::metadata(&whole).unwrap().len() as usize;
        let cut = truncated(&whole, &dir.join(format!("cut.{ext}")), length * 2 / 3);
        let e = disparity_size(&cut).unwrap_err().to_string();
        assert!(e.contains("truncated") && e.contains(&cut.display().to_string()), "{ext}: {e}");
        let files = sample(&left, &right, Some(&cut));
        let e = files.check_headers().unwrap_err().to_string();
        assert!(e.contains("truncated") && e.contains("cut."), "{ext}: {e}");
        assert!(FileDataset::load(&files, ValidRule::Positive).is_err(), "{ext}: reading it fails too");
        // Cut inside the header: still an error, naming the file.
        let stub = truncated(&whole, &dir.join(format!("stub.{ext}")), 5);
        let e = disparity_size(&stub).unwrap_err().to_string();
        assert!(e.contains("stub."), "{ext}: {e}");
    }
    // A PNG that is not 16-bit cannot be a KITTI disparity.
    let e = disparity_size(&left).unwrap_err().to_string();
    assert!(e.contains("16-bit") && e.contains("l.png"), "{e}");
    let e = image_size(dir.join("missing.png")).unwrap_err().to_string();
    assert!(e.contains("missing.png"), "{e}");
}
