//! Depth Anything V2's ViT-B and ViT-L without their checkpoints (too large to keep in
//! `shared/`): each size built to the official configuration has the paper's parameter count,
//! the official state dict's layout, and is recognised from its keys.
//!
//! The figures come from the paper (Yang et al., "Depth Anything V2", Table 7: 24.8 M, 97.5 M,
//! 335.3 M parameters) and the official `depth_anything_v2/dpt.py` model configs
//! (`model_configs` in the repository's `run.py`: features 64 / 128 / 256, out_channels
//! [48,96,192,384] / [96,192,384,768] / [256,512,1024,1024]) and `intermediate_layer_idx`
//! ([2,5,8,11] for vits and vitb, [4,11,17,23] for vitl).

use burn::module::Module;
use dgstereo_prior::depth_anything::checkpoint::{encoder_from_keys, model_keys};
use dgstereo_prior::{DepthAnythingV2, DepthAnythingV2Encoder};

/// The official configuration of each size.
#[test]
fn sizes_have_the_official_configurations() {
    use DepthAnythingV2Encoder::*;
    let official = [
        (Vits, 384, 12, 64, [48, 96, 192, 384], [2, 5, 8, 11]),
        (Vitb, 768, 12, 128, [96, 192, 384, 768], [2, 5, 8, 11]),
        (Vitl, 1024, 24, 256, [256, 512, 1024, 1024], [4, 11, 17, 23]),
    ];
    for (encoder, width, depth, features, out_channels, layers) in official {
        assert_eq!((encoder.vit().embed_dim, encoder.vit().depth), (width, depth), "{encoder}");
        assert_eq!(encoder.features(), features, "{encoder}");
        assert_eq!(encoder.out_channels(), out_channels, "{encoder}");
        assert_eq!(encoder.intermediate_layers(), layers, "{encoder}");
    }
}

/// Built to each size: the paper's parameter count (in millions, one decimal), the official
/// layout of keys (blocks, head projections), recognised from its keys; a state dict with a
/// head of another size is an error naming the key.
fn check_size(encoder: DepthAnythingV2Encoder, millions: f64) {
    let model = DepthAnythingV2::new(encoder, &dgstereo_core::default_device());
    let params = model.num_params();
    assert_eq!((params as f64 / 1e5).round() / 10.0, millions, "{encoder}: {params} parameters");
    let keys = model_keys(&model);
    let count: usize = keys.iter().map(|(_, s)| s.iter().product::<usize>()).sum();
    assert_eq!(count, params, "{encoder}: the keys hold every parameter");
    let depth = encoder.vit().depth;
    assert!(keys.iter().any(|(k, _)| *k == format!("pretrained.blocks.{}.mlp.fc2.weight", depth - 1)), "{encoder}");
    assert!(!keys.iter().any(|(k, _)| k.starts_with(&format!("pretrained.blocks.{depth}."))), "{encoder}");
    for (k, _) in &keys {
        assert!(k.starts_with("pretrained.") || k.starts_with("depth_head."), "{encoder}: unexpected key {k}");
    }
    assert_eq!(encoder_from_keys(&keys), Ok(encoder));
    let mut other_head = keys.clone();
    for (k, shape) in &mut other_head {
        if k == "depth_head.projects.2.weight" {
            shape[0] += 8;
        }
    }
    let problem = encoder_from_keys(&other_head).unwrap_err();
    assert_eq!(problem.key, "depth_head.projects.2.weight", "{problem}");
    assert!(problem.reason.contains(&encoder.to_string()), "{problem}");
}

#[test]
fn vits_is_recognised_from_its_keys() {
    check_size(DepthAnythingV2Encoder::Vits, 24.8);
}

#[test]
fn vitb_has_the_papers_parameter_count_and_the_official_keys() {
    check_size(DepthAnythingV2Encoder::Vitb, 97.5);
}

#[test]
fn vitl_has_the_papers_parameter_count_and_the_official_keys() {
    check_size(DepthAnythingV2Encoder::Vitl, 335.3);
}
