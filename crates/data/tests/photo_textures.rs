//! Photo textures of the synthetic generator: every surface cut from the folder's photographs,
//! exact correspondence between the views, reproducibility, the procedural scenes unchanged
//! without them, and clear errors for a folder that cannot serve.

mod common;

use std::path::Path;

use dgstereo_data::synthetic::{Pattern, PhotoLibrary, SyntheticConfig, SyntheticScene, TextureKind, generate};

/// Two small photographs of smooth colour fields with fine detail, written as PNG into `dir`.
fn write_photos(dir: &Path) {
    for (i, (w, h)) in [(80u32, 60u32), (40, 72)].into_iter().enumerate() {
        let img = image::RgbImage::from_fn(w, h, |x, y| {
            let (x, y) = (x as f32, y as f32);
            let v = |a: f32, b: f32, p: f32| {
                (127.0 + 100.0 * (a * x + b * y + p).sin() + 20.0 * ((x * y + p) * 0.7).sin()) as u8
            };
            image::Rgb([v(0.11, 0.07, i as f32), v(-0.05, 0.13, 1.0), v(0.3, -0.2, 2.0)])
        });
        img.save(dir.join(format!("photo{i}.png"))).unwrap();
    }
}

fn config(dir: &Path, photo_prob: f64) -> SyntheticConfig {
    SyntheticConfig {
        max_disparity: 24.0,
        photo_dir: Some(dir.to_path_buf()),
        photo_prob,
        ..SyntheticConfig::rich(96, 64)
    }
}

#[test]
fn every_surface_takes_a_photo_and_the_right_view_still_matches() {
    let dir = common::scratch("photos-all");
    write_photos(&dir);
    let cfg = config(&dir, 1.0);
    for seed in 0..3 {
        let scene = SyntheticScene::random(&cfg, seed);
        for surface in &scene.surfaces {
            assert_eq!(surface.texture.kind, TextureKind::Photo, "seed {seed}");
            assert!(matches!(surface.texture.pattern, Pattern::Photo(_)));
        }
        let s = scene.render();
        let checked = common::assert_right_view_matches_left(&scene, &s, seed);
        assert!(checked > s.left.data.len() / 6, "seed {seed}: {checked} pixels visible in both views");
        assert_eq!(s, scene.render(), "rendering is deterministic");
        assert_eq!(generate(&cfg, seed), s, "the same seed gives the same pair");
    }
}

#[test]
fn without_the_share_the_scenes_are_the_procedural_ones() {
    let dir = common::scratch("photos-none");
    write_photos(&dir);
    let procedural = SyntheticConfig { max_disparity: 24.0, ..SyntheticConfig::rich(96, 64) };
    for seed in 0..3 {
        assert_eq!(generate(&config(&dir, 0.0), seed), generate(&procedural, seed), "seed {seed}");
        let half = generate(&config(&dir, 0.5), seed);
        assert_eq!(half.disparity, generate(&procedural, seed).disparity, "the geometry does not change");
    }
    let half = SyntheticScene::random(&config(&dir, 0.5), 7);
    let photos = half.surfaces.iter().filter(|s| s.texture.kind == TextureKind::Photo).count();
    assert!(
        photos > 0 && photos < half.surfaces.len() || half.surfaces.len() < 3,
        "{photos} of {}",
        half.surfaces.len()
    );
}

#[test]
fn a_photo_texture_stays_within_its_photograph_anywhere() {
    let dir = common::scratch("photos-range");
    write_photos(&dir);
    let library = PhotoLibrary::of_folder(&dir).unwrap();
    assert_eq!(library.photos.len(), 2);
    let scene = SyntheticScene::random(&config(&dir, 1.0), 11);
    let Pattern::Photo(photo) = &scene.surfaces[0].texture.pattern else { panic!("a photo background") };
    let values = &library.photos[photo.index].data;
    let (lo, hi) = values.iter().fold((f32::MAX, f32::MIN), |(l, h), v| (l.min(*v), h.max(*v)));
    for (x, y) in [(-1e4, 3.0), (5.5, 1e5), (123.25, -77.5), (0.0, 0.0)] {
        for v in photo.at(x, y) {
            assert!((lo - 1e-3..=hi + 1e-3).contains(&v), "({x}, {y}): {v} outside {lo}..{hi}");
        }
    }
}

#[test]
fn folders_that_cannot_serve_are_named() {
    let empty = common::scratch("photos-empty");
    let e = PhotoLibrary::of_folder(&empty).unwrap_err().to_string();
    assert!(e.contains("photos-empty") && e.contains("no photograph"), "{e}");
    let missing = empty.join("absent");
    assert!(PhotoLibrary::of_folder(&missing).unwrap_err().to_string().contains("absent"));
    let tiny = common::scratch("photos-tiny");
    image::RgbImage::new(8, 8).save(tiny.join("dot.png")).unwrap();
    let e = PhotoLibrary::of_folder(&tiny).unwrap_err().to_string();
    assert!(e.contains("dot.png") && e.contains("16 pixels"), "{e}");
}
