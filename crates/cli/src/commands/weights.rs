//! `dgstereo weights list` and `dgstereo weights fetch NAME...`: the official checkpoints known
//! by name ([`dgstereo_weights`]), their sources, licences and how a fetch is checked, and where
//! the cache keeps them.

use std::process::ExitCode;

use anyhow::bail;
use clap::{Args, Subcommand};
use dgstereo_weights::{CATALOG, Role, Source, find};

/// The `weights` subcommands.
#[derive(Subcommand)]
pub enum WeightsCommand {
    /// Lists the names `--weights` and `--prior-weights` take, with source, licence, how a fetch
    /// is checked and whether each is in the cache.
    List,
    /// Downloads official checkpoints into the cache (resumable; checked before they are kept).
    Fetch(FetchArgs),
}

/// Names to fetch.
#[derive(Args)]
pub struct FetchArgs {
    /// Names as `dgstereo weights list` prints them (`raftstereo-middlebury`,
    /// `depth-anything-v2-small`).
    #[arg(required = true)]
    names: Vec<String>,
}

fn role(r: Role) -> &'static str {
    match r {
        Role::Stereo => "--weights",
        Role::Prior => "--prior-weights",
    }
}

pub fn run(cmd: WeightsCommand) -> anyhow::Result<ExitCode> {
    let fetcher = crate::fetching::fetcher()?;
    match cmd {
        WeightsCommand::List => {
            let cache = fetcher.cache();
            println!("cache: {} (hub files: {})", cache.root().display(), cache.hub().display());
            for w in &CATALOG {
                let state = match cache.find(w) {
                    Some(path) => format!("cached: {}", path.display()),
                    None => match w.source {
                        Source::Page { file, .. } => format!(
                            "not cached: download {file} by hand and give its path to {}, or put it at {}",
                            role(w.role),
                            cache.file_path(w).unwrap_or_default().display()
                        ),
                        _ => "not cached".to_string(),
                    },
                };
                println!(
                    "\n{}  ({})\n  {}\n  licence: {}\n  source: {}\n  verified: {}\n  {state}",
                    w.name,
                    role(w.role),
                    w.about,
                    w.licence,
                    w.origin(fetcher.sources()),
                    w.verification()
                );
            }
        }
        WeightsCommand::Fetch(a) => {
            let unknown: Vec<&str> = a.names.iter().map(String::as_str).filter(|n| find(n).is_none()).collect();
            if !unknown.is_empty() {
                bail!(
                    "unknown weights name(s) {}: known are {}",
                    unknown.join(", "),
                    CATALOG.iter().map(|w| w.name).collect::<Vec<_>>().join(", ")
                );
            }
            for w in a.names.iter().filter_map(|n| find(n)) {
                eprintln!("{}: {} (licence: {})", w.name, w.origin(fetcher.sources()), w.licence);
                let fetched = fetcher.fetch(w)?;
                eprintln!("{}: verified: {}", w.name, fetched.verified.describe());
                println!("{}\t{}", w.name, fetched.path.display());
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}
