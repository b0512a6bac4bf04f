//! `dgstereo demo`: the main job on the bundled Cones pair.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Context;
use clap::Args;
use dgstereo_data::{load_mask, load_rgb, read_disparity, save_rgb, write_disparity};
use dgstereo_eval::{ValidOptions, evaluate};

use dgstereo_inference::MinSize;
use dgstereo_inference::weights::asset;

use crate::engine::{DEFAULT_LR_CHECK, ModelArgs, load_engine, with_flags};
use dgstereo_data::visualize::{colorize, error_image, side_by_side};

/// Options of the demo.
#[derive(Args)]
pub struct DemoArgs {
    /// Output folder.
    #[arg(short, long, default_value = "out/demo")]
    out: PathBuf,
    /// Weights: a file or an official checkpoint's name (`dgstereo weights list`); default: the
    /// project's default model.
    #[arg(long)]
    weights: Option<PathBuf>,
    /// Update iterations (default: the official preset of a `.pth` checkpoint's architecture,
    /// else 32).
    #[arg(long)]
    iters: Option<usize>,
    /// Upscale the pair when its longer side is under this many pixels: `auto` (900 for models at
    /// 1/8 resolution such as the bundled default), `off`, or pixels.
    #[arg(long, default_value = "auto")]
    min_size: MinSize,
    /// Left-right consistency check (see `dgstereo infer --help`): fill the pixels the right view
    /// does not confirm, at this threshold in pixels (2 when no value is given).
    #[arg(long, value_name = "PX", num_args = 0..=1, default_missing_value = DEFAULT_LR_CHECK)]
    lr_check: Option<f32>,
}

pub fn run(a: DemoArgs) -> anyhow::Result<ExitCode> {
    let left_path = asset("cones/left_rgb.png")?;
    let dir = left_path.parent().context("asset folder")?.to_path_buf();
    let left = load_rgb(&left_path)?;
    let right = load_rgb(dir.join("right_rgb.png"))?;
    let gt = read_disparity(dir.join("disp_left.pfm"))?;
    let visible = load_mask(dir.join("occlusion.png"))?;
    let (engine, options) = load_engine(&ModelArgs {
        weights: a.weights,
        iters: a.iters,
        min_size: a.min_size,
        lr_check: a.lr_check,
        ..ModelArgs::defaults()
    })?;
    println!("weights: {}", engine.weights().display());

    let start = Instant::now();
    let prediction = engine.predict(&left, &right, "cones", &options).map_err(with_flags)?;
    let (disp, info) = (prediction.disparity, prediction.info);
    let seconds = start.elapsed().as_secs_f64();
    let (nw, nh) = info.network_size;
    let network = if (nw, nh) == (left.width, left.height) { String::new() } else { format!(" (network {nw}x{nh})") };
    let checked = info
        .rejected_share()
        .map_or(String::new(), |s| format!(", left-right check replaced {:.1} % of the pixels", 100.0 * s));
    println!("Cones {}x{}{network}, {} iterations{checked}: {seconds:.2} s", left.width, left.height, options.iters);

    std::fs::create_dir_all(&a.out).with_context(|| format!("cannot create {}", a.out.display()))?;
    write_disparity(a.out.join("cones_disparity.pfm"), &disp)?;
    let range = (0.0, 64.0);
    let colour = colorize(&disp, range, true);
    save_rgb(a.out.join("cones_disparity_color.png"), &colour)?;
    let err = error_image(&disp, &gt, 4.0);
    save_rgb(a.out.join("cones_side_by_side.png"), &side_by_side(&[&left, &colorize(&disp, range, false), &err]))?;

    let all = evaluate(&disp, &gt, None, ValidOptions { max_disp: None })?;
    let noc = evaluate(&disp, &gt, Some(&visible), ValidOptions { max_disp: None })?;
    println!("all pixels with ground truth: {}", serde_json::to_string(&all.to_json())?);
    println!("non-occluded pixels:          {}", serde_json::to_string(&noc.to_json())?);
    println!("for reference, OpenCV StereoSGBM on all pixels: EPE 1.37, bad-2 11.9 %");
    println!("wrote {}/cones_disparity.pfm, cones_disparity_color.png, cones_side_by_side.png", a.out.display());
    Ok(ExitCode::SUCCESS)
}
