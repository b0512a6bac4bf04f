//! The weights known by name: the official RAFT-Stereo checkpoints of `models.zip` and the
//! Depth Anything V2 checkpoints on the Hugging Face hub, each with its source, licence and the
//! architecture its tensors must show.

use dgstereo_model::checkpoint_config::OfficialPreset;
use dgstereo_prior::depth_anything::DepthAnythingV2Encoder;

/// Where the official RAFT-Stereo checkpoints are published (the official `download_models.sh`).
pub const RAFT_STEREO_MODELS_URL: &str = "https://www.dropbox.com/s/ftveifyqcomiwaq/models.zip?dl=1";

/// The Hugging Face hub.
pub const HUB_ENDPOINT: &str = "https://huggingface.co";

/// What a checkpoint is for: which option takes it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// Stereo weights (`--weights`).
    Stereo,
    /// A Depth Anything V2 prior (`--prior-weights`).
    Prior,
}

/// Where a checkpoint is downloaded from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Source {
    /// A member of the official `models.zip` (one download gives all five).
    ModelsZip {
        /// The member's file name.
        member: &'static str,
    },
    /// A file of a model repository on the Hugging Face hub, at `main`.
    Hub {
        /// `owner/name`.
        repo: &'static str,
        /// The file's path in the repository.
        file: &'static str,
    },
}

/// The architecture a checkpoint's tensors must show (checked after each download).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Architecture {
    /// RAFT-Stereo of this official preset.
    RaftStereo(OfficialPreset),
    /// Depth Anything V2 with this encoder.
    DepthAnythingV2(DepthAnythingV2Encoder),
}

/// One checkpoint known by name.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NamedWeights {
    /// The name the options take (`raftstereo-middlebury`).
    pub name: &'static str,
    /// Which option takes it.
    pub role: Role,
    /// Where it is downloaded from.
    pub source: Source,
    /// Its licence, as its publisher states it.
    pub licence: &'static str,
    /// The architecture its tensors must show.
    pub architecture: Architecture,
    /// The SHA-256 of the file where one is pinned. Hub files are also checked against the
    /// hub's own SHA-256 (the LFS etag), whether pinned or not.
    pub sha256: Option<&'static str>,
    /// One line on what it is.
    pub about: &'static str,
}

const RAFT_LICENCE: &str = "MIT (princeton-vl/RAFT-Stereo)";

const fn raft(name: &'static str, member: &'static str, preset: OfficialPreset, about: &'static str) -> NamedWeights {
    NamedWeights {
        name,
        role: Role::Stereo,
        source: Source::ModelsZip { member },
        licence: RAFT_LICENCE,
        architecture: Architecture::RaftStereo(preset),
        sha256: None,
        about,
    }
}

const fn depth_anything(
    name: &'static str,
    repo: &'static str,
    file: &'static str,
    encoder: DepthAnythingV2Encoder,
    licence: &'static str,
    about: &'static str,
) -> NamedWeights {
    NamedWeights {
        name,
        role: Role::Prior,
        source: Source::Hub { repo, file },
        licence,
        architecture: Architecture::DepthAnythingV2(encoder),
        sha256: None,
        about,
    }
}

/// Every checkpoint known by name, stereo weights first.
pub const CATALOG: [NamedWeights; 8] = [
    raft(
        "raftstereo-sceneflow",
        "raftstereo-sceneflow.pth",
        OfficialPreset::Default,
        "RAFT-Stereo trained on SceneFlow (the official defaults, 32 iterations)",
    ),
    raft(
        "raftstereo-middlebury",
        "raftstereo-middlebury.pth",
        OfficialPreset::Default,
        "RAFT-Stereo fine-tuned on Middlebury",
    ),
    raft("raftstereo-eth3d", "raftstereo-eth3d.pth", OfficialPreset::Default, "RAFT-Stereo fine-tuned on ETH3D"),
    raft(
        "raftstereo-realtime",
        "raftstereo-realtime.pth",
        OfficialPreset::Realtime,
        "RAFT-Stereo realtime: shared backbone, 1/8 resolution, 2 GRU levels, slow-fast GRU, 7 iterations",
    ),
    raft(
        "iraftstereo-rvc",
        "iraftstereo_rvc.pth",
        OfficialPreset::InstanceContext,
        "iRaftStereo_RVC (Robust Vision Challenge 2022): instance-norm context",
    ),
    depth_anything(
        "depth-anything-v2-small",
        "depth-anything/Depth-Anything-V2-Small",
        "depth_anything_v2_vits.pth",
        DepthAnythingV2Encoder::Vits,
        "Apache-2.0",
        "Depth Anything V2 ViT-S (24.8 M parameters)",
    ),
    depth_anything(
        "depth-anything-v2-base",
        "depth-anything/Depth-Anything-V2-Base",
        "depth_anything_v2_vitb.pth",
        DepthAnythingV2Encoder::Vitb,
        "CC-BY-NC-4.0 (non-commercial)",
        "Depth Anything V2 ViT-B (97.5 M parameters; the paper's prior)",
    ),
    depth_anything(
        "depth-anything-v2-large",
        "depth-anything/Depth-Anything-V2-Large",
        "depth_anything_v2_vitl.pth",
        DepthAnythingV2Encoder::Vitl,
        "CC-BY-NC-4.0 (non-commercial)",
        "Depth Anything V2 ViT-L (335.3 M parameters)",
    ),
];

/// The checkpoint called `name` (`_` and `-` alike, any case: `iraftstereo_rvc` too).
pub fn find(name: &str) -> Option<&'static NamedWeights> {
    let key = name.trim().to_ascii_lowercase().replace('_', "-");
    CATALOG.iter().find(|w| w.name == key)
}

impl NamedWeights {
    /// The file name it is kept under.
    pub fn file_name(&self) -> &'static str {
        match self.source {
            Source::ModelsZip { member } => member,
            Source::Hub { file, .. } => file,
        }
    }

    /// Where it is published, for people: the URL of the file or of the archive holding it.
    pub fn origin(&self, sources: &Sources) -> String {
        match self.source {
            Source::ModelsZip { member } => format!("{} ({member})", sources.models_zip),
            Source::Hub { repo, file } => format!("{}/{repo}/resolve/main/{file}", sources.hub),
        }
    }
}

/// The servers the weights come from: the public ones, or others (a mirror, a test's loopback
/// server).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Sources {
    /// The hub's endpoint (`HF_ENDPOINT`, else [`HUB_ENDPOINT`]).
    pub hub: String,
    /// The URL of RAFT-Stereo's `models.zip` (`DGSTEREO_RAFT_STEREO_MODELS_URL`, else
    /// [`RAFT_STEREO_MODELS_URL`]).
    pub models_zip: String,
}

impl Sources {
    /// The public servers, or the ones the environment names.
    pub fn from_env() -> Self {
        let var = |name: &str, default: &str| {
            std::env::var(name).ok().filter(|v| !v.is_empty()).unwrap_or_else(|| default.to_string())
        };
        Self {
            hub: var("HF_ENDPOINT", HUB_ENDPOINT).trim_end_matches('/').to_string(),
            models_zip: var("DGSTEREO_RAFT_STEREO_MODELS_URL", RAFT_STEREO_MODELS_URL),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_found_in_any_spelling() {
        for w in &CATALOG {
            assert_eq!(find(w.name), Some(w));
            assert_eq!(find(&w.name.to_uppercase().replace('-', "_")), Some(w));
            assert_eq!(CATALOG.iter().filter(|o| o.name == w.name || o.file_name() == w.file_name()).count(), 1);
        }
        assert_eq!(find("iraftstereo_rvc").map(|w| w.file_name()), Some("iraftstereo_rvc.pth"));
        assert!(find("raftstereo").is_none() && find("").is_none());
    }
}
