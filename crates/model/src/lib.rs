//! The stereo network, composed from the stage crates.
//!
//! [`RaftStereo`] wires the fusion, encoder, cost-volume and updater stages in RAFT-Stereo's
//! order; [`ModelConfig`] chooses each stage's variant and builds the module with one `init`.
//! [`StereoModel`] is the public inference API: it pads any image size to a multiple of 32,
//! runs the network and returns positive disparity at full resolution. Official RAFT-Stereo
//! `.pth` checkpoints load directly ([`checkpoint`]) into the architecture their tensors show
//! ([`checkpoint_config`], which reads the state-dict keys through [`official_keys`]), and
//! [`verify`] compares a forward pass with the activations the official code computed.
//!
//! DEFOM-Stereo is the same network with other variants chosen ([`ModelConfig`]'s monocular
//! network, encoders that add its features, [`InitialDisparity`], the scale lookup and update);
//! its official checkpoints load through the same loader ([`checkpoint`]), their configuration
//! read from their tensors ([`defom_config`]), and [`verify_defom`] checks it against the official
//! code's activations with seeded weights ([`seeded`]).
#![deny(missing_docs)]

pub mod canonical_safetensors;
pub mod checkpoint;
pub mod checkpoint_config;
pub mod config;
pub mod defom_config;
mod encode;
mod geometry_stage;
pub mod grown_inputs;
pub mod igev_config;
pub mod inference;
pub mod initial_disparity;
mod key_shapes;
pub mod network;
pub mod official_keys;
pub mod profile;
pub mod seeded;
mod seeded_verify;
pub mod stage_backward;
mod stored_config;
mod superpixel_stage;
pub mod verify;
pub mod verify_defom;
pub mod verify_igev;

pub use config::{EncoderConfig, ModelConfig};
pub use inference::{StereoModel, TrainingDisparities, padded_disparities, padded_training_disparities};
pub use initial_disparity::InitialDisparity;
pub use network::{FlowOutput, ForwardOptions, Probe, RaftStereo, Trace};
pub use stored_config::name_the_encoder_layout;
/// The stage crates, re-exported so benchmarks and tools can drive single stages of a model
/// (their traits included) through this crate alone.
pub use {
    dgstereo_costvolume as costvolume, dgstereo_encoder as encoder, dgstereo_fusion as fusion, dgstereo_prior as prior,
    dgstereo_updater as updater,
};
