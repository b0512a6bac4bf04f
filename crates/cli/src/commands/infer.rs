//! `dgstereo infer`: disparity (and depth, point clouds) of the user's stereo pairs.
//!
//! Whole-run problems (no pairs, weights that do not load or fit the experiment, a calibration
//! that does not parse) stop the command before any pair runs. Per-pair problems (a missing right
//! image, an unreadable or truncated file, views of different sizes) are reported as one line
//! naming the file, the other pairs still run, the failures are listed at the end and the exit
//! status is non-zero. A panic inside the model is caught and reported the same way, as an
//! internal error of that pair.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;
use dgstereo_data::load_rgb;
use dgstereo_inference::calibration::{Adjustment, Calibration, Rescaled};
use dgstereo_inference::pointcloud::PlyEncoding;
use dgstereo_inference::{Engine, PredictOptions, check_same_size};
use indicatif::{ProgressBar, ProgressStyle};

use crate::engine::{ModelArgs, describe, error_line, flag_names, load_engine, with_flags};
use crate::inputs::{PairList, PairPaths, from_folder, from_left_right, from_list};
use crate::outputs::{OutputOptions, SaveKind, calibration_beside, write_outputs};

/// Options of inference.
#[derive(Args)]
pub struct InferArgs {
    /// Left image(s): files or glob patterns (sorted, then zipped with --right).
    #[arg(short, long, num_args = 1..)]
    left: Vec<String>,
    /// Right image(s): files or glob patterns.
    #[arg(short, long, num_args = 1..)]
    right: Vec<String>,
    /// A folder of pairs: `*left*`/`*right*` or `im0`/`im1` image names (searched recursively).
    #[arg(long, conflicts_with_all = ["left", "right", "list"])]
    pairs: Option<PathBuf>,
    /// A text file with one `LEFT RIGHT` pair per line (paths relative to the file).
    #[arg(long, conflicts_with_all = ["left", "right"])]
    list: Option<PathBuf>,
    /// Output folder.
    #[arg(short, long, default_value = "out/infer")]
    out: PathBuf,
    /// Outputs, comma-separated: pfm, npy, png16, color, preview (left image and colour map side
    /// by side), depth, ply, rejected (the pixels --lr-check replaced).
    #[arg(long, value_enum, value_delimiter = ',', default_value = "pfm,color")]
    save: Vec<SaveKind>,
    /// Calibration for depth and ply: Middlebury calib.txt, JSON (fx, fy, cx, cy, baseline) or
    /// K.txt (default: a calib.txt or K.txt beside each left image). It applies to the image size
    /// it was made for; a resize at the same aspect ratio is applied with a note, any other size
    /// is an error unless --calib-crop / --calib-scale say how the images were made.
    #[arg(long)]
    calib: Option<PathBuf>,
    /// The pairs are crops of the calibrated images whose top-left corner is at X,Y (pixels of
    /// the calibrated image): the principal point moves by (-X, -Y).
    #[arg(long, value_name = "X,Y", value_parser = parse_crop)]
    calib_crop: Option<(f64, f64)>,
    /// The pairs are the calibrated images (after --calib-crop) resized by S, or by SX
    /// horizontally and SY vertically: fx, cx and doffs scale by SX, fy and cy by SY.
    #[arg(long, value_name = "S|SX,SY", value_parser = parse_scale)]
    calib_scale: Option<(f64, f64)>,
    /// Farthest point kept in point clouds, metres (default: the calibration's depth range, else
    /// the depth of a 1-pixel disparity).
    #[arg(long)]
    max_depth: Option<f64>,
    /// PLY encoding.
    #[arg(long, value_enum, default_value_t = PlyEncoding::Binary)]
    ply_encoding: PlyEncoding,
    #[command(flatten)]
    model: ModelArgs,
}

/// Two numbers `A,B`.
fn parse_pair(s: &str) -> Result<(f64, f64), String> {
    let numbers: Vec<f64> = s
        .split(',')
        .map(|v| v.trim().parse::<f64>().map_err(|_| format!("'{v}' is not a number")))
        .collect::<Result<_, _>>()?;
    match numbers[..] {
        [a, b] => Ok((a, b)),
        _ => Err(format!("'{s}': expected two numbers A,B")),
    }
}

/// `--calib-crop X,Y`: a corner of non-negative pixels.
fn parse_crop(s: &str) -> Result<(f64, f64), String> {
    let (x, y) = parse_pair(s)?;
    if !(x.is_finite() && y.is_finite() && x >= 0.0 && y >= 0.0) {
        return Err(format!("'{s}': the corner X,Y must be pixels >= 0"));
    }
    Ok((x, y))
}

/// `--calib-scale S` or `SX,SY`: positive factors.
fn parse_scale(s: &str) -> Result<(f64, f64), String> {
    let (sx, sy) = match s.trim().parse::<f64>() {
        Ok(v) => (v, v),
        Err(_) => parse_pair(s)?,
    };
    if !(sx.is_finite() && sy.is_finite() && sx > 0.0 && sy > 0.0) {
        return Err(format!("'{s}': the factors must be positive numbers"));
    }
    Ok((sx, sy))
}

fn find_pairs(a: &InferArgs) -> anyhow::Result<PairList> {
    match (&a.pairs, &a.list) {
        (Some(dir), _) => from_folder(dir),
        (None, Some(list)) => from_list(list),
        (None, None) => from_left_right(&a.left, &a.right),
    }
}

/// A failed pair: the file at fault (or the pair) and the problem, on one line.
struct Failure {
    what: PathBuf,
    message: String,
}

impl Failure {
    /// `FILE: problem`, without naming the file twice when the message already does.
    fn line(&self) -> String {
        if self.message.contains(&*self.what.to_string_lossy()) {
            self.message.clone()
        } else {
            format!("{}: {}", self.what.display(), self.message)
        }
    }
}

pub fn run(a: InferArgs) -> anyhow::Result<ExitCode> {
    infer(a).map_err(|e| anyhow::anyhow!(error_line(&e)))
}

fn infer(a: InferArgs) -> anyhow::Result<ExitCode> {
    let start = Instant::now();
    let list = find_pairs(&a)?;
    let global_calib = a.calib.as_deref().map(Calibration::load).transpose()?;
    if let Some(m) = a.max_depth
        && !(m.is_finite() && m > 0.0)
    {
        bail!("--max-depth must be a positive number of metres");
    }
    let kinds = dedup(&a.save);
    let adjustment = Adjustment { crop: a.calib_crop, scale: a.calib_scale };
    if !adjustment.is_none() && !kinds.iter().any(|k| k.needs_calibration()) {
        bail!(
            "--calib-crop and --calib-scale adjust the calibration of depth and ply outputs: add --save depth or ply"
        );
    }
    if kinds.contains(&SaveKind::Rejected) && a.model.lr_check.is_none() {
        bail!("--save rejected writes the pixels the left-right check replaced: add --lr-check");
    }
    if global_calib.is_none() && kinds.iter().any(|k| k.needs_calibration()) {
        // A whole-run problem: found before the model loads, not once per pair.
        let missing: Vec<String> = list
            .pairs
            .iter()
            .filter(|p| calibration_beside(&p.left).is_none())
            .map(|p| p.left.display().to_string())
            .collect();
        if !missing.is_empty() {
            bail!(
                "depth and ply outputs need a calibration, and {} of {} pair(s) have none beside the left image ({}{}): pass --calib FILE, or put calib.txt or K.txt beside the images",
                missing.len(),
                list.pairs.len(),
                missing.iter().take(3).cloned().collect::<Vec<_>>().join(", "),
                if missing.len() > 3 { ", ..." } else { "" }
            );
        }
    }
    let (engine, options) = load_engine(&a.model)?;
    std::fs::create_dir_all(&a.out).with_context(|| format!("{}: cannot create the output folder", a.out.display()))?;
    let opts = OutputOptions { dir: a.out.clone(), kinds, max_depth: a.max_depth, ply: a.ply_encoding };
    let calibration = CalibrationChoice { global: global_calib.as_ref(), adjustment };
    let mut notes: Vec<String> = Vec::new();

    let mut failures: Vec<Failure> =
        list.problems.iter().map(|p| Failure { what: p.path.clone(), message: p.message.clone() }).collect();
    for f in &failures {
        eprintln!("error: {}", f.line());
    }
    let total = list.pairs.len();
    eprintln!("configuration: {}", describe(&engine, &options));
    eprintln!(
        "{total} pair(s), weights {}, {} iterations, output {}",
        engine.weights().display(),
        options.iters,
        a.out.display()
    );
    let bar = ProgressBar::new(total as u64);
    bar.set_style(
        ProgressStyle::with_template("{elapsed_precise} [{bar:30}] {pos}/{len} pairs  {per_sec}  eta {eta}  {msg}")
            .unwrap_or_else(|_| ProgressStyle::default_bar())
            .progress_chars("=> "),
    );
    let previous_hook = std::panic::take_hook();
    std::panic::set_hook(Box::new(|_| {}));
    let mut done = 0usize;
    for pair in &list.pairs {
        bar.set_message(pair.name.clone());
        let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            process_pair(&engine, &options, pair, &opts, &calibration)
        }));
        match outcome {
            Ok(Ok((line, note))) => {
                done += 1;
                // A rescaled calibration is said once for each size it was rescaled to.
                if let Some(note) = note.map(|n| n.to_string())
                    && !notes.contains(&note)
                {
                    bar.suspend(|| eprintln!("note: {note}"));
                    notes.push(note);
                }
                bar.suspend(|| println!("{line}"));
            }
            Ok(Err(e)) => {
                let f = Failure { what: pair.left.clone(), message: error_line(&e) };
                bar.suspend(|| eprintln!("error: {}", f.line()));
                failures.push(f);
            }
            Err(panic) => {
                let msg = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_else(|| "unknown panic".into());
                let f = Failure {
                    what: pair.left.clone(),
                    message: format!("{}: internal error: {}", pair.left.display(), msg.replace(['\n', '\r'], " ")),
                };
                bar.suspend(|| eprintln!("error: {}", f.line()));
                failures.push(f);
            }
        }
        bar.inc(1);
    }
    bar.finish_and_clear();
    std::panic::set_hook(previous_hook);

    let seconds = start.elapsed().as_secs_f64();
    let attempted = total + list.problems.len();
    println!(
        "summary: {done} of {attempted} pair(s) done, {} failed, {seconds:.1} s ({:.2} pairs/s)",
        failures.len(),
        done as f64 / seconds.max(1e-9)
    );
    if failures.is_empty() {
        return Ok(ExitCode::SUCCESS);
    }
    eprintln!("failed:");
    for f in &failures {
        eprintln!("  {}", f.line());
    }
    Ok(ExitCode::FAILURE)
}

fn dedup(kinds: &[SaveKind]) -> Vec<SaveKind> {
    let mut out = Vec::new();
    for k in kinds {
        if !out.contains(k) {
            out.push(*k);
        }
    }
    out
}

/// The calibration of the run: `--calib` (else the file beside each left image) and how the
/// pairs were made from the calibrated images.
struct CalibrationChoice<'a> {
    global: Option<&'a Calibration>,
    adjustment: Adjustment,
}

/// Reads, predicts and writes one pair; returns the line reporting it and the notice of a
/// calibration rescaled to the pair's size.
fn process_pair(
    engine: &Engine,
    options: &PredictOptions,
    pair: &PairPaths,
    opts: &OutputOptions,
    calibration: &CalibrationChoice<'_>,
) -> anyhow::Result<(String, Option<Rescaled>)> {
    let t0 = Instant::now();
    let left = load_rgb(&pair.left)?;
    let right = load_rgb(&pair.right)?;
    let both = || format!("{} + {}", pair.left.display(), pair.right.display());
    check_same_size(&left, &right).map_err(|e| anyhow::Error::from(e).context(both()))?;
    let (calib, note) = if opts.kinds.iter().any(|k| k.needs_calibration()) {
        let loaded = calibration_for(&pair.left, calibration.global)?;
        let (calib, note) = loaded.adjusted(&calibration.adjustment, left.width, left.height).map_err(|e| {
            let hint = match &e {
                dgstereo_core::Error::Shape(_) if calibration.adjustment.is_none() => {
                    ": --calib-crop X,Y and/or --calib-scale S"
                }
                _ => "",
            };
            anyhow::anyhow!("{}{hint}", flag_names(&e.to_string()))
        })?;
        (Some(calib), note)
    } else {
        (None, None)
    };
    let prediction = engine.predict(&left, &right, &pair.name, options).map_err(|e| with_flags(e).context(both()))?;
    let (disp, info) = (prediction.disparity, prediction.info);
    let written = write_outputs(opts, &pair.name, &left, &disp, calib.as_ref(), info.rejected.as_ref())?;
    // Depth is `inf` where the disparity gives no point in front of the cameras: say how often.
    let no_depth = calib.as_ref().map_or(0, |c| disp.data.iter().filter(|d| c.depth(**d).is_infinite()).count());
    let no_depth = if no_depth > 0 {
        format!(", {no_depth} px without depth (disparity unknown or <= -doffs: inf)")
    } else {
        String::new()
    };
    let files: Vec<String> =
        written.iter().map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()).collect();
    let checked =
        info.rejected_share().map_or(String::new(), |s| format!(", left-right check replaced {:.1} %", 100.0 * s));
    let prior = info.prior_seconds.map_or(String::new(), |s| format!(" (depth prior {s:.2} s)"));
    let line = format!(
        "{}: {}x{} (network {}x{}, {:?} volume{checked}{no_depth}) {:.2} s{prior} -> {}",
        pair.name,
        left.width,
        left.height,
        info.network_size.0,
        info.network_size.1,
        info.corr,
        t0.elapsed().as_secs_f64(),
        files.join(", ")
    );
    Ok((line, note))
}

fn calibration_for(left: &Path, global: Option<&Calibration>) -> anyhow::Result<Calibration> {
    if let Some(c) = global {
        return Ok(c.clone());
    }
    match calibration_beside(left) {
        Some(p) => Ok(Calibration::load(&p)?),
        None => bail!(
            "{}: depth and ply outputs need a calibration: pass --calib FILE (or put calib.txt beside the image)",
            left.display()
        ),
    }
}
