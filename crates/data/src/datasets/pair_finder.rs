//! The one rule by which the files of a folder become stereo pairs: `dgstereo infer --pairs DIR`
//! and the `folder` data set (`dgstereo eval --dataset folder`, training data) both call
//! [`find_folder_pairs`], so a folder pairs the same way whichever command reads it.
//!
//! The rule:
//! - the folder is searched recursively, files in sorted order;
//! - a file can be a view of a pair when its extension is an image's (`png`, `jpg`, `jpeg`,
//!   `bmp`, `tif`, `tiff`, `ppm`, `pgm`, any case) and its name holds none of `disp`, `occ`,
//!   `mask`, `depth` (any case: ground truth, masks and priors lie beside the views);
//! - a left view's stem is `im0` (any case), or holds `left` (any case; the first occurrence is
//!   the side word);
//! - its right view is the file of the same folder whose stem is the left stem with `im0` turned
//!   into `im1`, or the side word into `right` written in the side word's case (`left` ->
//!   `right`, `Left` -> `Right`, `LEFT` -> `RIGHT`), any image extension;
//! - a left view without its right view is reported as unpaired, never silently dropped; each
//!   caller decides what to do with it (`infer` counts it as a failed pair, a data set skips it).
//!
//! Views given as two lists (`infer -l ... -r ...` of unequal lengths) pair by [`side_key`]: the
//! whole path with its side words ([`SIDE_WORDS`], folder names such as KITTI's `image_2` and
//! `image_3` among them) neutralised.

use std::path::{Path, PathBuf};

use dgstereo_core::Result;

use super::sceneflow::walk;

/// The extensions (lower case) of the files that can be views of a pair.
pub const PAIR_IMAGE_EXTENSIONS: [&str; 8] = ["png", "jpg", "jpeg", "bmp", "tif", "tiff", "ppm", "pgm"];

/// Words (lower case) that mark a file as not a view: ground truth, masks, priors.
const NOT_A_VIEW: [&str; 4] = ["disp", "occ", "mask", "depth"];

/// The words (lower case) that name a view's side, each left word with its right word: in a
/// stem (`left`, `im0`) or in a folder's name (KITTI's `image_2`/`image_3`, its stereo
/// flow's `colored_0`/`colored_1`).
pub const SIDE_WORDS: [(&str, &str); 4] =
    [("left", "right"), ("im0", "im1"), ("image_2", "image_3"), ("colored_0", "colored_1")];

/// Which view of a pair a path is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The left (reference) view.
    Left,
    /// The right view.
    Right,
}

/// The key a left view shares with its right view: the folder and stem, lower case, with every
/// side word of `side` ([`SIDE_WORDS`]) replaced by `#`.
pub fn side_key(path: &Path, side: Side) -> String {
    let stem = path.file_stem().map(|s| s.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let parent = path.parent().map(|d| d.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let mut key = format!("{parent}/{stem}");
    for (left, right) in SIDE_WORDS {
        key = key.replace(if side == Side::Left { left } else { right }, "#");
    }
    key
}

/// One pair of a folder.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FolderPair {
    /// The left view.
    pub left: PathBuf,
    /// The right view (same folder).
    pub right: PathBuf,
}

/// A left view whose right view is missing.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnpairedLeft {
    /// The left view.
    pub left: PathBuf,
    /// The stem its right view would have.
    pub expected_right_stem: String,
}

/// What [`find_folder_pairs`] found, each list in the folder's sorted order.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FolderPairs {
    /// Complete pairs.
    pub pairs: Vec<FolderPair>,
    /// Left views without their right view.
    pub unpaired: Vec<UnpairedLeft>,
}

/// Whether `path` can be a view of a pair (see the module doc).
pub fn is_view(path: &Path) -> bool {
    let image = path
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| PAIR_IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
    let name = path.file_name().map(|n| n.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    image && !NOT_A_VIEW.iter().any(|w| name.contains(w))
}

/// `stem` with its side word (the first `left`, any case) replaced by `word`; `None` when the
/// stem holds no side word.
pub fn replace_side_word(stem: &str, word: &str) -> Option<String> {
    let at = stem.to_ascii_lowercase().find("left")?;
    Some(format!("{}{word}{}", &stem[..at], &stem[at + 4..]))
}

/// The right view's stem for a left view's stem; `None` when the stem does not name a left view.
pub fn right_stem(stem: &str) -> Option<String> {
    if stem.eq_ignore_ascii_case("im0") {
        return Some(format!("{}1", &stem[..2]));
    }
    let at = stem.to_ascii_lowercase().find("left")?;
    let right = match &stem[at..at + 4] {
        "Left" => "Right",
        "LEFT" => "RIGHT",
        _ => "right",
    };
    replace_side_word(stem, right)
}

/// The pairs of the folder `root` (recursive), by the rule of the module doc.
pub fn find_folder_pairs(root: &Path) -> Result<FolderPairs> {
    let mut files = Vec::new();
    walk(root, &mut files)?;
    let views: Vec<&PathBuf> = files.iter().filter(|p| is_view(p)).collect();
    let mut found = FolderPairs::default();
    for left in &views {
        let stem = left.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let Some(want) = right_stem(&stem) else { continue };
        let right = views.iter().find(|q| {
            q.parent() == left.parent() && q.file_stem().is_some_and(|s| s.to_string_lossy() == want.as_str())
        });
        match right {
            Some(right) => found.pairs.push(FolderPair { left: (*left).clone(), right: (*right).clone() }),
            None => found.unpaired.push(UnpairedLeft { left: (*left).clone(), expected_right_stem: want }),
        }
    }
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn right_stems_follow_left_stems_in_their_case() {
        assert_eq!(right_stem("desk_left").as_deref(), Some("desk_right"));
        assert_eq!(right_stem("Left_0001").as_deref(), Some("Right_0001"));
        assert_eq!(right_stem("LEFT").as_deref(), Some("RIGHT"));
        assert_eq!(right_stem("im0").as_deref(), Some("im1"));
        assert_eq!(right_stem("IM0").as_deref(), Some("IM1"));
        assert_eq!(right_stem("image"), None);
        assert_eq!(replace_side_word("Left_0001", "disp").as_deref(), Some("disp_0001"));
    }

    #[test]
    fn listed_views_share_a_key_with_their_other_side() {
        let key = |p: &str, side| side_key(Path::new(p), side);
        assert_eq!(key("kitti/image_2/000000_10.png", Side::Left), key("kitti/image_3/000000_10.png", Side::Right));
        assert_eq!(key("a/Left_03.jpg", Side::Left), key("a/right_03.png", Side::Right));
        assert_eq!(key("scene/im0.png", Side::Left), key("scene/im1.png", Side::Right));
        assert_ne!(key("a/left_03.png", Side::Left), key("a/right_04.png", Side::Right));
        assert_ne!(key("x/left.png", Side::Left), key("y/right.png", Side::Right));
    }

    #[test]
    fn ground_truth_and_masks_are_not_views() {
        assert!(is_view(Path::new("a/desk_left.PNG")) && is_view(Path::new("im0.pgm")));
        for name in ["disp_left.png", "desk_occ_left.png", "mask0nocc.png", "depth_left.png", "left.pfm"] {
            assert!(!is_view(Path::new(name)), "{name}");
        }
    }

    #[test]
    fn a_folder_gives_its_pairs_and_its_unpaired_left_views() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::create_dir(dir.path().join("scene")).unwrap();
        for f in ["a_left.png", "a_right.jpg", "b_left.png", "scene/im0.png", "scene/im1.png", "a_disp.png"] {
            std::fs::write(dir.path().join(f), b"").unwrap();
        }
        let found = find_folder_pairs(dir.path()).unwrap();
        let pairs: Vec<(PathBuf, PathBuf)> = found
            .pairs
            .iter()
            .map(|p| {
                (p.left.strip_prefix(dir.path()).unwrap().into(), p.right.strip_prefix(dir.path()).unwrap().into())
            })
            .collect();
        assert_eq!(
            pairs,
            [("a_left.png".into(), "a_right.jpg".into()), ("scene/im0.png".into(), "scene/im1.png".into())]
        );
        assert_eq!(found.unpaired.len(), 1);
        assert!(found.unpaired[0].left.ends_with("b_left.png"));
        assert_eq!(found.unpaired[0].expected_right_stem, "b_right");
    }
}
