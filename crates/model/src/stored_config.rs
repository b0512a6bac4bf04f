//! The model configuration a checkpoint stores in its metadata (`model_config`, JSON).
//!
//! Our safetensors checkpoints record the [`ModelConfig`] they were saved from, and a loader
//! builds the network from it. The encoder layout is one key, `encoder.layout`; checkpoints that
//! name it by the two keys `encoder.shared_backbone` (a bool) and `encoder.feature_network`
//! (`residual` or `mobilenet-pyramid`), the bundled weights among them, name the same three
//! layouts, and [`ModelConfig::from_checkpoint_json`] reads them as the layout they name. A run
//! folder's `config.toml` written before the rename is read the same way when a run resumes
//! ([`name_the_encoder_layout`]). An experiment file has no such reading: there either key is an
//! unknown key.

use serde::de::Error as _;
use serde_json::{Map, Value};

use crate::ModelConfig;

impl ModelConfig {
    /// The configuration a checkpoint's `model_config` metadata entry holds.
    ///
    /// # Errors
    /// The text is not JSON, not a configuration, or names its encoder layout by both `layout`
    /// and the two-key form, or by a pair that is no layout (`shared_backbone = true` with the
    /// MobileNetV2 pyramid).
    pub fn from_checkpoint_json(json: &str) -> serde_json::Result<Self> {
        let mut value: Value = serde_json::from_str(json)?;
        name_the_encoder_layout(&mut value)?;
        serde_json::from_value(value)
    }
}

/// Replaces `encoder.shared_backbone` and `encoder.feature_network` of a stored model
/// configuration (a checkpoint's, or a run folder's `config.toml` read as a value) by the
/// `encoder.layout` they name; a configuration without them is left as it is.
///
/// # Errors
/// The encoder names its layout by both forms, or by a pair that is no layout.
pub fn name_the_encoder_layout(model: &mut Value) -> serde_json::Result<()> {
    match model.get_mut("encoder").and_then(Value::as_object_mut) {
        Some(encoder) => name_the_layout(encoder),
        None => Ok(()),
    }
}

/// Replaces `shared_backbone` and `feature_network` in an encoder table by the `layout` they
/// name; a table without them is left as it is.
fn name_the_layout(encoder: &mut Map<String, Value>) -> serde_json::Result<()> {
    let shared = encoder.remove("shared_backbone");
    let network = encoder.remove("feature_network");
    if shared.is_none() && network.is_none() {
        return Ok(());
    }
    if encoder.contains_key("layout") {
        return Err(serde_json::Error::custom(
            "encoder: `layout` beside `shared_backbone`/`feature_network`, which name the layout too",
        ));
    }
    let layout = match (shared.as_ref().map(Value::as_bool), network.as_ref().map(Value::as_str)) {
        (None | Some(Some(false)), None | Some(Some("residual"))) => "separate",
        (Some(Some(true)), None | Some(Some("residual"))) => "shared-backbone",
        (None | Some(Some(false)), Some(Some("mobilenet-pyramid"))) => "mobilenet-pyramid",
        _ => {
            return Err(serde_json::Error::custom(format!(
                "encoder: shared_backbone = {} with feature_network = {} names no encoder layout",
                shared.map_or("(absent)".into(), |v| v.to_string()),
                network.map_or("(absent)".into(), |v| v.to_string()),
            )));
        }
    };
    encoder.insert("layout".into(), layout.into());
    Ok(())
}

#[cfg(test)]
mod tests {
    use dgstereo_encoder::EncoderLayout;

    use super::*;

    fn layout_of(encoder: &str) -> serde_json::Result<EncoderLayout> {
        ModelConfig::from_checkpoint_json(&format!("{{\"encoder\":{encoder}}}")).map(|c| c.encoder.layout)
    }

    /// Each two-key form reads as the layout it names; `layout` itself reads as written.
    #[test]
    fn the_two_key_form_names_each_layout() {
        let cases = [
            (r#"{"shared_backbone":false}"#, EncoderLayout::Separate),
            (r#"{"shared_backbone":true,"feature_dim":128}"#, EncoderLayout::SharedBackbone),
            (r#"{"shared_backbone":true,"feature_network":"residual"}"#, EncoderLayout::SharedBackbone),
            (r#"{"shared_backbone":false,"feature_network":"mobilenet-pyramid"}"#, EncoderLayout::MobilenetPyramid),
            (r#"{"feature_network":"mobilenet-pyramid"}"#, EncoderLayout::MobilenetPyramid),
            (r#"{"layout":"shared-backbone"}"#, EncoderLayout::SharedBackbone),
            (r#"{}"#, EncoderLayout::Separate),
        ];
        for (encoder, layout) in cases {
            assert_eq!(layout_of(encoder).unwrap_or_else(|e| panic!("{encoder}: {e}")), layout, "{encoder}");
        }
    }

    /// A pair that is no layout, or both forms at once, is an error naming the keys.
    #[test]
    fn contradictions_are_refused() {
        for encoder in [
            r#"{"shared_backbone":true,"feature_network":"mobilenet-pyramid"}"#,
            r#"{"shared_backbone":"yes"}"#,
            r#"{"shared_backbone":false,"layout":"separate"}"#,
        ] {
            let message = layout_of(encoder).expect_err(encoder).to_string();
            assert!(message.contains("shared_backbone"), "{message}");
        }
    }

    /// The bundled weights' configuration reads, as separate encoders.
    #[test]
    fn the_bundled_weights_configuration_reads() {
        for name in ["raft-stereo-default", "paper-default"] {
            let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
                .join(format!("../../assets/weights/{name}.safetensors"));
            let json = crate::checkpoint::safetensors_metadata(&path, "model_config").unwrap().expect("model_config");
            let config = ModelConfig::from_checkpoint_json(&json).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(config.encoder.layout, EncoderLayout::Separate, "{name}");
            config.validate().unwrap_or_else(|e| panic!("{name}: {e}"));
        }
    }
}
