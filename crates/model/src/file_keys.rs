//! The checkpoint keys of the encoder layout's parameters.
//!
//! The layout is a module enum, so the module paths of its parameters carry the variant
//! (`encoder.Separate.fnet.conv1.weight`); checkpoint files keep the reference's keys
//! (`fnet.conv1.weight`), as official checkpoints and the bundled weights have them. Saving
//! drops the `encoder.<variant>.` prefix; loading puts back the variant of the model built.
//! (Official `.pth` files load with enum variants skipped, so there the prefix is `encoder.`.)

use crate::RaftStereo;

/// The pattern and replacement that turn a module path into its file key.
pub const TO_FILE: (&str, &str) = (r"^encoder\.[A-Z][A-Za-z0-9]*\.", "");

/// The pattern and replacement that turn a file key into a module path of `model`: the
/// layouts' fields (`fnet`, `cnet`, `conv2`; IGEV-Stereo's `feature`, `stem_2`, `stem_4`) go back
/// under the encoder's variant.
pub fn from_file(model: &RaftStereo) -> (&'static str, String) {
    (r"^(fnet|cnet|conv2|feature|stem_2|stem_4)\.", format!("encoder.{}.$1.", model.encoder.variant_name()))
}
