//! `dgstereo weights list` and `dgstereo weights fetch NAME...`: the official checkpoints known
//! by name ([`dgstereo_weights`]), their sources and licences, and where the cache keeps them.

use std::process::ExitCode;

use anyhow::bail;
use clap::{Args, Subcommand};
use dgstereo_weights::{CATALOG, Fetcher, Role, find};

/// The `weights` subcommands.
#[derive(Subcommand)]
pub enum WeightsCommand {
    /// Lists the names `--weights` and `--prior-weights` take, with source, licence and whether
    /// each is in the cache.
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
    let fetcher = Fetcher::from_env()?;
    match cmd {
        WeightsCommand::List => {
            println!("cache: {} (hub files: {})", fetcher.cache().root().display(), fetcher.cache().hub().display());
            for w in &CATALOG {
                let state = match fetcher.cache().find(w) {
                    Some(path) => format!("cached: {}", path.display()),
                    None => "not cached".to_string(),
                };
                println!(
                    "\n{}  ({})\n  {}\n  licence: {}\n  source: {}\n  {state}",
                    w.name,
                    role(w.role),
                    w.about,
                    w.licence,
                    w.origin(fetcher.sources())
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
            for name in &a.names {
                let w = find(name).expect("checked above");
                eprintln!("{}: {} (licence: {})", w.name, w.origin(fetcher.sources()), w.licence);
                let path = fetcher.get(w)?;
                println!("{}\t{}", w.name, path.display());
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}
