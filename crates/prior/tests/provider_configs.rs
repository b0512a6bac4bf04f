//! The `[prior]` TOML forms and the `none`, `file` and `cache` providers.

use std::cell::Cell;
use std::path::PathBuf;
use std::rc::Rc;

use burn::tensor::{Distribution, Tensor};
use dgstereo_core::tensor::{from_vec, to_vec};
use dgstereo_prior::formats::{DepthMap, write_npy, write_pfm, write_png16};
use dgstereo_prior::{
    CachedPrior, DepthAnythingV2Encoder, DepthPrior, PriorConfig, PriorInput, PriorProvider, SimulatedPriorConfig,
};

fn temp_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("dgstereo-prior-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn parse(text: &str) -> Result<PriorConfig, toml::de::Error> {
    toml::from_str(text)
}

fn pair(n: usize, h: usize, w: usize, seed: u64) -> PriorInput {
    let device = dgstereo_core::default_device();
    burn::tensor::Device::seed(&device, seed);
    PriorInput {
        left: Tensor::random([n, 3, h, w], Distribution::Uniform(0.0, 255.0), &device),
        right: Tensor::random([n, 3, h, w], Distribution::Uniform(0.0, 255.0), &device),
        gt_disparity: Some(Tensor::random([n, 1, h, w], Distribution::Uniform(1.0, 20.0), &device)),
        names: (0..n).map(|i| format!("pair{i}")).collect(),
    }
}

#[test]
fn toml_forms_parse_with_defaults_and_reject_unknown_keys() {
    assert_eq!(parse("kind = \"none\"").unwrap(), PriorConfig::None {});
    let e = parse("kind = \"none\"\nweights = \"w.pth\"").unwrap_err().to_string();
    assert!(e.contains("weights"), "`none` takes no keys: {e}");
    assert!(!PriorConfig::default().gives_prior());

    let dav2 =
        parse("kind = \"depth-anything-v2\"\nweights = \"w/depth_anything_v2_vitl.pth\"\nencoder = \"vitl\"").unwrap();
    assert_eq!(
        dav2,
        PriorConfig::DepthAnythingV2 {
            weights: "w/depth_anything_v2_vitl.pth".into(),
            encoder: Some(DepthAnythingV2Encoder::Vitl),
            input_size: 518
        }
    );
    assert!(dav2.gives_prior() && !dav2.uses_ground_truth());
    let err = parse("kind = \"depth-anything-v2\"\nencoder = \"vits\"").unwrap_err().to_string();
    assert!(err.contains("weights"), "{err}");
    let err = parse("kind = \"depth-anything-v2\"\nweights = \"a.pth\"\ninput_sise = 518").unwrap_err().to_string();
    assert!(err.contains("input_sise"), "{err}");

    let file = parse("kind = \"file\"\ndir = \"priors\"").unwrap();
    assert_eq!(
        file,
        PriorConfig::File { dir: "priors".into(), left: "{name}_left".into(), right: "{name}_right".into() }
    );

    let sim = parse("kind = \"simulated\"\nseed = 7\nnoise_std = 0.0").unwrap();
    assert_eq!(sim, PriorConfig::Simulated(SimulatedPriorConfig { seed: 7, noise_std: 0.0, ..Default::default() }));
    assert!(sim.uses_ground_truth());
    let err = parse("kind = \"simulated\"\nnoise = 0.1").unwrap_err().to_string();
    assert!(err.contains("noise"), "{err}");

    let cache = parse("kind = \"cache\"\ndir = \"c\"\n[inner]\nkind = \"simulated\"\nseed = 3").unwrap();
    let PriorConfig::Cache { inner, .. } = &cache else { panic!("{cache:?}") };
    assert!(matches!(**inner, PriorConfig::Simulated(SimulatedPriorConfig { seed: 3, .. })));
    assert!(cache.uses_ground_truth());
    let none_cached = parse("kind = \"cache\"\ndir = \"c\"\n[inner]\nkind = \"none\"").unwrap();
    assert!(!none_cached.gives_prior());

    // Round trip through TOML.
    for config in [dav2, file, sim, cache] {
        assert_eq!(parse(&toml::to_string(&config).unwrap()).unwrap(), config);
    }
}

#[test]
fn none_gives_no_prior() {
    let prior = PriorConfig::None {}.init(&dgstereo_core::default_device()).unwrap();
    assert!(prior.provide(&pair(1, 4, 5, 1)).unwrap().is_none());
}

#[test]
fn file_provider_reads_each_format_by_name_and_resizes() {
    let dir = temp_dir("files");
    let device = dgstereo_core::default_device();
    let (h, w) = (6, 8);
    let map = |offset: f32, height: usize, width: usize| DepthMap {
        height,
        width,
        values: (0..height * width).map(|i| offset + (i % 7) as f32 * 10.0 + (i / width) as f32).collect(),
    };
    write_npy(&dir.join("pair0_left.npy"), &map(1.0, h, w)).unwrap();
    write_pfm(&dir.join("pair0_right.pfm"), &map(2.0, h, w)).unwrap();
    write_png16(&dir.join("pair1_left.png"), &map(3.0, h, w)).unwrap();
    // A half-resolution map is resized to the image size.
    write_npy(&dir.join("pair1_right.npy"), &map(4.0, h / 2, w / 2)).unwrap();

    let config = PriorConfig::File { dir: dir.clone(), left: "{name}_left".into(), right: "{name}_right".into() };
    let prior = config.init(&device).unwrap();
    let out = prior.provide(&pair(2, h, w, 2)).unwrap().expect("a prior");
    assert_eq!(out.left.dims(), [2, 1, h, w]);
    assert_eq!(out.right.dims(), [2, 1, h, w]);
    let left = to_vec(out.left);
    assert_eq!(&left[..h * w], map(1.0, h, w).values.as_slice());
    assert_eq!(&left[h * w..], map(3.0, h, w).values.as_slice());
    let right = to_vec(out.right);
    assert_eq!(&right[..h * w], map(2.0, h, w).values.as_slice());
    let small = map(4.0, h / 2, w / 2).values;
    // align_corners=True keeps the corners exactly.
    assert_eq!(right[h * w], small[0]);
    assert_eq!(right[2 * h * w - 1], *small.last().unwrap());

    // A pair without files is an error naming the file.
    let mut input = pair(1, h, w, 3);
    input.names = vec!["pair7".into()];
    let err = prior.provide(&input).unwrap_err().to_string();
    assert!(err.contains("pair7_left"), "{err}");
    // A missing folder is an error naming the key.
    let missing = PriorConfig::File { dir: dir.join("nope"), left: "{name}".into(), right: "{name}".into() };
    assert!(missing.init(&device).unwrap_err().to_string().contains("prior.dir"));
    std::fs::remove_dir_all(&dir).ok();
}

/// A provider that counts its calls and returns a fixed function of the images.
#[derive(Debug, Clone)]
struct CountingPrior {
    calls: Rc<Cell<usize>>,
    elements: Rc<Cell<usize>>,
}

impl PriorProvider for CountingPrior {
    fn provide(&self, input: &PriorInput) -> dgstereo_core::Result<Option<DepthPrior>> {
        self.calls.set(self.calls.get() + 1);
        self.elements.set(self.elements.get() + input.left.dims()[0]);
        let left = input.left.clone().mean_dim(1).sqrt();
        let right = input.right.clone().mean_dim(1).add_scalar(1.0).log();
        Ok(Some(DepthPrior { left, right }))
    }
}

#[test]
fn cache_returns_identical_tensors_without_calling_the_wrapped_provider() {
    let dir = temp_dir("cache");
    let calls = Rc::new(Cell::new(0));
    let elements = Rc::new(Cell::new(0));
    let inner = CountingPrior { calls: calls.clone(), elements: elements.clone() };
    let cache = CachedPrior::new(inner.clone(), "counting v1", &dir, false).unwrap();
    let input = pair(2, 5, 7, 4);

    let first = cache.provide(&input).unwrap().unwrap();
    assert_eq!((calls.get(), elements.get()), (1, 2));
    let second = cache.provide(&input).unwrap().unwrap();
    assert_eq!(calls.get(), 1, "the second call must come from the cache");
    assert_eq!(to_vec(first.left.clone()), to_vec(second.left));
    assert_eq!(to_vec(first.right.clone()), to_vec(second.right));
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2, "one file per batch element");

    // Names do not matter, content does: a renamed pair hits, a changed pixel misses.
    let mut renamed = input.clone();
    renamed.names = vec!["x".into(), "y".into()];
    cache.provide(&renamed).unwrap().unwrap();
    assert_eq!(calls.get(), 1);
    let device = input.left.device();
    let mut pixels = to_vec(input.left.clone());
    pixels[0] += 1.0;
    let mut changed = input.clone();
    changed.left = from_vec(pixels, [2, 3, 5, 7], &device);
    let mixed = cache.provide(&changed).unwrap().unwrap();
    assert_eq!((calls.get(), elements.get()), (2, 3), "only the changed element is recomputed");
    assert_eq!(to_vec(mixed.right.narrow(0, 1, 1)), to_vec(first.right.narrow(0, 1, 1)));

    // Another provider configuration misses.
    let other = CachedPrior::new(inner, "counting v2", &dir, false).unwrap();
    other.provide(&input).unwrap().unwrap();
    assert_eq!(calls.get(), 3);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn cache_config_wraps_the_simulated_provider() {
    let dir = temp_dir("cache-config");
    let device = dgstereo_core::default_device();
    let config = PriorConfig::Cache {
        dir: dir.clone(),
        inner: Box::new(PriorConfig::Simulated(SimulatedPriorConfig { seed: 5, ..Default::default() })),
    };
    let input = pair(1, 6, 9, 5);
    let a = config.init(&device).unwrap().provide(&input).unwrap().unwrap();
    let b = config.init(&device).unwrap().provide(&input).unwrap().unwrap();
    assert_eq!(to_vec(a.left.clone()), to_vec(b.left));
    let direct = PriorConfig::Simulated(SimulatedPriorConfig { seed: 5, ..Default::default() });
    let c = direct.init(&device).unwrap().provide(&input).unwrap().unwrap();
    assert_eq!(to_vec(a.left), to_vec(c.left));
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn file_provider_errors_name_the_file() {
    let dir = temp_dir("file-errors");
    let device = dgstereo_core::default_device();
    let config = PriorConfig::File { dir: dir.clone(), left: "{name}_left".into(), right: "{name}_right".into() };
    let prior = config.init(&device).unwrap();
    let (h, w) = (4, 5);
    let good = DepthMap { height: h, width: w, values: vec![1.0; h * w] };

    // The left file exists, the right one does not: the message names the missing file's path.
    write_npy(&dir.join("pair0_left.npy"), &good).unwrap();
    let err = prior.provide(&pair(1, h, w, 6)).unwrap_err().to_string();
    assert!(err.contains(&dir.join("pair0_right").display().to_string()), "{err}");

    // A corrupt file and a file with a NaN are errors naming the file.
    std::fs::write(dir.join("pair0_right.pfm"), b"P5\n1 1\n255\n").unwrap();
    let err = prior.provide(&pair(1, h, w, 6)).unwrap_err().to_string();
    assert!(err.contains("pair0_right.pfm"), "{err}");
    std::fs::remove_file(dir.join("pair0_right.pfm")).unwrap();
    let mut nan = good.clone();
    nan.values[3] = f32::NAN;
    write_npy(&dir.join("pair0_right.npy"), &nan).unwrap();
    let err = prior.provide(&pair(1, h, w, 6)).unwrap_err().to_string();
    assert!(err.contains("pair0_right.npy") && err.contains("non-finite"), "{err}");

    // A batch without names cannot be matched to files.
    let mut unnamed = pair(1, h, w, 6);
    unnamed.names.clear();
    assert!(prior.provide(&unnamed).unwrap_err().to_string().contains("names"));
    std::fs::remove_dir_all(&dir).ok();
}

fn simulated(seed: u64, noise_std: f32) -> PriorConfig {
    PriorConfig::Simulated(SimulatedPriorConfig { seed, noise_std, ..Default::default() })
}

fn cache_files(dir: &std::path::Path) -> usize {
    std::fs::read_dir(dir).unwrap().count()
}

#[test]
fn cache_key_changes_with_the_provider_config() {
    let dir = temp_dir("cache-key");
    let device = dgstereo_core::default_device();
    let input = pair(1, 6, 9, 7);
    let cached = |inner: PriorConfig| PriorConfig::Cache { dir: dir.clone(), inner: Box::new(inner) };
    let run = |config: &PriorConfig| to_vec(config.init(&device).unwrap().provide(&input).unwrap().unwrap().left);

    let seed1 = run(&cached(simulated(1, 0.01)));
    assert_eq!(cache_files(&dir), 1);
    // The same configuration hits; another seed or another noise level misses and differs.
    assert_eq!(run(&cached(simulated(1, 0.01))), seed1);
    assert_eq!(cache_files(&dir), 1);
    let seed2 = run(&cached(simulated(2, 0.01)));
    assert_eq!(cache_files(&dir), 2);
    assert_ne!(seed2, seed1);
    assert_eq!(seed2, run(&simulated(2, 0.01)), "a miss returns the wrapped provider's output");
    run(&cached(simulated(1, 0.02)));
    assert_eq!(cache_files(&dir), 3);

    // The Depth Anything fingerprint follows the input size and the checkpoint file itself.
    let weights = dir.join("fake.pth");
    std::fs::write(&weights, [0u8; 10]).unwrap();
    let dav2 = |input_size| PriorConfig::DepthAnythingV2 { weights: weights.clone(), encoder: None, input_size };
    let before = dav2(518).fingerprint().unwrap();
    assert_ne!(before, dav2(364).fingerprint().unwrap());
    std::fs::write(&weights, [0u8; 20]).unwrap();
    assert_ne!(before, dav2(518).fingerprint().unwrap());
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_corrupt_cache_entry_is_an_error_naming_it() {
    let dir = temp_dir("cache-corrupt");
    let calls = Rc::new(Cell::new(0));
    let inner = CountingPrior { calls: calls.clone(), elements: Rc::new(Cell::new(0)) };
    let cache = CachedPrior::new(inner, "counting v1", &dir, false).unwrap();
    let input = pair(1, 3, 4, 8);
    let [entry] = cache.entry_paths(&input).try_into().unwrap();
    std::fs::write(&entry, b"truncated").unwrap();
    let err = cache.provide(&input).unwrap_err().to_string();
    assert!(err.contains(&entry.file_name().unwrap().to_string_lossy().to_string()), "{err}");
    assert_eq!(calls.get(), 0);
    std::fs::remove_dir_all(&dir).ok();
}

/// `PriorConfig::variants` lists every kind serde accepts, once, in the enum's order, and names
/// each as TOML does.
#[test]
fn every_kind_is_listed() {
    let accepted = dgstereo_core::serde_names::accepted_kinds::<PriorConfig>("kind").unwrap();
    let variants = PriorConfig::variants();
    let listed: Vec<&str> = variants.iter().map(PriorConfig::kind).collect();
    assert_eq!(listed, accepted);
    for variant in variants {
        let text = toml::to_string(&variant).unwrap();
        assert_eq!(toml::from_str::<PriorConfig>(&text).unwrap(), variant, "{text}");
    }
}

/// Validation reads no files and keys its problems relative to the prior table, nested ones
/// under `inner`.
#[test]
fn problems_are_keyed_relative_to_the_table() {
    let keys = |config: &PriorConfig| config.problems().into_iter().map(|p| p.key).collect::<Vec<_>>();
    let empty_cache = PriorConfig::Cache {
        dir: PathBuf::new(),
        inner: Box::new(PriorConfig::File { dir: PathBuf::new(), left: "l".into(), right: "r".into() }),
    };
    assert_eq!(keys(&empty_cache), ["dir", "inner.dir"]);
    let none_inside = PriorConfig::Cache { dir: "c".into(), inner: Box::new(PriorConfig::None {}) };
    assert_eq!(keys(&none_inside), ["inner.kind"]);
    let bad = SimulatedPriorConfig { gamma: [2.0, 1.0], noise_std: -1.0, ..SimulatedPriorConfig::default() };
    assert_eq!(keys(&PriorConfig::Simulated(bad)), ["gamma", "noise_std"]);
    let files = PriorConfig::File { dir: "no/such/folder".into(), left: "l".into(), right: "r".into() };
    assert!(files.validate().is_ok(), "validation reads no files");
}

/// Every kind refuses a key it does not have, naming it: `none`, which has no keys, as well as
/// the kinds with parameters.
#[test]
fn every_kind_refuses_unknown_keys() {
    for variant in PriorConfig::variants() {
        let text = format!("weightz = 1\n{}", toml::to_string(&variant).unwrap());
        let message = toml::from_str::<PriorConfig>(&text).expect_err(&text).to_string();
        assert!(message.contains("weightz"), "{}: {message}", variant.kind());
    }
}
