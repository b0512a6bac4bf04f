//! Finding the stereo pairs of `dgstereo infer` and naming their outputs.
//!
//! Pairs come from `-l/-r` files or glob patterns (each side sorted, then zipped, as the
//! reference demo does), from a folder (`--pairs DIR`: `*left*`/`*right*` or `im0`/`im1` names,
//! searched recursively, by the same rule as `eval --dataset folder`) or from a list file (`--list FILE`: one `LEFT RIGHT` pair per line).
//! Problems that concern one pair (a left image without its right image) become a
//! [`PairProblem`] so the other pairs still run; problems that concern the whole request (a
//! pattern matching nothing, an unreadable list) are errors.
//!
//! Design decision: an output name is the *unique part* of the left image's path. Paths are taken
//! relative to the deepest folder common to all left images, the extension and the words that only
//! say "left" (`left`, `im0`) are dropped, and what remains must differ between pairs; colliding
//! names get a `-2`, `-3`, ... suffix, so two pairs never write the same file.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use dgstereo_data::datasets::pair_finder::{SIDE_WORDS, Side, find_folder_pairs, side_key};

/// One stereo pair to process.
#[derive(Clone, Debug, PartialEq)]
pub struct PairPaths {
    /// Left image.
    pub left: PathBuf,
    /// Right image.
    pub right: PathBuf,
    /// Output name (unique among the pairs of one run).
    pub name: String,
}

/// A pair that cannot be formed (reported and counted as a failure).
#[derive(Clone, Debug, PartialEq)]
pub struct PairProblem {
    /// The file concerned.
    pub path: PathBuf,
    /// What is wrong.
    pub message: String,
}

/// The pairs found, and the ones that could not be formed.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PairList {
    /// Complete pairs, named.
    pub pairs: Vec<PairPaths>,
    /// Incomplete pairs.
    pub problems: Vec<PairProblem>,
}

fn has_glob_chars(s: &str) -> bool {
    s.contains(['*', '?', '['])
}

/// Expands files and glob patterns, each pattern's matches sorted. A plain path is kept as given
/// (a missing file is then reported when it is read, naming it).
pub fn expand_patterns(patterns: &[String]) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for pattern in patterns {
        if !has_glob_chars(pattern) {
            out.push(PathBuf::from(pattern));
            continue;
        }
        let paths = glob::glob(pattern).with_context(|| format!("'{pattern}' is not a valid glob pattern"))?;
        let mut matched: Vec<PathBuf> = paths.filter_map(Result::ok).filter(|p| p.is_file()).collect();
        if matched.is_empty() {
            bail!("'{pattern}' matches no file");
        }
        matched.sort();
        out.extend(matched);
    }
    Ok(out)
}

/// Pairs `-l` with `-r` inputs: zipped in order when both sides have as many files, otherwise
/// matched by the data crate's side words (`left`↔`right`, `im0`↔`im1`, `image_2`↔`image_3`,
/// [`dgstereo_data::datasets::pair_finder::side_key`]), unmatched files being problems.
pub fn from_left_right(left: &[String], right: &[String]) -> anyhow::Result<PairList> {
    if left.is_empty() || right.is_empty() {
        bail!("give both -l/--left and -r/--right images (files or glob patterns), or --pairs DIR, or --list FILE");
    }
    let lefts = expand_patterns(left)?;
    let rights = expand_patterns(right)?;
    if lefts.len() == rights.len() {
        return Ok(named(lefts.into_iter().zip(rights).collect(), Vec::new()));
    }
    let mut by_key: HashMap<String, PathBuf> = rights.iter().map(|r| (side_key(r, Side::Right), r.clone())).collect();
    let mut pairs = Vec::new();
    let mut problems = Vec::new();
    for l in lefts {
        match by_key.remove(&side_key(&l, Side::Left)) {
            Some(r) => pairs.push((l, r)),
            None => {
                problems.push(PairProblem { path: l, message: "missing right image: no -r file matches it".into() })
            }
        }
    }
    let mut unmatched: Vec<PathBuf> = by_key.into_values().collect();
    unmatched.sort();
    problems.extend(
        unmatched
            .into_iter()
            .map(|r| PairProblem { path: r, message: "missing left image: no -l file matches it".into() }),
    );
    Ok(named(pairs, problems))
}

/// The pairs of a folder (recursive), by the data crate's one pair rule
/// ([`dgstereo_data::datasets::pair_finder`], which `eval --dataset folder` follows too):
/// `<x>left<y>.<ext>` with `<x>right<y>.<ext>` and `im0.<ext>` with `im1.<ext>`, names holding
/// `disp`, `occ`, `mask` or `depth` not being views. A left image without its right image is a
/// problem.
pub fn from_folder(dir: &Path) -> anyhow::Result<PairList> {
    if !dir.is_dir() {
        bail!("{}: --pairs needs a folder", dir.display());
    }
    let found = find_folder_pairs(dir)?;
    if found.pairs.is_empty() && found.unpaired.is_empty() {
        bail!("{}: no stereo pairs found (expected *left*/*right* or im0/im1 image names)", dir.display());
    }
    let pairs = found.pairs.into_iter().map(|p| (p.left, p.right)).collect();
    let problems = found
        .unpaired
        .into_iter()
        .map(|u| PairProblem {
            path: u.left,
            message: format!("missing right image (expected {}.* beside it)", u.expected_right_stem),
        })
        .collect();
    Ok(named(pairs, problems))
}

/// The pairs of a list file: one `LEFT RIGHT` pair per line (whitespace or a comma between),
/// paths relative to the list's folder, `#` starting a comment. A line with one path is a problem.
pub fn from_list(list: &Path) -> anyhow::Result<PairList> {
    let text =
        std::fs::read_to_string(list).with_context(|| format!("{}: cannot read the pair list", list.display()))?;
    let base = list.parent().unwrap_or(Path::new(""));
    let mut pairs = Vec::new();
    let mut problems = Vec::new();
    for (i, line) in text.lines().enumerate() {
        let line = line.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split([',', ' ', '\t']).filter(|f| !f.is_empty()).collect();
        match fields.as_slice() {
            [l, r] => pairs.push((base.join(l), base.join(r))),
            [l] => problems.push(PairProblem {
                path: base.join(l),
                message: format!("missing right image ({} line {})", list.display(), i + 1),
            }),
            _ => bail!("{} line {}: expected 'LEFT RIGHT', found {} fields", list.display(), i + 1, fields.len()),
        }
    }
    if pairs.is_empty() && problems.is_empty() {
        bail!("{}: the pair list is empty", list.display());
    }
    Ok(named(pairs, problems))
}

fn named(pairs: Vec<(PathBuf, PathBuf)>, problems: Vec<PairProblem>) -> PairList {
    let lefts: Vec<&Path> = pairs.iter().map(|(l, _)| l.as_path()).collect();
    let names = unique_names(&lefts);
    let pairs = pairs.into_iter().zip(names).map(|((left, right), name)| PairPaths { left, right, name }).collect();
    PairList { pairs, problems }
}

/// The deepest folder containing every path.
fn common_folder(paths: &[&Path]) -> PathBuf {
    let mut common: Option<Vec<std::path::Component>> = None;
    for p in paths {
        let parent: Vec<_> = p.parent().map(|d| d.components().collect()).unwrap_or_default();
        common = Some(match common {
            None => parent,
            Some(c) => c.into_iter().zip(parent).take_while(|(a, b)| a == b).map(|(a, _)| a).collect(),
        });
    }
    common.unwrap_or_default().into_iter().collect()
}

/// Drops the words that only say "left" from a name (the data crate's left side words, and `l`
/// as in `scene_l.png`); separators left dangling are removed.
fn without_side_words(name: &str) -> String {
    let seps = ['_', '-', '.', ' '];
    let mut parts: Vec<String> = Vec::new();
    for component in name.split('/') {
        let tokens: Vec<&str> = component
            .split(seps)
            .filter(|t| {
                let t = t.to_ascii_lowercase();
                !t.is_empty() && t != "l" && !SIDE_WORDS.iter().any(|(left, _)| *left == t)
            })
            .collect();
        let joined = tokens.join("_");
        if !joined.is_empty() {
            parts.push(joined);
        }
    }
    parts.join("_")
}

/// Output names of left images: their unique part (see the module doc), sanitised to
/// `[A-Za-z0-9_.-]`, never empty, never two alike (case-insensitively).
pub fn unique_names(lefts: &[&Path]) -> Vec<String> {
    let root = common_folder(lefts);
    let mut used: HashMap<String, usize> = HashMap::new();
    lefts
        .iter()
        .map(|p| {
            let rel = p.strip_prefix(&root).unwrap_or(p).with_extension("");
            let rel = rel.to_string_lossy().replace('\\', "/");
            let mut name = without_side_words(&rel);
            if name.is_empty() {
                // `im0.png` alone: the folder names the scene, as in the reference demo.
                name = p
                    .parent()
                    .and_then(|d| d.file_name())
                    .map(|d| without_side_words(&d.to_string_lossy()))
                    .filter(|n| !n.is_empty())
                    .unwrap_or_else(|| "pair".into());
            }
            let name: String =
                name.chars().map(|c| if c.is_ascii_alphanumeric() || "_.-".contains(c) { c } else { '_' }).collect();
            let count = used.entry(name.to_ascii_lowercase()).or_insert(0);
            *count += 1;
            if *count == 1 { name } else { format!("{name}-{count}") }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(paths: &[&str]) -> Vec<String> {
        let p: Vec<&Path> = paths.iter().map(Path::new).collect();
        unique_names(&p)
    }

    #[test]
    fn names_are_the_unique_part_of_the_path() {
        assert_eq!(names(&["d/desk_left.png", "d/stairs_left.png"]), ["desk", "stairs"]);
        assert_eq!(names(&["m/Art/im0.png", "m/Bowling/im0.png"]), ["Art", "Bowling"]);
        assert_eq!(names(&["a/cones/left_rgb.png"]), ["rgb"]);
        assert_eq!(names(&["scene/im0.png"]), ["scene"]);
        assert_eq!(names(&["x/a/left.png", "x/b/left.png"]), ["a", "b"]);
    }

    #[test]
    fn colliding_names_get_a_suffix() {
        let n = names(&["d/a_left.png", "d/a_left.jpg", "d/A-left.png"]);
        assert_eq!(n.len(), 3);
        let mut lower: Vec<String> = n.iter().map(|s| s.to_ascii_lowercase()).collect();
        lower.sort();
        lower.dedup();
        assert_eq!(lower.len(), 3, "{n:?}");
    }

    #[test]
    fn infer_and_eval_pair_a_folder_alike() {
        let dir = tempfile::tempdir().unwrap();
        for sub in ["scene", "seq"] {
            std::fs::create_dir(dir.path().join(sub)).unwrap();
        }
        let files = [
            "desk_left.png",
            "desk_right.jpg",
            "desk_disp.pfm",
            "depth_left.png",
            "depth_right.png",
            "scene/im0.png",
            "scene/im1.png",
            "scene/disp0GT.pfm",
            "seq/Left_0001.png",
            "seq/Right_0001.png",
            "seq/LEFT_0002.pgm",
            "seq/RIGHT_0002.pgm",
            "lonely_left.png",
        ];
        for f in files {
            std::fs::write(dir.path().join(f), b"").unwrap();
        }
        let infer = from_folder(dir.path()).unwrap();
        let eval = dgstereo_data::datasets::folder_pairs(dir.path()).unwrap();
        let infer_pairs: Vec<(PathBuf, PathBuf)> =
            infer.pairs.iter().map(|p| (p.left.clone(), p.right.clone())).collect();
        let eval_pairs: Vec<(PathBuf, PathBuf)> =
            eval.files.iter().map(|f| (f.left.clone(), f.right.clone())).collect();
        assert_eq!(infer_pairs, eval_pairs);
        assert_eq!(infer_pairs.len(), 4, "{infer_pairs:?}");
        // The left view without its right view: a problem for infer, absent from the data set.
        assert_eq!(infer.problems.len(), 1);
        assert!(infer.problems[0].path.ends_with("lonely_left.png"));
    }

    #[test]
    fn unequal_sides_are_matched_by_name() {
        let dir = tempfile::tempdir().unwrap();
        for f in ["a_left.png", "a_right.png", "b_left.png"] {
            std::fs::write(dir.path().join(f), b"").unwrap();
        }
        let d = dir.path().display();
        let list = from_left_right(&[format!("{d}/*_left.png")], &[format!("{d}/*_right.png")]).unwrap();
        assert_eq!(list.pairs.len(), 1);
        assert_eq!(list.pairs[0].name, "a");
        assert_eq!(list.problems.len(), 1);
        assert!(list.problems[0].path.ends_with("b_left.png"));
        let folder = from_folder(dir.path()).unwrap();
        assert_eq!((folder.pairs.len(), folder.problems.len()), (1, 1));
    }
}
