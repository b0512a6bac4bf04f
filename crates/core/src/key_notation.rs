//! The notation of a rename between an official state-dict key and our module path, written
//! once and read in both directions: the model crate's tables of official keys
//! (`dgstereo_model::official_keys::renames`) and the prior crate's Depth Anything V2 table are
//! written in it.
//!
//! Each side is a key fragment: names, digits and dots are literal, a leading `^` and a trailing
//! `$` anchor it at the key's start and end, and a brace holds a part both sides share: `{#}` a
//! number, `{*}` a name, `{a|b}` one of the names listed. Both sides hold the same braces in the
//! same order. A table of renames is applied in order to turn an official key into our path;
//! its inverse is each rename turned around, applied in the reverse order.

/// One rename, official key fragment to ours ([module docs](self) for the notation).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Rename {
    /// The fragment of the official key.
    pub official: &'static str,
    /// The same fragment of our module path.
    pub ours: &'static str,
}

impl Rename {
    /// The rename of `official` to `ours`.
    pub const fn new(official: &'static str, ours: &'static str) -> Self {
        Self { official, ours }
    }

    /// The braces of a side, in order.
    pub fn braces(side: &str) -> Vec<&str> {
        side.split('{').skip(1).filter_map(|rest| rest.split_once('}').map(|(inner, _)| inner)).collect()
    }
}

/// The regex pattern and replacement (in the form `burn`'s `KeyRemapper` takes) that turn a key
/// holding fragment `from` into one holding `to`.
fn compile(from: &str, to: &str) -> (String, String) {
    let mut pattern = String::new();
    let body = from.strip_prefix('^').inspect(|_| pattern.push('^')).unwrap_or(from);
    let (body, end) = body.strip_suffix('$').map_or((body, ""), |b| (b, "$"));
    let mut rest = body;
    while let Some((literal, after)) = rest.split_once('{') {
        pattern += &escape(literal);
        let (inner, after) = after.split_once('}').expect("a brace is closed");
        pattern += &match inner {
            "#" => r"(\d+)".to_string(),
            "*" => r"(\w+)".to_string(),
            names => format!("({})", names.split('|').map(escape).collect::<Vec<_>>().join("|")),
        };
        rest = after;
    }
    pattern += &escape(rest);
    pattern += end;
    let mut replacement = String::new();
    let body = to.trim_start_matches('^').trim_end_matches('$');
    let mut rest = body;
    let mut group = 0;
    while let Some((literal, after)) = rest.split_once('{') {
        group += 1;
        replacement += literal;
        replacement += &format!("${{{group}}}");
        rest = after.split_once('}').expect("a brace is closed").1;
    }
    replacement += rest;
    (pattern, replacement)
}

/// `literal` with its dots escaped (the notation's literals are names, digits and dots).
fn escape(literal: &str) -> String {
    literal.replace('.', r"\.")
}

/// `key` with every pattern of `remapper` applied in order.
pub fn apply(remapper: &burn::store::KeyRemapper, key: &str) -> String {
    remapper.patterns.iter().fold(key.to_string(), |k, (pattern, to)| pattern.replace_all(&k, to.as_str()).into_owned())
}

/// The patterns that turn an official key into our module path: the table's renames in order.
pub fn load_patterns(table: &[Rename]) -> Vec<(String, String)> {
    table.iter().map(|r| compile(r.official, r.ours)).collect()
}

/// The patterns that turn our module path into the official key: each rename of the table
/// turned around, in the reverse order.
pub fn save_patterns(table: &[Rename]) -> Vec<(String, String)> {
    table.iter().rev().map(|r| compile(r.ours, r.official)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Literals, anchors and each kind of brace become the regex and replacement they stand for.
    #[test]
    fn the_notation_compiles_to_patterns_and_replacements() {
        assert_eq!(compile("downsample.0.", "downsample."), (r"downsample\.0\.".into(), "downsample.".into()));
        assert_eq!(
            compile("^{stem_2|stem_4}.0.", "^{stem_2|stem_4}.block."),
            (r"^(stem_2|stem_4)\.0\.".into(), "${1}.block.".into())
        );
        assert_eq!(
            compile("{outputs08|outputs16}.{#}.0.", "{outputs08|outputs16}.{#}.block."),
            (r"(outputs08|outputs16)\.(\d+)\.0\.".into(), "${1}.${2}.block.".into())
        );
        assert_eq!(
            compile("^{spx|spx_gru}.{weight|bias}$", "^{spx|spx_gru}.0.{weight|bias}$"),
            (r"^(spx|spx_gru)\.(weight|bias)$".into(), "${1}.0.${2}".into())
        );
        assert_eq!(compile("feature_att_{*}.reduce.", "x"), (r"feature_att_(\w+)\.reduce\.".into(), "x".into()));
    }

    /// The inverse of a chain is its renames turned around in the reverse order, so a chain of
    /// moves (each GRU one stride finer) comes back whole.
    #[test]
    fn a_chain_of_moves_comes_back() {
        let chain =
            [Rename::new("^gru16.", "^gru32."), Rename::new("^gru08.", "^gru16."), Rename::new("^gru04.", "^gru08.")];
        let apply = |patterns: Vec<(String, String)>, key: &str| {
            let remapper = burn::store::KeyRemapper::from_patterns(patterns).unwrap();
            remapper.patterns.iter().fold(key.to_string(), |k, (p, r)| p.replace_all(&k, r.as_str()).into_owned())
        };
        for (official, ours) in [("gru04.w", "gru08.w"), ("gru08.w", "gru16.w"), ("gru16.w", "gru32.w")] {
            assert_eq!(apply(load_patterns(&chain), official), ours);
            assert_eq!(apply(save_patterns(&chain), ours), official);
        }
    }
}
