//! `ferret generate`: write procedurally generated houses in the ProcTHOR schema.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Result, bail};
use ferret_world::generate::{GeneratorOptions, generate_houses, write_houses};

/// Generate houses (1–10 rooms, containers and small objects) deterministically from a seed and
/// write them as ProcTHOR JSON: `.jsonl.gz`, `.jsonl` or (one house) `.json`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Number of houses (at most 10000).
    #[arg(long, default_value_t = 100, value_parser = crate::args::house_count)]
    count: usize,
    /// Seed; the same seed always gives the same houses.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Fewest rooms per house.
    #[arg(long, default_value_t = 1)]
    min_rooms: usize,
    /// Most rooms per house.
    #[arg(long, default_value_t = 10)]
    max_rooms: usize,
    /// Output file.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

/// Runs `ferret generate`.
pub fn run(args: Args) -> Result<ExitCode> {
    if args.min_rooms == 0 || args.min_rooms > args.max_rooms || args.max_rooms > 10 {
        bail!("rooms must satisfy 1 <= --min-rooms <= --max-rooms <= 10");
    }
    let opts = GeneratorOptions {
        min_rooms: args.min_rooms,
        max_rooms: args.max_rooms,
        ..GeneratorOptions::default()
    };
    let houses = generate_houses(args.count, args.seed, &opts);
    crate::output::write_with_path(&args.out, |p| Ok(write_houses(p, &houses)?))?;
    println!("wrote {} houses to {}", houses.len(), args.out.display());
    Ok(ExitCode::SUCCESS)
}
