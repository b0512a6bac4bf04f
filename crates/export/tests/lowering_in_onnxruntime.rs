//! The lowering table, operation by operation, in ONNX Runtime: each case is a tiny tensor
//! program, run on the Flex CPU device for the expected values and recorded on the capture
//! device, lowered to an ONNX file and run by ONNX Runtime (Python's `onnxruntime`, from
//! `DGSTEREO_PYTHON` or the test venv `target/python-venv` that `scripts/test` makes). Without
//! it the comparison is skipped with a notice (an error under `CI=true`); the lowering itself
//! and `onnx`'s structural checks of what it writes still run.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use burn::backend::capture::CaptureBackend;
use burn::module::Module;
use burn::tensor::module::{
    attention, avg_pool2d, conv_transpose2d, conv_transpose3d, conv2d, conv3d, deform_conv2d, interpolate, layer_norm,
    linear, max_pool2d, unfold4d,
};
use burn::tensor::ops::{
    AttentionModuleOptions, AvgPoolOptions, ConvOptions, ConvTransposeOptions, DeformConvOptions, InterpolateMode,
    InterpolateOptions, MaxPoolOptions, PadMode, UnfoldOptions,
};
use burn::tensor::{Device, Distribution, Int, Tensor, s};
use dgstereo_encoder::pyramid::feature_pyramid;
use dgstereo_encoder::{EncoderConfig, EncoderLayout, Encoders, PyramidEncoders};
use dgstereo_export::lower::{Boundaries, lower_graph, to_bytes};
use dgstereo_updater::superpixel::{SuperpixelUpsampler, context_upsample};

type Program = fn(&[Tensor<4>]) -> Tensor<4>;

/// `(name, input shapes, program)`: each program uses one operation family of the table.
fn cases() -> Vec<(&'static str, Vec<[usize; 4]>, Program)> {
    let s = [1, 3, 5, 6];
    vec![
        ("relu_sigmoid_tanh", vec![s], |x| {
            burn::tensor::activation::relu(x[0].clone())
                + burn::tensor::activation::sigmoid(x[0].clone()) * x[0].clone().tanh()
        }),
        ("exp_log_sqrt_floor_neg_abs", vec![s], |x| {
            let a = x[0].clone().abs();
            (a.clone() + 1.0).log() + a.clone().sqrt() + x[0].clone().floor().neg() + (x[0].clone() * 0.1).exp()
        }),
        ("softmax", vec![s], |x| burn::tensor::activation::softmax(x[0].clone(), 3)),
        ("binary_broadcast", vec![s, [1, 3, 1, 6]], |x| {
            (x[0].clone() + x[1].clone()) * x[1].clone() - x[0].clone() / (x[1].clone().abs() + 1.0)
        }),
        ("scalars", vec![s], |x| ((x[0].clone() + 2.0) * 3.0 - 1.5) / 4.0),
        ("clamps", vec![s], |x| {
            x[0].clone().clamp(-0.5, 0.5) + x[0].clone().clamp_min(0.2) + x[0].clone().clamp_max(-0.1)
        }),
        ("comparisons", vec![s], |x| {
            x[0].clone().greater_equal_elem(0.1).float() + x[0].clone().lower_equal_elem(-0.2).float() * 2.0
        }),
        ("reductions", vec![s], |x| {
            let x = x[0].clone();
            x.clone().mean_dim(3) + x.clone().sum_dim(3) + x.clone().min_dim(1).sum_dim(2) + x.max_dim(2)
        }),
        ("cat_reshape_permute_swap", vec![s], |x| {
            let c = Tensor::cat(vec![x[0].clone(), x[0].clone() * 2.0], 1);
            c.reshape([1, 6, 30, 1]).permute([0, 2, 1, 3]).swap_dims(1, 2).reshape([1, 6, 5, 6])
        }),
        ("slice_expand", vec![s], |x| {
            x[0].clone().slice([0..1, 1..3, 0..5, 2..5]).expand([2, 2, 5, 3]).reshape([1, 4, 5, 3])
        }),
        ("gather", vec![s], |x| {
            let idx: Tensor<4, Int> = (x[0].clone().abs() * 2.0).floor().clamp(0.0, 5.0).int();
            x[0].clone().gather(3, idx.clone()) + idx.float()
        }),
        ("created", vec![s], |x| {
            let d = x[0].device();
            let s = [1, 3, 5, 6];
            x[0].clone() + Tensor::<4>::zeros(s, &d) + Tensor::<4>::ones(s, &d) + Tensor::<4>::full(s, 0.25, &d)
        }),
        ("pad_edge_constant", vec![s], |x| {
            x[0].clone().pad([(0, 0), (0, 0), (1, 2), (3, 0)], PadMode::Edge)
                + x[0].clone().pad([(0, 0), (0, 0), (1, 2), (3, 0)], PadMode::Constant(0.5))
        }),
        ("matmul", vec![[1, 2, 5, 4], [1, 2, 4, 3]], |x| x[0].clone().matmul(x[1].clone())),
        ("conv2d", vec![[1, 4, 9, 11], [6, 2, 3, 3]], |x| {
            conv2d(x[0].clone(), x[1].clone(), None, ConvOptions::new([2, 1], [1, 2], [1, 2], 2))
        }),
        ("pools", vec![[1, 2, 9, 11]], |x| {
            let a = avg_pool2d(x[0].clone(), AvgPoolOptions::new([3, 3]).with_stride([2, 2]).with_padding([1, 1]));
            a + max_pool2d(x[0].clone(), MaxPoolOptions::new([3, 3]).with_stride([2, 2]).with_padding([1, 1]))
        }),
        ("interpolate", vec![[1, 2, 5, 7]], |x| {
            let mut aligned = InterpolateOptions::new(InterpolateMode::Bilinear);
            aligned.align_corners = true;
            aligned.output_size = Some([9, 13]);
            let mut half = InterpolateOptions::new(InterpolateMode::Bilinear);
            half.output_size = Some([9, 13]);
            let mut nearest = InterpolateOptions::new(InterpolateMode::Nearest);
            nearest.output_size = Some([9, 13]);
            interpolate(x[0].clone(), aligned) + interpolate(x[0].clone(), half) + interpolate(x[0].clone(), nearest)
        }),
        ("unfold4d", vec![[1, 2, 6, 7]], |x| {
            unfold4d(x[0].clone(), [3, 3], UnfoldOptions::new([1, 1], [1, 1], [1, 1])).reshape([1, 18, 6, 7])
        }),
        ("deform_conv2d", vec![[1, 4, 6, 7], [1, 18, 6, 7], [3, 4, 3, 3]], |x| {
            let offset = x[1].clone() * 2.0;
            deform_conv2d(
                x[0].clone(),
                offset,
                x[2].clone(),
                None,
                None,
                DeformConvOptions::new([1, 1], [1, 1], [1, 1], 1, 1),
            )
        }),
        // A monocular network's ViT and DPT head (DEFOM-Stereo's Depth Anything V2).
        ("gelu", vec![s], |x| burn::tensor::activation::gelu(x[0].clone() * 3.0)),
        ("linear", vec![[1, 2, 5, 4], [1, 1, 4, 3], [1, 1, 1, 3]], |x| {
            let weight = x[1].clone().reshape([4, 3]);
            linear(x[0].clone(), weight.clone(), Some(x[2].clone().reshape([3]))) + linear(x[0].clone(), weight, None)
        }),
        ("layer_norm", vec![[1, 2, 5, 6], [1, 1, 1, 6], [1, 1, 1, 6]], |x| {
            let (gamma, beta) = (x[1].clone().reshape([6]), x[2].clone().reshape([6]));
            layer_norm(x[0].clone(), gamma.clone(), Some(beta), 1e-6) + layer_norm(x[0].clone(), gamma, None, 1e-5)
        }),
        ("attention", vec![[1, 2, 5, 4], [1, 2, 7, 4], [1, 2, 7, 3]], |x| {
            let scaled = AttentionModuleOptions { scale: Some(0.3), ..AttentionModuleOptions::default() };
            let v = x[2].clone();
            attention(x[0].clone(), x[1].clone(), v.clone(), None, None, AttentionModuleOptions::default())
                + attention(x[0].clone(), x[1].clone(), v, None, None, scaled)
        }),
        ("conv_transpose2d", vec![[1, 4, 3, 5], [4, 3, 4, 4], [1, 1, 1, 6]], |x| {
            let bias = x[2].clone().reshape([6]).narrow(0, 0, 3);
            let four = ConvTransposeOptions::new([4, 4], [0, 0], [0, 0], [1, 1], 1);
            let up = conv_transpose2d(x[0].clone(), x[1].clone(), Some(bias), four);
            let grouped = ConvTransposeOptions::new([2, 2], [1, 1], [1, 1], [1, 1], 2);
            let half = conv_transpose2d(x[0].clone(), x[1].clone().narrow(1, 0, 2), None, grouped);
            up.slice([0..1, 0..3, 0..7, 0..11]) + half.slice([0..1, 0..3, 0..7, 0..11])
        }),
        // A 3D cost-volume network's blocks (IGEV-Stereo's geometry encoding volume); the
        // volumes `[N, C, D, H, W]` travel as `[N, C, D·H, W]`.
        ("leaky_relu", vec![s], |x| burn::tensor::activation::leaky_relu(x[0].clone(), 0.01)),
        ("conv3d", vec![[1, 4, 15, 6], [6, 2, 9, 3], [1, 1, 1, 6]], |x| {
            let volume = x[0].clone().reshape([1, 4, 3, 5, 6]);
            let weight = x[1].clone().reshape([6, 2, 3, 3, 3]);
            let bias = x[2].clone().reshape([6]);
            let grouped = ConvOptions::new([1, 2, 1], [1, 1, 1], [1, 1, 2], 2);
            let y = conv3d(volume.clone(), weight.clone(), Some(bias), grouped);
            let plain = ConvOptions::new([1, 1, 1], [1, 1, 1], [1, 1, 1], 2);
            let z = conv3d(volume, weight, None, plain);
            let [_, c, d, h, w] = y.dims();
            y.reshape([1, c, d * h, w]) + z.slice([0..1, 0..6, 0..3, 0..3, 0..4]).reshape([1, 6, 9, 4])
        }),
        ("conv_transpose3d", vec![[1, 4, 6, 4], [4, 3, 16, 4], [1, 1, 1, 3]], |x| {
            let volume = x[0].clone().reshape([1, 4, 2, 3, 4]);
            let weight = x[1].clone().reshape([4, 3, 4, 4, 4]);
            let bias = x[2].clone().reshape([3]);
            let up = ConvTransposeOptions::new([2, 2, 2], [1, 1, 1], [0, 0, 0], [1, 1, 1], 1);
            let y = conv_transpose3d(volume, weight, Some(bias), up);
            let [_, c, d, h, w] = y.dims();
            y.reshape([1, c, d * h, w])
        }),
        ("slice_assign", vec![s, [1, 2, 3, 4], [1, 3, 5, 2]], |x| {
            // An inner region, a region reaching the ends of its axes (negative bounds), and a
            // region spanning all but the last axis (one concatenation).
            let inner = x[0].clone().slice_assign([0..1, 1..3, 1..4, 1..5], x[1].clone());
            let ends =
                x[0].clone().slice_assign(s![0..1, -2.., 2.., ..-2], x[1].clone().narrow(2, 0, 3).narrow(3, 0, 4));
            let last = x[0].clone().slice_assign(s![.., .., .., 4..], x[2].clone());
            inner + ends * 2.0 + last * 3.0
        }),
        // IGEV-Stereo's encoder side as modules: the MobileNetV2 pyramid (depthwise convolutions,
        // ReLU6), the image stems, the superpixel weights (transposed convolutions, nearest
        // resize where sizes differ) and the weighted 3x3 neighbourhood upsampling.
        ("igev_pyramid_and_superpixel", vec![[1, 3, 64, 96]], |x| {
            let (encoders, upsampler) = igev_modules();
            let device = x[0].device();
            let (feature, stems) =
                (encoders.feature.clone().to_device(&device), encoders.stem_2.clone().to_device(&device));
            let stem_4 = encoders.stem_4.clone().to_device(&device);
            let upsampler = upsampler.clone().to_device(&device);
            // The image as the encoders see it, normalised to -1..1.
            let pyramid = feature_pyramid(&feature, [&stems, &stem_4], x[0].clone());
            let weights = upsampler.initial_weights(pyramid.levels[0].clone(), pyramid.stem_2.clone());
            let disparity = context_upsample(pyramid.levels[0].clone().narrow(1, 0, 1), weights.clone());
            Tensor::cat(vec![weights, disparity], 1)
        }),
    ]
}

/// IGEV-Stereo's encoders and superpixel upsampler with fresh weights, built once on the host
/// (a case runs on the host and on the capture device with the same weights).
fn igev_modules() -> &'static (PyramidEncoders, SuperpixelUpsampler) {
    static MODULES: OnceLock<(PyramidEncoders, SuperpixelUpsampler)> = OnceLock::new();
    MODULES.get_or_init(|| {
        let host = Device::flex();
        let config = EncoderConfig { layout: EncoderLayout::MobilenetPyramid, ..Default::default() };
        let Encoders::Pyramid(encoders) = config.init([32; 3], 2, None, &host).unwrap() else { unreachable!() };
        (encoders, SuperpixelUpsampler::new(&host))
    })
}

fn inputs(shapes: &[[usize; 4]], seed: u64) -> Vec<Tensor<4>> {
    let host = Device::flex();
    burn::tensor::Device::seed(&host, seed);
    shapes.iter().map(|&s| Tensor::<4>::random(s, Distribution::Uniform(-1.0, 1.0), &host)).collect()
}

/// Runs `program` on the capture device and lowers it: the ONNX file's bytes.
fn export(program: Program, xs: &[Tensor<4>]) -> Vec<u8> {
    let device = Device::capture();
    let mut names = None;
    let captured = device
        .capture_scope(|scope| {
            let moved: Vec<Tensor<4>> = xs.iter().map(|x| x.clone().to_device(&device)).collect();
            let id = |t: &Tensor<4>| t.clone().try_into_primitive::<CaptureBackend>().unwrap().id();
            let ins: Vec<_> = moved.iter().enumerate().map(|(i, t)| (id(t), format!("x{i}"))).collect();
            let out = program(&moved);
            let outs = vec![(id(&out), "y".to_string())];
            let ids = (ins.iter().map(|p| p.0).collect::<Vec<_>>(), outs.iter().map(|p| p.0).collect::<Vec<_>>());
            names = Some(Boundaries { inputs: ins, outputs: outs });
            scope.complete(ids.0, ids.1)
        })
        .unwrap();
    let model = lower_graph(&captured.graph.operations, &captured.values, &names.unwrap(), &[], "test").unwrap();
    to_bytes(&model).unwrap()
}

fn write_f32(path: &Path, t: &Tensor<4>) -> Vec<usize> {
    let data = t.to_data();
    let values: Vec<f32> = data.try_to_vec::<f32>().unwrap();
    std::fs::write(path, values.iter().flat_map(|v| v.to_le_bytes()).collect::<Vec<u8>>()).unwrap();
    t.dims().to_vec()
}

fn python() -> Option<PathBuf> {
    let candidates = std::env::var_os("DGSTEREO_PYTHON")
        .map(PathBuf::from)
        .into_iter()
        .chain(std::iter::once(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../target/python-venv/bin/python")));
    for p in candidates {
        let ok =
            Command::new(&p).args(["-c", "import onnx, onnxruntime, numpy"]).output().is_ok_and(|o| o.status.success());
        if ok {
            return Some(p);
        }
    }
    None
}

const RUNNER: &str = r#"
import json, sys
import numpy as np, onnx, onnxruntime as ort
cases = json.load(open(sys.argv[1]))
result = {}
for c in cases:
    onnx.checker.check_model(onnx.load(c["file"]), full_check=True)
    s = ort.InferenceSession(c["file"], providers=["CPUExecutionProvider"])
    feed = {n: np.fromfile(p, dtype=np.float32).reshape(shape) for n, p, shape in c["inputs"]}
    got = s.run(None, feed)[0]
    want = np.fromfile(c["expected"], dtype=np.float32).reshape(c["shape"])
    diff = float(np.abs(got - want).max()) if got.shape == want.shape else 1e9
    result[c["name"]] = [list(got.shape) == c["shape"], diff, float(np.abs(want).max())]
print(json.dumps(result))
"#;

#[test]
fn every_lowered_operation_runs_in_onnxruntime_as_in_burn() {
    let dir = tempfile::tempdir().unwrap();
    let mut manifest = Vec::new();
    for (seed, (name, shapes, program)) in cases().into_iter().enumerate() {
        let xs = inputs(&shapes, seed as u64 + 1);
        let want = program(&xs);
        let bytes = export(program, &xs);
        let file = dir.path().join(format!("{name}.onnx"));
        std::fs::write(&file, bytes).unwrap();
        let feeds: Vec<_> = xs
            .iter()
            .enumerate()
            .map(|(i, x)| {
                let p = dir.path().join(format!("{name}.x{i}.bin"));
                let shape = write_f32(&p, x);
                serde_json::json!([format!("x{i}"), p, shape])
            })
            .collect();
        let expected = dir.path().join(format!("{name}.y.bin"));
        let shape = write_f32(&expected, &want);
        manifest.push(
            serde_json::json!({"name": name, "file": file, "inputs": feeds, "expected": expected, "shape": shape}),
        );
    }
    let Some(python) = python() else {
        assert!(
            std::env::var("CI").as_deref() != Ok("true"),
            "CI=true: no Python with onnx and onnxruntime (DGSTEREO_PYTHON or target/python-venv)"
        );
        eprintln!("notice: no Python with onnx and onnxruntime; the files were written but not run");
        return;
    };
    let list = dir.path().join("cases.json");
    std::fs::write(&list, serde_json::to_vec(&manifest).unwrap()).unwrap();
    let out = Command::new(python).args(["-c", RUNNER]).arg(&list).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let result: BTreeMap<String, (bool, f64, f64)> = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(result.len(), manifest.len());
    // Within 1e-5 of the output's scale: its largest magnitude, or 1 for small outputs.
    for (name, (shape_ok, diff, largest)) in &result {
        eprintln!("{name}: max |onnxruntime - burn| = {diff:.2e} (largest |burn| {largest:.2e})");
        let tolerance = 1e-5 * largest.max(1.0);
        assert!(*shape_ok && *diff < tolerance, "{name}: shape {shape_ok}, max |onnxruntime - burn| = {diff}");
    }
}

#[test]
fn an_operation_the_table_lacks_is_an_error_naming_it() {
    let xs = inputs(&[[1, 1, 4, 4]], 7);
    let device = Device::capture();
    let captured = device
        .capture_scope(|scope| {
            let x = xs[0].clone().to_device(&device);
            let id = |t: &Tensor<4>| t.clone().try_into_primitive::<CaptureBackend>().unwrap().id();
            let y = x.clone().cumsum(3);
            scope.complete([id(&x)], [id(&y)])
        })
        .unwrap();
    let names = Boundaries {
        inputs: vec![(captured.graph.inputs[0], "x".into())],
        outputs: vec![(captured.graph.outputs[0], "y".into())],
    };
    let e = lower_graph(&captured.graph.operations, &captured.values, &names, &[], "test").unwrap_err().to_string();
    assert!(e.contains("CumSum") && e.contains("no lowering"), "{e}");
}
