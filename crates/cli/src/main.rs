//! The `dgstereo` command-line tool.
fn main() {}
