//! Seeded weights: every tensor of an official state dict as a pure function of its key and
//! shape, so a conformance file needs no checkpoint beside it.
//!
//! The arithmetic is `../shared/golden/seeded_weights.py`'s, exact in IEEE float32/float64, so
//! the tensors rebuilt here equal the ones the official code ran with, bit for bit. For a tensor
//! named `KEY` with shape `S` and `n = prod(S)` elements:
//! - `h = FNV-1a 64(SALT + KEY)`; `z_i = splitmix64(h + i)` (wrapping);
//! - `u_i = (z_i >> 40) / 2^24` (24 bits, exact in f32), `t_i = 2·u_i - 1`;
//! - rank ≥ 2: `t_i · f32(1 / sqrt(fan_in))` (the scale computed in f64, `fan_in = prod(S[1..])`);
//!   a key ending in `running_var`: `u_i · 0.5 + 1`; in `weight` (rank ≤ 1): `t_i · 0.1 + 1`;
//!   any other: `t_i · 0.1` (each operation one float32 rounding, none fused).
//!
//! A golden file's metadata lists the keys and shapes (`keys`, in state-dict order), the keys
//! that are another key's storage (`aliases`: later key → first key, one module registered
//! under two names) and the constant buffers that keep their values (`kept`, stored in the file
//! as tensors `state.<key>`). [`golden_state_dict`] rebuilds the whole state dict from it, in
//! the official layout, for the official-checkpoint loader.

use std::collections::BTreeMap;
use std::path::Path;

use dgstereo_core::{Error, Result};
use safetensors::SafeTensors;

/// One tensor of a state dict: official key, shape, row-major float32 values.
#[derive(Debug, Clone, PartialEq)]
pub struct StateTensor {
    /// The official state-dict key.
    pub key: String,
    /// Its shape.
    pub shape: Vec<usize>,
    /// Its values, row-major.
    pub values: Vec<f32>,
}

/// A state dict in the official layout, in the order its keys were listed.
pub type StateDict = Vec<StateTensor>;

/// FNV-1a 64 of `bytes` (offset `0xcbf29ce484222325`, prime `0x100000001b3`).
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3))
}

/// The splitmix64 finaliser of `x` (with its increment), wrapping mod 2^64.
pub fn splitmix64(x: u64) -> u64 {
    let z = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    let z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// The values of the seeded tensor `key` of `shape` (row-major), `salt` prefixed to the key.
pub fn seeded_values(key: &str, shape: &[usize], salt: &str) -> Vec<f32> {
    let n: usize = shape.iter().product();
    let h = fnv1a64(format!("{salt}{key}").as_bytes());
    let scale = (shape.len() >= 2).then(|| {
        let fan_in: usize = shape[1..].iter().product();
        (1.0 / (fan_in as f64).sqrt()) as f32
    });
    (0..n as u64)
        .map(|i| {
            let u = (splitmix64(h.wrapping_add(i)) >> 40) as f32 / 16_777_216.0;
            let t = u * 2.0 - 1.0;
            match scale {
                Some(s) => t * s,
                None if key.ends_with("running_var") => u * 0.5 + 1.0,
                None if key.ends_with("weight") => t * 0.1 + 1.0,
                None => t * 0.1,
            }
        })
        .collect()
}

fn metadata_json<T: serde::de::DeserializeOwned>(
    metadata: &BTreeMap<String, String>,
    name: &str,
    path: &Path,
) -> Result<T> {
    let text = metadata.get(name).ok_or_else(|| Error::format(path, format!("no metadata entry '{name}'")))?;
    serde_json::from_str(text).map_err(|e| Error::format(path, format!("metadata entry '{name}': {e}")))
}

/// The metadata of a safetensors file (empty when it has none).
pub fn safetensors_metadata(bytes: &[u8], path: &Path) -> Result<BTreeMap<String, String>> {
    let (_, meta) =
        SafeTensors::read_metadata(bytes).map_err(|e| Error::format(path, format!("not a safetensors file: {e}")))?;
    Ok(meta.metadata().clone().unwrap_or_default().into_iter().collect())
}

/// Rebuilds the state dict of a seeded golden file (`../shared/golden/*_seeded.*`) from its
/// metadata: every key of `keys` seeded with `salt`, an alias holding its first key's values, a
/// kept buffer read from the file's `state.<key>` tensor. Returns it with the metadata.
///
/// # Errors
/// [`Error::Io`] when the file cannot be read; [`Error::Format`] naming the metadata entry or
/// tensor that is missing or malformed.
pub fn golden_state_dict(path: &Path) -> Result<(StateDict, BTreeMap<String, String>)> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let metadata = safetensors_metadata(&bytes, path)?;
    let keys: Vec<(String, Vec<usize>)> = metadata_json(&metadata, "keys", path)?;
    let aliases: BTreeMap<String, String> = metadata_json(&metadata, "aliases", path)?;
    let kept: Vec<String> = metadata_json(&metadata, "kept", path)?;
    let salt = metadata.get("salt").cloned().unwrap_or_default();
    let file =
        SafeTensors::deserialize(&bytes).map_err(|e| Error::format(path, format!("not a safetensors file: {e}")))?;
    let mut built: BTreeMap<String, usize> = BTreeMap::new();
    let mut state = StateDict::with_capacity(keys.len());
    for (key, shape) in keys {
        let values = if let Some(first) = aliases.get(&key) {
            let at = built.get(first).ok_or_else(|| {
                Error::format(path, format!("alias '{key}' names '{first}', which no earlier key is"))
            })?;
            state[*at].values.clone()
        } else if kept.contains(&key) {
            let name = format!("state.{key}");
            let view = file.tensor(&name).map_err(|e| Error::format(path, format!("kept buffer '{name}': {e}")))?;
            if view.dtype() != safetensors::Dtype::F32 || view.shape() != shape.as_slice() {
                return Err(Error::format(
                    path,
                    format!("'{name}' is {:?} {:?}, the key lists float32 {shape:?}", view.dtype(), view.shape()),
                ));
            }
            view.data().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
        } else {
            seeded_values(&key, &shape, &salt)
        };
        built.insert(key.clone(), state.len());
        state.push(StateTensor { key, shape, values });
    }
    Ok((state, metadata))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bit patterns computed once by `../shared/golden/seeded_weights.py` (its `seeded(key,
    /// shape, salt)` in numpy), for one tensor of each rule: element 0, 1 and the last.
    #[test]
    fn values_are_those_of_the_reference_arithmetic() {
        assert_eq!(fnv1a64(b"fnet.conv1.weight"), 0x3c66_0885_1a7d_5acf);
        // (key, shape, salt, [(element, bits)])
        type Case<'a> = (&'a str, &'a [usize], &'a str, [(usize, u32); 3]);
        let cases: [Case; 8] = [
            ("fnet.conv1.weight", &[64, 3, 7, 7], "", [(0, 0x3cfa_f8a2), (1, 0x3d34_b23e), (9407, 0xbd71_0abf)]),
            ("cnet.norm1.running_var", &[64], "", [(0, 0x3f92_dd31), (1, 0x3fab_12b7), (63, 0x3faf_0b6e)]),
            ("cnet.norm1.weight", &[64], "", [(0, 0x3f67_79ce), (1, 0x3f8b_e84c), (63, 0x3f80_5799)]),
            ("cnet.norm1.running_mean", &[64], "", [(0, 0xbd49_874a), (1, 0xbc05_c940), (63, 0xbda6_5337)]),
            (
                "defomencoder.depth_anything.pretrained.cls_token",
                &[1, 1, 384],
                "",
                [(0, 0xbd0c_37ac), (1, 0xbc25_6657), (383, 0x3c5c_5d14)],
            ),
            ("fnet.conv1.weight", &[64, 3, 7, 7], "igev/", [(0, 0x3d02_b2b0), (1, 0x3d45_f350), (9407, 0x3d9e_df79)]),
            (
                "defomencoder.depth_anything.pretrained.blocks.0.ls1.gamma",
                &[384],
                "",
                [(0, 0x3d17_d167), (1, 0xbdb3_7990), (383, 0xbd87_90c3)],
            ),
            ("update_block.disp_head.conv2.bias", &[1], "", [(0, 0x3c37_eae7), (0, 0x3c37_eae7), (0, 0x3c37_eae7)]),
        ];
        for (key, shape, salt, expected) in cases {
            let values = seeded_values(key, shape, salt);
            assert_eq!(values.len(), shape.iter().product::<usize>(), "{key}");
            for (i, bits) in expected {
                assert_eq!(values[i].to_bits(), bits, "{salt}{key}[{i}] = {}", values[i]);
            }
        }
        // A scalar (rank 0) is one element by the last rule.
        assert_eq!(seeded_values("x.bias", &[], "")[0].to_bits(), 0xbdab_bdad);
    }
}
