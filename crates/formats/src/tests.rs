//! Round trips and the samples of every accepted dtype, from bytes written here as NumPy lays
//! them out.

use std::path::Path;

use crate::npy::{NpyArray, NpyDtype, SampleKind, decode_npy, decode_npy_header, encode_npy};
use crate::pfm::{Endian, Pfm, decode_pfm, encode_pfm};

/// A version 1.0 `.npy` with the given `descr` and `shape` text, then `samples`.
fn npy(descr: &str, shape: &str, samples: &[u8]) -> Vec<u8> {
    let header = format!("{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape}, }}\n");
    let mut out = b"\x93NUMPY\x01\x00".to_vec();
    out.extend((header.len() as u16).to_le_bytes());
    out.extend(header.as_bytes());
    out.extend(samples);
    out
}

#[test]
fn npy_reads_every_integer_and_float_dtype_in_both_orders() {
    let path = Path::new("m.npy");
    let read = |bytes: Vec<u8>| decode_npy(&bytes, path).unwrap().data;
    assert_eq!(read(npy("|u1", "(3,)", &[0, 7, 255])), vec![0.0, 7.0, 255.0]);
    assert_eq!(read(npy("|i1", "(2,)", &[0xff, 0x80])), vec![-1.0, -128.0]);
    let u2: Vec<u8> = [300u16, 65535].iter().flat_map(|v| v.to_le_bytes()).collect();
    assert_eq!(read(npy("<u2", "(1, 2)", &u2)), vec![300.0, 65535.0]);
    let i2: Vec<u8> = [-2i16, 513].iter().flat_map(|v| v.to_be_bytes()).collect();
    assert_eq!(read(npy(">i2", "(2,)", &i2)), vec![-2.0, 513.0]);
    let i4: Vec<u8> = [-70000i32, 5].iter().flat_map(|v| v.to_le_bytes()).collect();
    assert_eq!(read(npy("<i4", "(2,)", &i4)), vec![-70000.0, 5.0]);
    let u4: Vec<u8> = [4_000_000_000u32].iter().flat_map(|v| v.to_be_bytes()).collect();
    assert_eq!(read(npy(">u4", "(1,)", &u4)), vec![4_000_000_000.0]);
    let f4: Vec<u8> = [1.5f32, -0.25].iter().flat_map(|v| v.to_be_bytes()).collect();
    assert_eq!(read(npy(">f4", "(2,)", &f4)), vec![1.5, -0.25]);
    let f8: Vec<u8> = [2.5f64, 1e-3].iter().flat_map(|v| v.to_le_bytes()).collect();
    assert_eq!(read(npy("<f8", "(2,)", &f8)), vec![2.5, 1e-3f64 as f32]);
    let header = decode_npy_header(&npy("<u2", "(4, 5)", &[]), path).unwrap();
    assert_eq!((header.kind, header.sample_bytes, header.shape), (SampleKind::Unsigned, 2, vec![4, 5]));
}

#[test]
fn npy_refuses_other_dtypes_and_short_samples_naming_the_file() {
    let path = Path::new("dir/m.npy");
    let e = decode_npy(&npy("<c8", "(1,)", &[0; 8]), path).unwrap_err().to_string();
    assert!(e.contains("dir/m.npy") && e.contains("c8"), "{e}");
    let e = decode_npy(&npy("<f4", "(2, 2)", &[0; 12]), path).unwrap_err().to_string();
    assert!(e.contains("dir/m.npy") && e.contains("truncated"), "{e}");
    let e = decode_npy(b"\x93NUMPY", path).unwrap_err().to_string();
    assert!(e.contains("dir/m.npy"), "{e}");
}

#[test]
fn npy_and_pfm_round_trip() {
    let arr = NpyArray { shape: vec![2, 3], data: vec![0.5, -1.0, 2.0, 3.25, f32::INFINITY, 0.0] };
    for dtype in [NpyDtype::F32, NpyDtype::F64] {
        let back = decode_npy(&encode_npy(&arr, dtype).unwrap(), Path::new("a.npy")).unwrap();
        assert_eq!(back, arr);
    }
    let pfm = Pfm { width: 3, height: 2, channels: 1, data: arr.data.clone() };
    for endian in [Endian::Little, Endian::Big] {
        let back = decode_pfm(&encode_pfm(&pfm, endian).unwrap(), Path::new("a.pfm")).unwrap();
        assert_eq!(back, pfm, "{endian:?}");
    }
}
