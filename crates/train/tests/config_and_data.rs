//! The `[train]`/`[data]` tables and the stateless batch generator.

mod common;

use dgstereo_data::synthetic::TexturePreset;
use dgstereo_experiment::{DataSource, SyntheticScenes, TrainingConfig, TrainingDataConfig};
use dgstereo_train::batch::TrainingData;

#[test]
fn empty_tables_are_the_reference_recipe() {
    let t: TrainingConfig = toml::from_str("").unwrap();
    assert_eq!(t, TrainingConfig::default());
    assert_eq!((t.lr, t.weight_decay, t.eps, t.clip, t.iters, t.batch_size), (2e-4, 1e-5, 1e-8, 1.0, 22, 4));
    assert_eq!((t.warmup_fraction, t.schedule_total_steps()), (0.01, t.steps + 100));
    let d: TrainingDataConfig = toml::from_str("").unwrap();
    assert_eq!(d, TrainingDataConfig::default());
    // Written back, the tables load to the same values.
    assert_eq!(toml::from_str::<TrainingConfig>(&toml::to_string(&t).unwrap()).unwrap(), t);
    assert_eq!(toml::from_str::<TrainingDataConfig>(&toml::to_string(&d).unwrap()).unwrap(), d);
}

#[test]
fn unknown_keys_and_bad_values_are_named() {
    let e = toml::from_str::<TrainingConfig>("learning_rate = 1e-3").unwrap_err().to_string();
    assert!(e.contains("learning_rate"), "{e}");
    let e =
        toml::from_str::<TrainingDataConfig>("[[sources]]\nkind = \"synthetic\"\nwidht = 10").unwrap_err().to_string();
    assert!(e.contains("widht"), "{e}");
    let e = TrainingConfig { clip: -1.0, ..TrainingConfig::default() }.validate().unwrap_err().to_string();
    assert!(e.contains("train.clip"), "{e}");
    let d = TrainingDataConfig {
        sources: vec![DataSource::Folder { weight: 1.0, root: "/no/such/folder".into(), sparse: false }],
        ..TrainingDataConfig::default()
    };
    let e = TrainingData::new(&d, &TrainingConfig::default()).err().unwrap().to_string();
    assert!(e.contains("data.sources[0].root") && e.contains("/no/such/folder"), "{e}");
}

#[test]
fn batches_depend_only_on_seed_and_step() {
    let parts = common::tiny_parts(10, 1, 1e-3, None, 2);
    let a = TrainingData::new(&parts.data, &parts.train).unwrap();
    let b = TrainingData::new(&parts.data, &parts.train).unwrap();
    // Any order of requests gives the same pairs.
    let late = b.pair(5, 1).unwrap();
    let early = b.pair(0, 0).unwrap();
    assert_eq!(a.pair(0, 0).unwrap().left, early.left);
    assert_eq!(a.pair(5, 1).unwrap().disparity, late.disparity);
    assert_ne!(a.pair(1, 0).unwrap().left, early.left, "another step draws another pair");
    let mut other = parts.train.clone();
    other.seed += 1;
    let c = TrainingData::new(&parts.data, &other).unwrap();
    assert_ne!(c.pair(0, 0).unwrap().left, early.left, "another seed draws another pair");
}

#[test]
fn augmented_batches_have_the_crop_size_and_both_targets() {
    let mut parts = common::tiny_parts(10, 1, 1e-3, None, 2);
    parts.data.augment = true;
    parts.data.sources = vec![DataSource::Synthetic {
        weight: 1.0,
        scenes: SyntheticScenes { width: 96, height: 64, ..Default::default() },
        count: None,
        lattices: None,
    }];
    let data = TrainingData::new(&parts.data, &parts.train).unwrap();
    let pairs = data.batch(3, 2).unwrap();
    for p in &pairs {
        assert_eq!((p.left.height, p.left.width), (32, 64));
        assert_eq!((p.disparity_nearest.height, p.disparity_nearest.width), (32, 64));
        assert!(p.valid.count() > 0);
    }
}

#[test]
fn synthetic_textures_key_selects_the_preset_and_rejects_unknown_values() {
    let parse = |extra: &str| {
        toml::from_str::<TrainingDataConfig>(&format!("[[sources]]\nkind = \"synthetic\"\nwidth = 48\n{extra}"))
    };
    let textures = |d: &TrainingDataConfig| match &d.sources[0] {
        DataSource::Synthetic { scenes, .. } => scenes.textures,
        other => panic!("{other:?}"),
    };
    let smooth = parse("").unwrap();
    assert_eq!(textures(&smooth), TexturePreset::Smooth);
    assert_eq!(textures(&parse("textures = \"smooth\"").unwrap()), TexturePreset::Smooth);
    let rich = parse("textures = \"rich\"").unwrap();
    assert_eq!(textures(&rich), TexturePreset::Rich);
    // Written back, the key round-trips (and stays absent for the default).
    assert!(!toml::to_string(&smooth).unwrap().contains("textures"));
    assert_eq!(toml::from_str::<TrainingDataConfig>(&toml::to_string(&rich).unwrap()).unwrap(), rich);
    let e = parse("textures = \"fancy\"").unwrap_err().to_string();
    assert!(e.contains("textures") && e.contains("fancy") && e.contains("rich"), "{e}");
    let e = parse("textures = 3").unwrap_err().to_string();
    assert!(e.contains("textures"), "{e}");
    // The validation set takes the same key.
    let v = toml::from_str::<TrainingDataConfig>("[validation]\ntextures = \"rich\"").unwrap();
    assert_eq!(v.validation.scenes.textures, TexturePreset::Rich);
    assert_eq!(toml::from_str::<TrainingDataConfig>("").unwrap().validation.scenes.textures, TexturePreset::Smooth);
    let e = toml::from_str::<TrainingDataConfig>("[validation]\ntextures = \"rough\"").unwrap_err().to_string();
    assert!(e.contains("textures") && e.contains("rough"), "{e}");

    // The rich source renders the same scenes (same disparity) with other colours.
    let mut parts = common::tiny_parts(10, 1, 1e-3, None, 2);
    let smooth_data = TrainingData::new(&parts.data, &parts.train).unwrap();
    let DataSource::Synthetic { scenes, .. } = &mut parts.data.sources[0] else { unreachable!() };
    scenes.textures = TexturePreset::Rich;
    let rich_data = TrainingData::new(&parts.data, &parts.train).unwrap();
    let (mut differ, mut same_disparity) = (false, true);
    for step in 0..3 {
        let (a, b) = (smooth_data.pair(step, 0).unwrap(), rich_data.pair(step, 0).unwrap());
        same_disparity &= a.disparity == b.disparity;
        differ |= a.left != b.left;
    }
    assert!(same_disparity && differ);
}

/// A `[data]` table with one synthetic source of 96x64 up to 24 px, plus the `extra` key lines.
fn synthetic_source(extra: &str) -> TrainingDataConfig {
    toml::from_str(&format!(
        "[[sources]]\nkind = \"synthetic\"\nwidth = 96\nheight = 64\nmax_disparity = 24.0\n{extra}"
    ))
    .unwrap()
}

#[test]
fn synthetic_min_disparity_range_raises_the_far_end_and_bad_ranges_name_the_key() {
    let error = |text: &str| toml::from_str::<TrainingDataConfig>(text).unwrap().validate().unwrap_err().to_string();
    let near = synthetic_source("min_disparity = [10.0, 14.0]");
    near.validate().unwrap();
    assert!(matches!(
        near.sources[0],
        DataSource::Synthetic { scenes: SyntheticScenes { min_disparity: Some([10.0, 14.0]), .. }, .. }
    ));
    assert_eq!(toml::from_str::<TrainingDataConfig>(&toml::to_string(&near).unwrap()).unwrap(), near);
    for bad in ["[0.0, 4.0]", "[8.0, 4.0]", "[4.0, 23.5]", "[nan, 4.0]"] {
        let e = synthetic_source(&format!("min_disparity = {bad}")).validate().unwrap_err().to_string();
        assert!(e.contains("data.sources[0].min_disparity"), "{bad}: {e}");
    }
    let e = error("[[sources]]\nkind = \"synthetic\"\nmax_disparity = -3.0");
    assert!(e.contains("data.sources[0].max_disparity") && e.contains("-3"), "{e}");
    let e = error("[validation]\nwidth = 100\nmin_disparity = [2.0, 30.0]");
    assert!(e.contains("data.validation.min_disparity") && e.contains("14"), "{e}");

    // Training pairs (no augmentation, no crop change) have no disparity below the range.
    let mut parts = common::tiny_parts(10, 1, 1e-3, None, 2);
    parts.data.sources = near.sources.clone();
    let data = TrainingData::new(&parts.data, &parts.train).unwrap();
    for step in 0..3 {
        let p = data.pair(step, 0).unwrap();
        let low = p.disparity.data.iter().copied().fold(f32::INFINITY, f32::min);
        assert!(low >= 10.0 - 1e-4, "step {step}: smallest disparity {low}");
    }
    // The validation set follows its own keys.
    let v = toml::from_str::<TrainingDataConfig>(
        "[validation]\nwidth = 96\nheight = 64\nmax_disparity = 30.0\nmin_disparity = [20.0, 20.0]",
    )
    .unwrap();
    v.validate().unwrap();
    let synth = v.validation.synthetic();
    assert_eq!((synth.max_disparity, synth.min_disparity_range), (30.0, Some([20.0, 20.0])));
}

#[test]
fn synthetic_lattices_key_sets_the_share_and_bad_shares_name_the_key() {
    let parse = |value: &str| synthetic_source(&format!("lattices = {value}"));
    let all = parse("1.0");
    all.validate().unwrap();
    assert_eq!(toml::from_str::<TrainingDataConfig>(&toml::to_string(&all).unwrap()).unwrap(), all);
    for bad in ["1.5", "-0.1", "nan"] {
        let e = parse(bad).validate().unwrap_err().to_string();
        assert!(e.contains("data.sources[0].lattices"), "{bad}: {e}");
    }
    // With every scene latticed, the training pairs differ from the same seeds without.
    let mut parts = common::tiny_parts(10, 1, 1e-3, None, 2);
    parts.data.augment = false;
    parts.data.sources = all.sources.clone();
    let with = TrainingData::new(&parts.data, &parts.train).unwrap();
    parts.data.sources = parse("0.0").sources;
    let without = TrainingData::new(&parts.data, &parts.train).unwrap();
    let differ =
        (0..3).filter(|&s| with.pair(s, 0).unwrap().disparity != without.pair(s, 0).unwrap().disparity).count();
    assert!(differ >= 2, "only {differ} of 3 pairs changed");
}

/// A folder source marked `sparse` goes through the sparse augmentor: every supervised pixel
/// holds a scaled ground-truth value, never one blended with the holes (0 in KITTI files).
#[test]
fn sparse_folder_sources_move_ground_truth_points() {
    let dir = tempfile::tempdir().unwrap();
    let (w, h) = (160, 96);
    let mut img = dgstereo_data::RgbImage::new(w, h);
    let mut disp = dgstereo_data::DisparityMap { width: w, height: h, data: vec![0.0; w * h] };
    for y in 0..h {
        for x in 0..w {
            img.set(x, y, [(x * 7 % 255) as f32, (y * 5 % 255) as f32, 90.0]);
            if x % 3 == 0 && y % 2 == 0 {
                disp.data[y * w + x] = 8.0 + (x / 16) as f32;
            }
        }
    }
    dgstereo_data::save_rgb(dir.path().join("a_left.png"), &img).unwrap();
    dgstereo_data::save_rgb(dir.path().join("a_right.png"), &img).unwrap();
    dgstereo_data::kitti_png::write_kitti_png(dir.path().join("a_disp.png"), &disp).unwrap();
    let values: Vec<f32> = disp.data.iter().copied().filter(|d| *d > 0.0).collect();
    let train = TrainingConfig { crop: [48, 64], ..TrainingConfig::default() };
    let blended = |sparse: bool| {
        let data = TrainingDataConfig {
            sources: vec![DataSource::Folder { weight: 1.0, root: dir.path().into(), sparse }],
            ..TrainingDataConfig::default()
        };
        let data = TrainingData::new(&data, &train).unwrap();
        (0..8)
            .map(|step| {
                let p = data.pair(step, 0).unwrap();
                assert_eq!((p.disparity.width, p.disparity.height), (64, 48));
                // The scale is drawn per pair; supervised values are ground-truth values times
                // one factor, so their ratios must be ratios of ground-truth values.
                let supervised: Vec<f32> =
                    p.disparity.data.iter().zip(&p.valid.data).filter(|(_, ok)| **ok).map(|(d, _)| *d).collect();
                let Some(&first) = supervised.first() else { return 0 };
                let distinct_ratio = supervised.iter().any(|d| {
                    let k = d / first;
                    !values.iter().any(|v| values.iter().any(|u| (u / v - k).abs() < 1e-4))
                });
                usize::from(distinct_ratio)
            })
            .sum::<usize>()
    };
    assert_eq!(blended(true), 0, "the sparse augmentor supervises only moved ground-truth points");
    assert!(blended(false) > 0, "the dense augmentor interpolates into the holes");
}
