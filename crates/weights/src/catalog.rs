//! The weights known by name: the official RAFT-Stereo checkpoints of `models.zip`, the Depth
//! Anything V2 checkpoints on the Hugging Face hub, DEFOM-Stereo's on Google Drive and
//! IGEV-Stereo's (downloaded by hand), each with its source, licence, the SHA-256 its publisher
//! states where one is published, and the architecture its tensors must show.

use dgstereo_model::checkpoint_config::OfficialPreset;
use dgstereo_prior::depth_anything::DepthAnythingV2Encoder;

/// Where the official RAFT-Stereo checkpoints are published (the official `download_models.sh`).
pub const RAFT_STEREO_MODELS_URL: &str = "https://www.dropbox.com/s/ftveifyqcomiwaq/models.zip?dl=1";

/// The Hugging Face hub.
pub const HUB_ENDPOINT: &str = "https://huggingface.co";

/// Google Drive's download server (what `drive.google.com/uc?export=download` redirects to).
pub const GOOGLE_DRIVE_URL: &str = "https://drive.usercontent.google.com";

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
    /// A file shared on Google Drive, one of the files `ids` names: the first whose name is
    /// `file` (the release script lists ids without names, so the name Drive states decides).
    GoogleDrive {
        /// The file's name, as Drive states it.
        file: &'static str,
        /// The ids of the shared files that may be it, tried in order.
        ids: &'static [&'static str],
    },
    /// Published on a page no program downloads from (a Google Drive folder): the user
    /// downloads `file` there and gives its path, or places it in the cache.
    Page {
        /// The page.
        url: &'static str,
        /// The file's name there.
        file: &'static str,
    },
}

/// The architecture a checkpoint's tensors must show (checked after each download): what a
/// loader asks to learn whether a named file is, say, a DEFOM-Stereo checkpoint.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Architecture {
    /// RAFT-Stereo of this official preset.
    RaftStereo(OfficialPreset),
    /// Depth Anything V2 with this encoder.
    DepthAnythingV2(DepthAnythingV2Encoder),
    /// DEFOM-Stereo, with Depth Anything V2 of this encoder inside.
    DefomStereo(DepthAnythingV2Encoder),
    /// IGEV-Stereo (MobileNetV2 features, geometry encoding volume).
    IgevStereo,
}

impl Architecture {
    /// Why no network of this architecture loads in dgstereo, `None` where one does: every
    /// architecture of the catalog has one (RAFT-Stereo, DEFOM-Stereo, IGEV-Stereo, Depth Anything
    /// V2). A weights option refuses a name with a reason before fetching it; `weights fetch`
    /// would still download it.
    pub fn unloadable_reason(self) -> Option<&'static str> {
        match self {
            Self::RaftStereo(_) | Self::DepthAnythingV2(_) | Self::DefomStereo(_) | Self::IgevStereo => None,
        }
    }
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
    /// The SHA-256 its publisher states (the hub's LFS object id), where one is published: every
    /// download and every later load must match it. Without one the download is checked for
    /// structure only and the SHA-256 of the first fetch is recorded instead.
    pub sha256: Option<&'static str>,
    /// One line on what it is.
    pub about: &'static str,
}

const RAFT_LICENCE: &str = "MIT (princeton-vl/RAFT-Stereo)";
const DEFOM_LICENCE: &str =
    "MIT (Insta360-Research-Team/DEFOM-Stereo), with Depth Anything V2 Small inside (Apache-2.0)";
const DEFOM_LARGE_LICENCE: &str = "CC-BY-NC-4.0 (non-commercial): MIT code, but it holds Depth Anything V2 Large";

/// The Google Drive ids of DEFOM-Stereo's six released checkpoints, as the official
/// `scripts/download_models.sh` lists them (without names).
const DEFOM_IDS: &[&str] = &[
    "1XuAM4vqzura_6NKN70hMW5lFD4TafnDL",
    "1FNt-SDysG5bUOmjZ91mzH2V_TXvLCvr5",
    "1qyXKO-Nxq3ndl2H0deQpo6BSvwlGKYEg",
    "1Dy1eGDdtkp2GQYQRTvMwR-3eAzaRCe_k",
    "1duHLtUCDNIA76m6Fqwa7hv-aBMY-P3mg",
    "1xEPS7gceJSFn_IHdzebBCgQaRNGwf1aG",
];

/// IGEV-Stereo's checkpoints: a shared Google Drive folder (the official README).
const IGEV_FOLDER: &str = "https://drive.google.com/drive/folders/1SsMHRyN7808jDViMN1sKz1Nx-71JxUuz";

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

/// A Depth Anything V2 checkpoint of the hub, with the SHA-256 the hub publishes for it (its
/// LFS object id, which the hub also sends as `x-linked-etag` and names its CDN object by).
const fn depth_anything(
    name: &'static str,
    repo: &'static str,
    file: &'static str,
    encoder: DepthAnythingV2Encoder,
    sha256: &'static str,
    licence: &'static str,
    about: &'static str,
) -> NamedWeights {
    NamedWeights {
        name,
        role: Role::Prior,
        source: Source::Hub { repo, file },
        licence,
        architecture: Architecture::DepthAnythingV2(encoder),
        sha256: Some(sha256),
        about,
    }
}

const fn defom(
    name: &'static str,
    file: &'static str,
    encoder: DepthAnythingV2Encoder,
    about: &'static str,
) -> NamedWeights {
    let licence = match encoder {
        DepthAnythingV2Encoder::Vits => DEFOM_LICENCE,
        _ => DEFOM_LARGE_LICENCE,
    };
    NamedWeights {
        name,
        role: Role::Stereo,
        source: Source::GoogleDrive { file, ids: DEFOM_IDS },
        licence,
        architecture: Architecture::DefomStereo(encoder),
        sha256: None,
        about,
    }
}

/// Every checkpoint known by name, stereo weights first.
pub const CATALOG: [NamedWeights; 15] = [
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
    defom(
        "defomstereo-vits-sceneflow",
        "defomstereo_vits_sceneflow.pth",
        DepthAnythingV2Encoder::Vits,
        "DEFOM-Stereo ViT-S trained on SceneFlow (CVPR 2025)",
    ),
    defom(
        "defomstereo-vitl-sceneflow",
        "defomstereo_vitl_sceneflow.pth",
        DepthAnythingV2Encoder::Vitl,
        "DEFOM-Stereo ViT-L trained on SceneFlow (its zero-shot model)",
    ),
    defom(
        "defomstereo-vitl-kitti",
        "defomstereo_vitl_kitti.pth",
        DepthAnythingV2Encoder::Vitl,
        "DEFOM-Stereo ViT-L fine-tuned on KITTI",
    ),
    defom(
        "defomstereo-vitl-middlebury",
        "defomstereo_vitl_middlebury.pth",
        DepthAnythingV2Encoder::Vitl,
        "DEFOM-Stereo ViT-L fine-tuned on Middlebury",
    ),
    defom(
        "defomstereo-vitl-eth3d",
        "defomstereo_vitl_eth3d.pth",
        DepthAnythingV2Encoder::Vitl,
        "DEFOM-Stereo ViT-L fine-tuned on ETH3D",
    ),
    defom(
        "defomstereo-vits-rvc",
        "defomstereo_vits_rvc.pth",
        DepthAnythingV2Encoder::Vits,
        "DEFOM-Stereo ViT-S of the Robust Vision Challenge (KITTI, Middlebury, ETH3D together)",
    ),
    NamedWeights {
        name: "igev-stereo-sceneflow",
        role: Role::Stereo,
        source: Source::Page { url: IGEV_FOLDER, file: "sceneflow.pth" },
        licence: "MIT (gangweiX/IGEV)",
        architecture: Architecture::IgevStereo,
        sha256: None,
        about: "IGEV-Stereo trained on SceneFlow (CVPR 2023)",
    },
    depth_anything(
        "depth-anything-v2-small",
        "depth-anything/Depth-Anything-V2-Small",
        "depth_anything_v2_vits.pth",
        DepthAnythingV2Encoder::Vits,
        "715fade13be8f229f8a70cc02066f656f2423a59effd0579197bbf57860e1378",
        "Apache-2.0",
        "Depth Anything V2 ViT-S (24.8 M parameters)",
    ),
    depth_anything(
        "depth-anything-v2-base",
        "depth-anything/Depth-Anything-V2-Base",
        "depth_anything_v2_vitb.pth",
        DepthAnythingV2Encoder::Vitb,
        "0d2b7002e62d39d655571c371333340bd88f67ab95050c03591555aa05645328",
        "CC-BY-NC-4.0 (non-commercial)",
        "Depth Anything V2 ViT-B (97.5 M parameters; the paper's prior)",
    ),
    depth_anything(
        "depth-anything-v2-large",
        "depth-anything/Depth-Anything-V2-Large",
        "depth_anything_v2_vitl.pth",
        DepthAnythingV2Encoder::Vitl,
        "a7ea19fa0ed99244e67b624c72b8580b7e9553043245905be58796a608eb9345",
        "CC-BY-NC-4.0 (non-commercial)",
        "Depth Anything V2 ViT-L (335.3 M parameters)",
    ),
];

/// Whether `text` is a SHA-256 in hex (what the catalog pins; the hub's etag of a large file is
/// one too).
pub fn is_sha256(text: &str) -> bool {
    text.len() == 64 && text.bytes().all(|b| b.is_ascii_hexdigit())
}

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
            Source::Hub { file, .. } | Source::GoogleDrive { file, .. } | Source::Page { file, .. } => file,
        }
    }

    /// Where it is published, for people: the URL of the file, of the archive holding it, or
    /// of the page to download it from.
    pub fn origin(&self, sources: &Sources) -> String {
        match self.source {
            Source::ModelsZip { member } => format!("{} ({member})", sources.models_zip),
            Source::Hub { repo, file } => format!("{}/{repo}/resolve/main/{file}", sources.hub),
            Source::GoogleDrive { file, ids } => match ids {
                [id] => format!("{} ({file})", sources.google_drive_file(id)),
                _ => format!("Google Drive ({file}, one of the {} files of its release)", ids.len()),
            },
            Source::Page { url, file } => format!("{url} ({file}, downloaded by hand)"),
        }
    }

    /// How far a fetch of it is checked: against a published SHA-256, or for structure only.
    pub fn verification(&self) -> &'static str {
        if self.sha256.is_some() { "SHA-256 pinned" } else { "structure only" }
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
    /// Google Drive's download server (`DGSTEREO_GOOGLE_DRIVE_URL`, else [`GOOGLE_DRIVE_URL`]).
    pub google_drive: String,
}

impl Default for Sources {
    /// The public servers.
    fn default() -> Self {
        Self {
            hub: HUB_ENDPOINT.to_string(),
            models_zip: RAFT_STEREO_MODELS_URL.to_string(),
            google_drive: GOOGLE_DRIVE_URL.to_string(),
        }
    }
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
            google_drive: var("DGSTEREO_GOOGLE_DRIVE_URL", GOOGLE_DRIVE_URL).trim_end_matches('/').to_string(),
        }
    }

    /// The download address of the Google Drive file `id`.
    pub fn google_drive_file(&self, id: &str) -> String {
        format!("{}/download?id={id}&export=download", self.google_drive)
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

    #[test]
    fn pinned_hashes_are_sha256_and_vit_l_defom_carries_the_non_commercial_licence() {
        for w in &CATALOG {
            if let Some(sha) = w.sha256 {
                assert!(is_sha256(sha) && sha == sha.to_ascii_lowercase(), "{}", w.name);
            }
            if let Architecture::DefomStereo(encoder) = w.architecture {
                let non_commercial = w.licence.contains("CC-BY-NC-4.0");
                assert_eq!(non_commercial, encoder == DepthAnythingV2Encoder::Vitl, "{}", w.name);
            }
        }
        assert_eq!(CATALOG.iter().filter(|w| matches!(w.architecture, Architecture::DefomStereo(_))).count(), 6);
    }
}
