//! Safetensors files whose bytes depend only on their contents.
//!
//! A safetensors file starts with a JSON header listing the tensors and the metadata. The
//! writers keep the metadata in a hash map, so two processes writing the same weights and the
//! same metadata order the header differently, and a `sha256sum` check of a reproduced run
//! fails although every tensor is identical. [`canonical_header`] rewrites the header with
//! every object's keys sorted; the tensor data, addressed by offsets from the header's end, is
//! untouched.

use std::collections::BTreeMap;

use dgstereo_core::{Error, Result};
use serde_json::Value;

fn sorted(value: Value) -> Value {
    match value {
        Value::Object(map) => {
            let sorted: BTreeMap<String, Value> = map.into_iter().map(|(k, v)| (k, sorted(v))).collect();
            Value::Object(sorted.into_iter().collect())
        }
        Value::Array(items) => Value::Array(items.into_iter().map(sorted).collect()),
        other => other,
    }
}

/// `bytes`, a safetensors file, with its header's keys sorted (padded with spaces to a multiple
/// of 8 bytes, as the format's writers do).
///
/// # Errors
/// `bytes` is not a safetensors file.
pub fn canonical_header(bytes: &[u8]) -> Result<Vec<u8>> {
    let bad = |m: &str| Error::encode("a canonical safetensors header", format!("not a safetensors file: {m}"));
    let len_bytes: [u8; 8] =
        bytes.get(..8).and_then(|b| b.try_into().ok()).ok_or_else(|| bad("shorter than 8 bytes"))?;
    let len = usize::try_from(u64::from_le_bytes(len_bytes)).map_err(|_| bad("header length"))?;
    let header = bytes.get(8..8 + len).ok_or_else(|| bad("truncated header"))?;
    let value: Value = serde_json::from_slice(header).map_err(|e| bad(&e.to_string()))?;
    let mut text = serde_json::to_string(&sorted(value)).map_err(|e| bad(&e.to_string()))?;
    while text.len() % 8 != 0 {
        text.push(' ');
    }
    let mut out = Vec::with_capacity(bytes.len() + 8);
    out.extend_from_slice(&(text.len() as u64).to_le_bytes());
    out.extend_from_slice(text.as_bytes());
    out.extend_from_slice(&bytes[8 + len..]);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn file(header: &str, data: &[u8]) -> Vec<u8> {
        let mut out = (header.len() as u64).to_le_bytes().to_vec();
        out.extend_from_slice(header.as_bytes());
        out.extend_from_slice(data);
        out
    }

    #[test]
    fn orders_differing_only_in_key_order_give_the_same_bytes() {
        let data = [1u8, 2, 3, 4];
        let a =
            file(r#"{"__metadata__":{"b":"2","a":"1"},"t":{"dtype":"U8","shape":[4],"data_offsets":[0,4]}}"#, &data);
        let b =
            file(r#"{"t":{"data_offsets":[0,4],"shape":[4],"dtype":"U8"},"__metadata__":{"a":"1","b":"2"}}"#, &data);
        let (ca, cb) = (canonical_header(&a).unwrap(), canonical_header(&b).unwrap());
        assert_eq!(ca, cb);
        assert_eq!((ca.len() - data.len()) % 8, 0, "the header is padded to 8 bytes");
        let parsed = safetensors::SafeTensors::deserialize(&ca).unwrap();
        assert_eq!(parsed.tensor("t").unwrap().data(), &data);
        assert!(canonical_header(&a[..5]).is_err());
    }
}
