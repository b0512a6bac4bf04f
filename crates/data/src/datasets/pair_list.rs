//! The stereo pairs a user names (`dgstereo infer`) and the names of their outputs.
//!
//! Pairs come from two lists of files or glob patterns (each side sorted, then zipped, as the
//! reference demo does; [`from_left_right`]), from a folder (`*left*`/`*right*` or `im0`/`im1`
//! names, searched recursively, by the [`super::pair_finder`] rule the `folder` data set follows
//! too; [`from_folder`]) or from a list file (one `LEFT RIGHT` pair per line; [`from_list`]).
//! Problems that concern one pair (a left image without its right image) become a
//! [`PairProblem`] so the other pairs still run; problems that concern the whole request (a
//! pattern matching nothing, an unreadable list) are errors naming the pattern or file.
//!
//! Design decision: an output name is the *unique part* of the left image's path. Paths are taken
//! relative to the deepest folder common to all left images, the extension and the words that only
//! say "left" (`left`, `im0`) are dropped, and what remains must differ between pairs; colliding
//! names get a `-2`, `-3`, ... suffix, so two pairs never write the same file.

use std::collections::HashMap;
use std::io::ErrorKind;
use std::path::{Path, PathBuf};

use dgstereo_core::{Error, Result};

use super::pair_finder::{SIDE_WORDS, Side, find_folder_pairs, side_key};

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

/// A pair that cannot be formed (reported and counted as a failure), or one that failed.
#[derive(Clone, Debug, PartialEq)]
pub struct PairProblem {
    /// The file concerned.
    pub path: PathBuf,
    /// What is wrong.
    pub message: String,
}

impl PairProblem {
    /// `FILE: problem` on one line, without naming the file twice when the message already does.
    pub fn line(&self) -> String {
        if self.message.contains(&*self.path.to_string_lossy()) {
            self.message.clone()
        } else {
            format!("{}: {}", self.path.display(), self.message)
        }
    }
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

/// An error about the glob pattern `pattern` (named as the path at fault).
fn pattern_error(pattern: &str, kind: ErrorKind, message: String) -> Error {
    Error::io(pattern, std::io::Error::new(kind, message))
}

/// Expands files and glob patterns, each pattern's matches sorted. A plain path is kept as given
/// (a missing file is then reported when it is read, naming it).
///
/// # Errors
/// A pattern that is not valid or matches no file ([`Error::Io`], naming the pattern).
pub fn expand_patterns(patterns: &[String]) -> Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for pattern in patterns {
        if !has_glob_chars(pattern) {
            out.push(PathBuf::from(pattern));
            continue;
        }
        let paths = glob::glob(pattern)
            .map_err(|e| pattern_error(pattern, ErrorKind::InvalidInput, format!("not a valid glob pattern: {e}")))?;
        let mut matched: Vec<PathBuf> = paths.filter_map(Result::ok).filter(|p| p.is_file()).collect();
        if matched.is_empty() {
            return Err(pattern_error(pattern, ErrorKind::NotFound, "matches no file".into()));
        }
        matched.sort();
        out.extend(matched);
    }
    Ok(out)
}

/// Pairs `-l` with `-r` inputs: zipped in order when both sides have as many files, otherwise
/// matched by the data crate's side words (`left`↔`right`, `im0`↔`im1`, `image_2`↔`image_3`,
/// [`side_key`]), unmatched files being problems.
///
/// # Errors
/// A side without files or patterns (keyed `left` or `right`), or a pattern
/// [`expand_patterns`] refuses.
pub fn from_left_right(left: &[String], right: &[String]) -> Result<PairList> {
    for (key, given) in [("left", left), ("right", right)] {
        if given.is_empty() {
            return Err(Error::config(key, "no images given: both sides need files or glob patterns"));
        }
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

/// The pairs of a folder (recursive), by the crate's one pair rule ([`super::pair_finder`],
/// which the `folder` data set follows too):
/// `<x>left<y>.<ext>` with `<x>right<y>.<ext>` and `im0.<ext>` with `im1.<ext>`, names holding
/// `disp`, `occ`, `mask` or `depth` not being views. A left image without its right image is a
/// problem.
///
/// # Errors
/// `dir` is not a folder, or holds no view of a pair ([`Error::Format`], naming it).
pub fn from_folder(dir: &Path) -> Result<PairList> {
    if !dir.is_dir() {
        return Err(Error::io(dir, std::io::Error::new(ErrorKind::NotADirectory, "not a folder")));
    }
    let found = find_folder_pairs(dir)?;
    if found.pairs.is_empty() && found.unpaired.is_empty() {
        return Err(Error::format(dir, "no stereo pairs found (expected *left*/*right* or im0/im1 image names)"));
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
///
/// # Errors
/// The list cannot be read, a line holds more than two paths, or the list holds none
/// (naming the list, and the line).
pub fn from_list(list: &Path) -> Result<PairList> {
    let text = std::fs::read_to_string(list)
        .map_err(|e| Error::io(list, std::io::Error::new(e.kind(), format!("cannot read the pair list: {e}"))))?;
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
            _ => {
                let message = format!("line {}: expected 'LEFT RIGHT', found {} fields", i + 1, fields.len());
                return Err(Error::format(list, message));
            }
        }
    }
    if pairs.is_empty() && problems.is_empty() {
        return Err(Error::format(list, "the pair list is empty"));
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

/// Drops the words that only say "left" from a name (the crate's left side words, and `l`
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
        let eval = super::super::folder_pairs(dir.path()).unwrap();
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
        assert_eq!(list.problems[0].line(), format!("{d}/b_left.png: missing right image: no -r file matches it"));
        let named = PairProblem { path: "x.png".into(), message: "x.png: truncated".into() };
        assert_eq!(named.line(), "x.png: truncated");
        let folder = from_folder(dir.path()).unwrap();
        assert_eq!((folder.pairs.len(), folder.problems.len()), (1, 1));
    }

    #[test]
    fn whole_request_problems_are_typed_and_name_their_file() {
        let dir = tempfile::tempdir().unwrap();
        let pattern = format!("{}/*_left.png", dir.path().display());
        let e = expand_patterns(std::slice::from_ref(&pattern)).unwrap_err();
        assert!(
            matches!(&e, Error::Io { path, source } if path == Path::new(&pattern) && source.kind() == ErrorKind::NotFound),
            "{e}"
        );
        let e = from_left_right(&[], &[pattern]).unwrap_err();
        assert!(matches!(&e, Error::Config(p) if p.key == "left"), "{e}");
        let list = dir.path().join("pairs.txt");
        std::fs::write(&list, "# only a comment\n").unwrap();
        assert_eq!(from_list(&list).unwrap_err().to_string(), format!("{}: the pair list is empty", list.display()));
        std::fs::write(&list, "a.png b.png\na.png b.png c.png\n").unwrap();
        let e = from_list(&list).unwrap_err();
        assert!(
            matches!(&e, Error::Format { path, message } if path == &list && message.starts_with("line 2:")),
            "{e}"
        );
        let e = from_folder(&list).unwrap_err();
        assert!(matches!(&e, Error::Io { source, .. } if source.kind() == ErrorKind::NotADirectory), "{e}");
        let e = from_folder(dir.path()).unwrap_err();
        assert!(e.to_string().contains("no stereo pairs found"), "{e}");
    }
}
