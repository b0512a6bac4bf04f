//! The `photos` key of a synthetic source and of the validation set: parsed, checked (the share
//! and, where the data is opened, the folder, named by key) and handed to the generator.

use dgstereo_experiment::{DataSource, SyntheticScenes, TrainingDataConfig};

fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("dgstereo-train-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn data(dir: &std::path::Path, share: f64) -> TrainingDataConfig {
    let text = format!(
        "[[sources]]\nkind = \"synthetic\"\nphotos = {{ dir = {dir:?}, share = {share} }}\n\n[validation]\ncount = 2\nphotos = {{ dir = {dir:?}, share = 1.0 }}\n"
    );
    toml::from_str(&text).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

#[test]
fn photo_textures_are_checked_and_reach_the_generator() {
    let dir = scratch("photos");
    image::RgbImage::from_fn(32, 24, |x, y| image::Rgb([(x * 7) as u8, (y * 9) as u8, 100]))
        .save(dir.join("a.png"))
        .unwrap();
    let config = data(&dir, 0.5);
    config.validate().unwrap();
    let DataSource::Synthetic { scenes: SyntheticScenes { photos: Some(p), .. }, .. } = &config.sources[0] else {
        panic!("a synthetic source with photos")
    };
    assert_eq!((p.dir.as_path(), p.share), (dir.as_path(), 0.5));
    let validation = config.validation.synthetic();
    assert_eq!((validation.photo_dir.as_deref(), validation.photo_prob), (Some(dir.as_path()), 1.0));

    let e = data(&dir, 1.5).validate().unwrap_err().to_string();
    assert!(e.contains("data.sources[0].photos.share: 1.5"), "{e}");
    config.check_files().unwrap();
    // A missing folder passes `validate` (an experiment file checks on a machine without the
    // data) and is named where the data is opened.
    let absent = data(&dir.join("absent"), 0.5);
    absent.validate().unwrap();
    let e = absent.check_files().unwrap_err().to_string();
    assert!(e.contains("data.sources[0].photos.dir") && e.contains("absent"), "{e}");
    let e = dgstereo_train::batch::TrainingData::new(&absent, &Default::default()).err().unwrap().to_string();
    assert!(e.contains("data.sources[0].photos.dir") && e.contains("absent"), "{e}");
    let e = toml::from_str::<TrainingDataConfig>(
        "[[sources]]\nkind = \"synthetic\"\nphotos = { dir = \"x\", share = 0.5, mix = 1 }\n",
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("mix"), "{e}");
}
