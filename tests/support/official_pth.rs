//! Writing a state dict in the official layout as a PyTorch `.pth` file, as `torch.save` of a
//! `DataParallel` model's `state_dict()` writes it: a zip archive (entries stored) holding
//! `archive/data.pkl`, a pickle (protocol 2) of an `OrderedDict` from each key, under the
//! `module.` prefix, to `torch._utils._rebuild_tensor_v2(storage, 0, shape, stride, False,
//! OrderedDict())`, and each tensor's float32 storage as `archive/data/N`. Tests make official
//! checkpoints of seeded weights ([`dgstereo_model::seeded::golden_state_dict`]) with it, so the
//! `.pth` loader and every command that takes a checkpoint run on a file of the official
//! layout without one beside the repository. Included by path from the tests that use it.

#![allow(dead_code)]

use std::io::Write;
use std::path::Path;

use dgstereo_model::seeded::StateDict;

/// Pickle opcodes (protocol 2).
mod op {
    pub const PROTO: u8 = 0x80;
    pub const GLOBAL: u8 = b'c';
    pub const EMPTY_TUPLE: u8 = b')';
    pub const REDUCE: u8 = b'R';
    pub const MARK: u8 = b'(';
    pub const TUPLE: u8 = b't';
    pub const BINUNICODE: u8 = b'X';
    pub const BININT: u8 = b'J';
    pub const BINPERSID: u8 = b'Q';
    pub const NEWFALSE: u8 = 0x89;
    pub const SETITEMS: u8 = b'u';
    pub const STOP: u8 = b'.';
}

fn global(out: &mut Vec<u8>, module: &str, name: &str) {
    out.push(op::GLOBAL);
    out.extend_from_slice(format!("{module}\n{name}\n").as_bytes());
}

fn text(out: &mut Vec<u8>, s: &str) {
    out.push(op::BINUNICODE);
    out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

fn int(out: &mut Vec<u8>, v: usize) {
    out.push(op::BININT);
    out.extend_from_slice(&i32::try_from(v).expect("a count under 2^31").to_le_bytes());
}

fn int_tuple(out: &mut Vec<u8>, values: &[usize]) {
    out.push(op::MARK);
    values.iter().for_each(|&v| int(out, v));
    out.push(op::TUPLE);
}

fn empty_ordered_dict(out: &mut Vec<u8>) {
    global(out, "collections", "OrderedDict");
    out.push(op::EMPTY_TUPLE);
    out.push(op::REDUCE);
}

/// The pickle of `state` with each key under `prefix`, storage `i` for tensor `i`.
fn pickle(state: &StateDict, prefix: &str) -> Vec<u8> {
    let mut out = vec![op::PROTO, 2];
    empty_ordered_dict(&mut out);
    out.push(op::MARK);
    for (i, t) in state.iter().enumerate() {
        text(&mut out, &format!("{prefix}{}", t.key));
        global(&mut out, "torch._utils", "_rebuild_tensor_v2");
        out.push(op::MARK);
        // The storage, by persistent id: ('storage', FloatStorage, key, location, numel).
        out.push(op::MARK);
        text(&mut out, "storage");
        global(&mut out, "torch", "FloatStorage");
        text(&mut out, &i.to_string());
        text(&mut out, "cpu");
        int(&mut out, t.values.len());
        out.push(op::TUPLE);
        out.push(op::BINPERSID);
        int(&mut out, 0);
        int_tuple(&mut out, &t.shape);
        let strides: Vec<usize> = (0..t.shape.len()).map(|d| t.shape[d + 1..].iter().product()).collect();
        int_tuple(&mut out, &strides);
        out.push(op::NEWFALSE);
        empty_ordered_dict(&mut out);
        out.push(op::TUPLE);
        out.push(op::REDUCE);
    }
    out.push(op::SETITEMS);
    out.push(op::STOP);
    out
}

/// Writes `state` to `path` as the official code saves it, each key under `prefix`
/// (`"module."` for a checkpoint saved from `DataParallel`, as the released ones are).
pub fn write_pth(state: &StateDict, prefix: &str, path: &Path) {
    let file = std::fs::File::create(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut zip = zip::ZipWriter::new(std::io::BufWriter::new(file));
    let stored = zip::write::FileOptions::default().compression_method(zip::CompressionMethod::Stored);
    zip.start_file("archive/data.pkl", stored).unwrap();
    zip.write_all(&pickle(state, prefix)).unwrap();
    zip.start_file("archive/byteorder", stored).unwrap();
    zip.write_all(b"little").unwrap();
    for (i, t) in state.iter().enumerate() {
        zip.start_file(format!("archive/data/{i}"), stored).unwrap();
        let bytes: Vec<u8> = t.values.iter().flat_map(|v| v.to_le_bytes()).collect();
        zip.write_all(&bytes).unwrap();
    }
    zip.start_file("archive/version", stored).unwrap();
    zip.write_all(b"3\n").unwrap();
    zip.finish().unwrap().flush().unwrap();
}
