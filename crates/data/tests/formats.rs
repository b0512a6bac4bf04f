//! Round trips and error reporting of the image and disparity formats.

mod common;

use std::path::Path;

use dgstereo_core::Error;
use dgstereo_data::npy::{NpyArray, NpyDtype, decode_npy, encode_npy, read_npy, write_npy};
use dgstereo_data::pfm::{Endian, Pfm, decode_pfm, encode_pfm, read_pfm, write_pfm};
use dgstereo_data::{
    DisparityMap, RgbImage, kitti_png, load_mask, load_rgb, read_disparity, save_mask, save_rgb, write_disparity,
};

fn names_file(e: &Error, file: &Path) -> bool {
    let s = e.to_string();
    s.contains(&file.display().to_string())
}

fn sample_map(w: usize, h: usize) -> DisparityMap {
    let mut d = DisparityMap::from_vec(w, h, (0..w * h).map(|i| i as f32 * 0.25 + 0.5).collect()).unwrap();
    d.set(1, 0, f32::INFINITY);
    d.set(2, 1, f32::NAN);
    d
}

fn same_bits(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}

#[test]
fn pfm_round_trips_both_endiannesses_and_channels() {
    let dir = common::scratch("pfm_rt");
    for channels in [1usize, 3] {
        for endian in [Endian::Little, Endian::Big] {
            let (w, h) = (5, 3);
            let data: Vec<f32> = (0..w * h * channels).map(|i| i as f32 - 7.5).collect();
            let pfm = Pfm { width: w, height: h, channels, data };
            let path = dir.join(format!("a{channels}{endian:?}.pfm"));
            write_pfm(&path, &pfm, endian).unwrap();
            assert_eq!(read_pfm(&path).unwrap(), pfm);
        }
    }
}

#[test]
fn pfm_rows_are_stored_bottom_to_top() {
    // A 1x2 grayscale map, top row 1.0, bottom row 2.0: the file holds 2.0 first.
    let pfm = Pfm { width: 1, height: 2, channels: 1, data: vec![1.0, 2.0] };
    let bytes = encode_pfm(&pfm, Endian::Little).unwrap();
    let header = b"Pf\n1 2\n-1.0\n";
    assert_eq!(&bytes[..header.len()], header);
    assert_eq!(&bytes[header.len()..header.len() + 4], &2.0f32.to_le_bytes());
    // Hand-written big-endian file with the header on one line.
    let mut be = b"Pf 1 2 1.0\n".to_vec();
    be.extend_from_slice(&5.0f32.to_be_bytes());
    be.extend_from_slice(&6.0f32.to_be_bytes());
    let p = decode_pfm(&be, Path::new("x.pfm")).unwrap();
    assert_eq!(p.data, vec![6.0, 5.0]);
}

#[test]
fn pfm_disparity_keeps_inf_and_nan() {
    let dir = common::scratch("pfm_disp");
    let d = sample_map(4, 3);
    let path = dir.join("d.pfm");
    write_disparity(&path, &d).unwrap();
    assert!(same_bits(&read_disparity(&path).unwrap().data, &d.data));
}

#[test]
fn pfm_errors_name_the_file() {
    let dir = common::scratch("pfm_err");
    let missing = dir.join("missing.pfm");
    let e = read_pfm(&missing).unwrap_err();
    assert!(matches!(e, Error::Io { .. }) && names_file(&e, &missing), "{e}");

    let bad = dir.join("bad.pfm");
    std::fs::write(&bad, b"P6\n1 1\n255\n").unwrap();
    let e = read_pfm(&bad).unwrap_err();
    assert!(matches!(e, Error::Format { .. }) && names_file(&e, &bad), "{e}");
    assert!(e.to_string().contains("magic"), "{e}");

    let trunc = dir.join("trunc.pfm");
    let mut bytes = encode_pfm(&Pfm { width: 4, height: 4, channels: 1, data: vec![1.0; 16] }, Endian::Little).unwrap();
    bytes.truncate(bytes.len() - 3);
    std::fs::write(&trunc, &bytes).unwrap();
    let e = read_pfm(&trunc).unwrap_err();
    assert!(names_file(&e, &trunc) && e.to_string().contains("truncated"), "{e}");

    let header_only = dir.join("hdr.pfm");
    std::fs::write(&header_only, b"Pf\n4").unwrap();
    let e = read_pfm(&header_only).unwrap_err();
    assert!(names_file(&e, &header_only), "{e}");
}

#[test]
fn kitti_png_round_trips_at_1_over_256() {
    let dir = common::scratch("kitti");
    let mut d =
        DisparityMap::from_vec(4, 2, vec![0.0, 1.0 / 256.0, 12.5, 65535.0 / 256.0, 3.0, 0.0, 100.25, 7.0]).unwrap();
    let path = dir.join("d.png");
    write_disparity(&path, &d).unwrap();
    assert_eq!(read_disparity(&path).unwrap(), d);
    // Non-finite and negative values are stored as 0 (invalid).
    d.set(0, 0, f32::NAN);
    d.set(1, 0, f32::INFINITY);
    d.set(2, 0, -3.0);
    kitti_png::write_kitti_png(&path, &d).unwrap();
    let back = kitti_png::read_kitti_png(&path).unwrap();
    assert_eq!(&back.data[..3], &[0.0, 0.0, 0.0]);
    // An 8-bit PNG is not a KITTI disparity.
    let rgb = dir.join("rgb.png");
    save_rgb(&rgb, &RgbImage::new(2, 2)).unwrap();
    let e = kitti_png::read_kitti_png(&rgb).unwrap_err();
    assert!(names_file(&e, &rgb) && e.to_string().contains("16-bit"), "{e}");
}

#[test]
fn npy_round_trips_2d_3d_f32_f64() {
    let dir = common::scratch("npy");
    for shape in [vec![3usize, 4], vec![2, 3, 4], vec![5]] {
        for dtype in [NpyDtype::F32, NpyDtype::F64] {
            let n: usize = shape.iter().product();
            let arr = NpyArray { shape: shape.clone(), data: (0..n).map(|i| i as f32 * 0.5 - 1.0).collect() };
            let path = dir.join(format!("a{}{dtype:?}.npy", shape.len()));
            write_npy(&path, &arr, dtype).unwrap();
            let bytes = std::fs::read(&path).unwrap();
            let hlen = u16::from_le_bytes([bytes[8], bytes[9]]) as usize;
            assert_eq!((10 + hlen) % 64, 0, "header is padded to 64 bytes");
            assert_eq!(read_npy(&path).unwrap(), arr);
        }
    }
    let d = sample_map(3, 2);
    let path = dir.join("d.npy");
    write_disparity(&path, &d).unwrap();
    assert!(same_bits(&read_disparity(&path).unwrap().data, &d.data));
}

#[test]
fn npy_reads_numpy_written_big_endian_and_v2_headers() {
    // As numpy writes np.array([[1.5, -2]], dtype='>f8') with version 2.0.
    let header = "{'descr': '>f8', 'fortran_order': False, 'shape': (1, 2), }";
    let mut bytes = b"\x93NUMPY\x02\x00".to_vec();
    let mut h = header.to_string();
    h.push_str(&" ".repeat((64 - (12 + h.len() + 1) % 64) % 64));
    h.push('\n');
    bytes.extend_from_slice(&(h.len() as u32).to_le_bytes());
    bytes.extend_from_slice(h.as_bytes());
    bytes.extend_from_slice(&1.5f64.to_be_bytes());
    bytes.extend_from_slice(&(-2f64).to_be_bytes());
    let arr = decode_npy(&bytes, Path::new("x.npy")).unwrap();
    assert_eq!(arr, NpyArray { shape: vec![1, 2], data: vec![1.5, -2.0] });
}

fn replace_bytes(hay: &[u8], from: &[u8], to: &[u8]) -> Vec<u8> {
    let at = hay.windows(from.len()).position(|w| w == from).expect("pattern present");
    let mut out = hay[..at].to_vec();
    out.extend_from_slice(to);
    out.extend_from_slice(&hay[at + from.len()..]);
    out
}

#[test]
fn npy_errors_name_the_file() {
    let dir = common::scratch("npy_err");
    let arr = NpyArray { shape: vec![4, 4], data: vec![0.0; 16] };
    let good = encode_npy(&arr, NpyDtype::F32).unwrap();
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("trunc.npy", good[..good.len() - 1].to_vec(), "truncated"),
        ("magic.npy", b"hello world, not numpy".to_vec(), "magic"),
        ("dtype.npy", replace_bytes(&good, b"<f4", b"<c8"), "dtype"),
        ("fortran.npy", replace_bytes(&good, b"False", b"True "), "Fortran"),
    ];
    for (name, bytes, needle) in cases {
        let path = dir.join(name);
        std::fs::write(&path, &bytes).unwrap();
        let e = read_npy(&path).unwrap_err();
        assert!(names_file(&e, &path) && e.to_string().contains(needle), "{name}: {e}");
    }
    let e = read_npy(dir.join("missing.npy")).unwrap_err();
    assert!(matches!(e, Error::Io { .. }) && names_file(&e, &dir.join("missing.npy")), "{e}");
    // A 3-D array with no singleton dimension is not a disparity map.
    let p = dir.join("cube.npy");
    write_npy(&p, &NpyArray { shape: vec![2, 2, 2], data: vec![0.0; 8] }, NpyDtype::F32).unwrap();
    let e = read_disparity(&p).unwrap_err();
    assert!(names_file(&e, &p), "{e}");
}

#[test]
fn unknown_disparity_extension_is_an_error() {
    let e = read_disparity("x/disp.tiff").unwrap_err();
    assert!(e.to_string().contains("disp.tiff"), "{e}");
}

#[test]
fn images_of_every_depth_load_as_rgb_0_255() {
    let dir = common::scratch("images");
    let (w, h) = (3u32, 2u32);
    // 8-bit gray
    let g8 = image::GrayImage::from_fn(w, h, |x, y| image::Luma([(x * 40 + y * 100) as u8]));
    g8.save(dir.join("g8.png")).unwrap();
    let img = load_rgb(dir.join("g8.png")).unwrap();
    assert_eq!((img.width, img.height), (3, 2));
    assert_eq!(img.get(2, 1), [180.0, 180.0, 180.0]);
    // 16-bit gray and RGB, scaled to 0..255
    let g16: image::ImageBuffer<image::Luma<u16>, Vec<u16>> =
        image::ImageBuffer::from_fn(w, h, |x, _| image::Luma([if x == 0 { 65535 } else { 257 * 10 }]));
    g16.save(dir.join("g16.png")).unwrap();
    let img = load_rgb(dir.join("g16.png")).unwrap();
    assert_eq!(img.get(0, 0), [255.0; 3]);
    assert!((img.get(1, 0)[0] - 10.0).abs() < 1e-4);
    let c16: image::ImageBuffer<image::Rgb<u16>, Vec<u16>> =
        image::ImageBuffer::from_fn(w, h, |_, _| image::Rgb([0, 257 * 128, 65535]));
    c16.save(dir.join("c16.png")).unwrap();
    let px = load_rgb(dir.join("c16.png")).unwrap().get(1, 1);
    assert!((px[0]).abs() < 1e-4 && (px[1] - 128.0).abs() < 1e-3 && (px[2] - 255.0).abs() < 1e-4);
    // RGBA drops alpha; RGB PNG round trip is exact; JPEG is close.
    let rgb = RgbImage::from_fn(16, 8, |x, y| [(x * 10) as f32, (y * 20) as f32, 77.0]);
    save_rgb(dir.join("c8.png"), &rgb).unwrap();
    assert_eq!(load_rgb(dir.join("c8.png")).unwrap(), rgb);
    let rgba = image::RgbaImage::from_fn(w, h, |_, _| image::Rgba([1, 2, 3, 4]));
    rgba.save(dir.join("a.png")).unwrap();
    assert_eq!(load_rgb(dir.join("a.png")).unwrap().get(0, 0), [1.0, 2.0, 3.0]);
    let flat = RgbImage::from_fn(16, 16, |_, _| [100.0, 150.0, 200.0]);
    save_rgb(dir.join("c.jpg"), &flat).unwrap();
    let j = load_rgb(dir.join("c.jpg")).unwrap();
    assert!(j.data.iter().zip(&flat.data).all(|(a, b)| (a - b).abs() < 4.0));
}

#[test]
fn image_errors_name_the_file() {
    let dir = common::scratch("image_err");
    let missing = dir.join("nope.png");
    let e = load_rgb(&missing).unwrap_err();
    assert!(matches!(e, Error::Io { .. }) && names_file(&e, &missing), "{e}");
    let garbage = dir.join("garbage.png");
    std::fs::write(&garbage, b"\x89PNG\r\n\x1a\nthis is not a png").unwrap();
    let e = load_rgb(&garbage).unwrap_err();
    assert!(names_file(&e, &garbage), "{e}");
    // A truncated PNG.
    let good = dir.join("good.png");
    save_rgb(&good, &RgbImage::from_fn(32, 32, |x, y| [x as f32, y as f32, 0.0])).unwrap();
    let bytes = std::fs::read(&good).unwrap();
    let trunc = dir.join("trunc.png");
    std::fs::write(&trunc, &bytes[..bytes.len() / 2]).unwrap();
    let e = load_rgb(&trunc).unwrap_err();
    assert!(names_file(&e, &trunc), "{e}");
}

#[test]
fn masks_round_trip() {
    let dir = common::scratch("mask");
    let m = dgstereo_data::Mask { width: 3, height: 2, data: vec![true, false, true, false, false, true] };
    save_mask(dir.join("m.png"), &m).unwrap();
    assert_eq!(load_mask(dir.join("m.png")).unwrap(), m);
}

#[test]
fn rgb_layout_is_planar_chw() {
    let img = RgbImage::from_fn(2, 1, |x, _| [x as f32, 10.0 + x as f32, 20.0 + x as f32]);
    assert_eq!(img.data, vec![0.0, 1.0, 10.0, 11.0, 20.0, 21.0]);
    assert_eq!(img.to_interleaved(), vec![0.0, 10.0, 20.0, 1.0, 11.0, 21.0]);
    assert_eq!(RgbImage::from_interleaved(2, 1, &img.to_interleaved()).unwrap(), img);
}
