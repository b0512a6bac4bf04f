//! The names a serde enum accepts, asked of serde itself.
//!
//! Each stage lists its kinds in its own crate (`FusionConfig::variants`, `GuidanceKind::ALL`,
//! ...), and a test compares the list with what deserialisation accepts. serde keeps that list
//! in the derived code and hands it only to an error's `unknown_variant(name, expected)`; so a
//! probe name that no enum has is deserialised here with an error type that keeps `expected`,
//! instead of reading the list back out of an error message's text.

use std::fmt;

use serde::de::value::{MapDeserializer, StrDeserializer};
use serde::de::{self, DeserializeOwned};

/// A name no enum of ours has.
const PROBE: &str = "\u{1}unknown";

/// The error of a probe: the names serde expected, when it said so.
#[derive(Debug)]
struct Probed {
    expected: Option<&'static [&'static str]>,
    message: String,
}

impl fmt::Display for Probed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for Probed {}

impl de::Error for Probed {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        Self { expected: None, message: msg.to_string() }
    }

    fn unknown_variant(variant: &str, expected: &'static [&'static str]) -> Self {
        Self { expected: Some(expected), message: format!("unknown variant {variant:?}") }
    }
}

/// What a probe's result says: the expected names, or what went otherwise.
fn expected<T>(result: Result<T, Probed>) -> Result<Vec<&'static str>, String> {
    match result {
        Ok(_) => Err("the probe name was accepted".into()),
        Err(Probed { expected: Some(names), .. }) => Ok(names.to_vec()),
        Err(Probed { message, .. }) => Err(message),
    }
}

/// The names a plain enum (its variants written as strings, `"gradient"`) accepts, in the
/// enum's order.
///
/// # Errors
/// What serde said when it did not answer with the list (a type that is not such an enum).
pub fn accepted_names<T: DeserializeOwned>() -> Result<Vec<&'static str>, String> {
    expected(T::deserialize(StrDeserializer::<Probed>::new(PROBE)))
}

/// The kinds an internally tagged enum (`#[serde(tag = "kind")]`, a table with `kind = "..."`)
/// accepts under `tag`, in the enum's order.
///
/// # Errors
/// What serde said when it did not answer with the list.
pub fn accepted_kinds<T: DeserializeOwned>(tag: &str) -> Result<Vec<&'static str>, String> {
    let table = MapDeserializer::<_, Probed>::new(std::iter::once((tag, PROBE)));
    expected(T::deserialize(table))
}

#[cfg(test)]
mod tests {
    use serde::Deserialize;

    use super::*;

    #[derive(Debug, Deserialize)]
    #[serde(rename_all = "kebab-case")]
    #[allow(dead_code)]
    enum Plain {
        First,
        SecondName,
    }

    #[derive(Debug, Deserialize)]
    #[serde(tag = "kind", rename_all = "kebab-case", deny_unknown_fields)]
    #[allow(dead_code)]
    enum Tagged {
        Off {},
        On { level: u32 },
    }

    #[test]
    fn serde_names_the_variants_of_plain_and_tagged_enums() {
        assert_eq!(accepted_names::<Plain>().unwrap(), ["first", "second-name"]);
        assert_eq!(accepted_kinds::<Tagged>("kind").unwrap(), ["off", "on"]);
        assert!(accepted_names::<u32>().is_err());
        assert!(accepted_kinds::<Tagged>("type").is_err());
    }
}
