//! `train.frozen`: parameters that do not train.
//!
//! DEFOM-Stereo freezes the Depth Anything V2 inside it (`requires_grad = False` on its ViT and
//! depth head) and gives the optimiser only the parameters that require a gradient. Here a
//! frozen parameter is marked as requiring none on the autodiff device: the backward pass then
//! gives it no gradient, so clipping, the gradient exchange and AdamW (whose weight decay is
//! part of its step) never see it, and its value stays bit for bit what it was loaded as. The
//! mark is set each time a trainer is built, so a resumed run freezes the same parameters.

use burn::module::{Module, ModuleMapper, Param};
use burn::tensor::Tensor;
use dgstereo_core::{Error, Result};
use dgstereo_model::RaftStereo;

use crate::params::PathStack;

/// Whether the module path `path` lies under `prefix` (the path itself or one below it).
pub fn under(path: &str, prefix: &str) -> bool {
    path.strip_prefix(prefix).is_some_and(|rest| rest.is_empty() || rest.starts_with('.'))
}

/// Walks the module with the paths its checkpoints write: an enum module's variant (the
/// encoders' layout) is no segment of them, as in burn-store's names (`encoder.fnet.conv1`).
struct Freezer<'a> {
    path: PathStack,
    prefixes: &'a [String],
    matched: Vec<usize>,
}

fn is_variant(container_type: &str) -> bool {
    container_type.starts_with("Enum:")
}

impl ModuleMapper for Freezer<'_> {
    fn enter_module(&mut self, name: &str, container_type: &str) {
        if !is_variant(container_type) {
            self.path.enter(name);
        }
    }
    fn exit_module(&mut self, _name: &str, container_type: &str) {
        if !is_variant(container_type) {
            self.path.exit();
        }
    }
    fn map_float<const D: usize>(&mut self, param: Param<Tensor<D>>) -> Param<Tensor<D>> {
        let path = self.path.current();
        let hits: Vec<usize> = (0..self.prefixes.len()).filter(|&i| under(&path, &self.prefixes[i])).collect();
        if hits.is_empty() {
            return param;
        }
        self.matched.extend(hits);
        param.set_require_grad(false)
    }
}

/// `model` with every float parameter under one of `prefixes` (module paths as checkpoints
/// name them, `train.frozen`) requiring no gradient.
///
/// # Errors
/// [`Error::Config`] keyed `train.frozen[i]` when prefix `i` names no parameter of the model.
pub fn freeze(model: RaftStereo, prefixes: &[String]) -> Result<RaftStereo> {
    if prefixes.is_empty() {
        return Ok(model);
    }
    let mut freezer = Freezer { path: PathStack::default(), prefixes, matched: Vec::new() };
    let model = model.map(&mut freezer);
    if let Some(i) = (0..prefixes.len()).find(|i| !freezer.matched.contains(i)) {
        return Err(Error::config(
            format!("train.frozen[{i}]"),
            format!(
                "'{}' names no parameter of the model (module paths such as monocular.pretrained, \
                 monocular.depth_head, encoder.fnet)",
                prefixes[i]
            ),
        ));
    }
    Ok(model)
}

#[cfg(test)]
mod tests {
    use super::under;

    #[test]
    fn prefixes_match_whole_path_segments() {
        assert!(under("monocular.pretrained.blocks.0.norm1.weight", "monocular.pretrained"));
        assert!(under("monocular.pretrained", "monocular.pretrained"));
        assert!(!under("monocular.pretrained_extra.weight", "monocular.pretrained"));
        assert!(!under("monocular.depth_feat.projects.0.weight", "monocular.depth_head"));
    }
}
