//! `dgstereo infer`: disparity (and depth, point clouds) of the user's stereo pairs.
//!
//! Whole-run problems (no pairs, weights that do not load or fit the experiment, a calibration
//! that does not parse) stop the command before any pair runs. Per-pair problems (a missing right
//! image, an unreadable or truncated file, views of different sizes) are reported as one line
//! naming the file, the other pairs still run, the failures are listed at the end and the exit
//! status is non-zero. A panic inside the model is caught and reported the same way, as an
//! internal error of that pair.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, bail};
use clap::Args;
use dgstereo_data::datasets::pair_list::{PairList, PairProblem, from_folder, from_left_right, from_list};
use dgstereo_inference::calibration::{Adjustment, Calibration};
use dgstereo_inference::outputs::{OutputOptions, SaveKind, calibration_beside};
use dgstereo_inference::pair_files::{PairFiles, PairReport};
use dgstereo_inference::pointcloud::PlyEncoding;
use indicatif::{ProgressBar, ProgressStyle};

use crate::engine::{ModelArgs, error_line, load_engine, with_flags};

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
        (Some(dir), _) if !dir.is_dir() => bail!("{}: --pairs needs a folder", dir.display()),
        (Some(dir), _) => Ok(from_folder(dir)?),
        (None, Some(list)) => Ok(from_list(list)?),
        (None, None) if a.left.is_empty() || a.right.is_empty() => {
            bail!("give both -l/--left and -r/--right images (files or glob patterns), or --pairs DIR, or --list FILE")
        }
        (None, None) => Ok(from_left_right(&a.left, &a.right)?),
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
    // Each kind once, in the order first given.
    let kinds: Vec<SaveKind> =
        a.save.iter().enumerate().filter(|(i, k)| !a.save[..*i].contains(k)).map(|(_, k)| *k).collect();
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
    let job = PairFiles {
        engine: &engine,
        options: &options,
        outputs: &opts,
        calibration: global_calib.as_ref(),
        adjustment,
    };
    let mut notes: Vec<String> = Vec::new();

    let mut failures = list.problems.clone();
    for f in &failures {
        eprintln!("error: {}", f.line());
    }
    let total = list.pairs.len();
    eprintln!("configuration: {}", engine.describe(&options));
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
        match job.run(pair) {
            Ok(report) => {
                done += 1;
                // A rescaled calibration is said once for each size it was rescaled to.
                if let Some(note) = report.rescaled.as_ref().map(|n| n.to_string())
                    && !notes.contains(&note)
                {
                    bar.suspend(|| eprintln!("note: {note}"));
                    notes.push(note);
                }
                bar.suspend(|| println!("{}", report_line(&pair.name, &report)));
            }
            Err(e) => {
                let f = PairProblem { path: pair.left.clone(), message: error_line(&with_flags(e)) };
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

/// The line reporting a pair that was done.
fn report_line(name: &str, r: &PairReport) -> String {
    // Depth is `inf` where the disparity gives no point in front of the cameras: say how often.
    let no_depth = match r.without_depth {
        0 => String::new(),
        n => format!(", {n} px without depth (disparity unknown or <= -doffs: inf)"),
    };
    let files: Vec<String> =
        r.written.iter().map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()).collect();
    let info = &r.info;
    let checked =
        info.rejected_share().map_or(String::new(), |s| format!(", left-right check replaced {:.1} %", 100.0 * s));
    let prior = info.prior_seconds.map_or(String::new(), |s| format!(" (depth prior {s:.2} s)"));
    let ((w, h), (nw, nh)) = (r.size, info.network_size);
    let volume = format!("{:?} volume{checked}{no_depth}", info.corr);
    format!("{name}: {w}x{h} (network {nw}x{nh}, {volume}) {:.2} s{prior} -> {}", r.seconds, files.join(", "))
}
