//! `ferret houses check` and `ferret houses show`.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use ferret_report::{PlanOptions, PlanPath, Rgb, draw_floor_plan};
use ferret_world::{Distances, House, OccupancyGrid, Place, WorldError};
use rayon::prelude::*;
use serde::Serialize;

use crate::common::{GridArgs, HouseArgs, progress};

/// Check and draw houses.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Load and validate houses, build their grids and distances, report per house and in total.
    /// Exits non-zero when any house is invalid or has an unreachable container.
    Check(CheckArgs),
    /// Draw a house's floor plan (PNG or SVG by the file extension).
    Show(ShowArgs),
}

/// Arguments of `houses check`.
#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    #[command(flatten)]
    houses: HouseArgs,
    #[command(flatten)]
    grid: GridArgs,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
}

/// Arguments of `houses show`.
#[derive(clap::Args, Debug)]
pub struct ShowArgs {
    #[command(flatten)]
    houses: HouseArgs,
    #[command(flatten)]
    grid: GridArgs,
    /// Index of the house in the file (or among the generated houses).
    #[arg(long, default_value_t = 0)]
    index: usize,
    /// Output picture: `.png` or `.svg`.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
    /// Draw the shortest path between two places: `start`, a container id (`4|1`) or a container
    /// type (`Fridge`, the first one).
    #[arg(long, num_args = 2, value_names = ["FROM", "TO"])]
    path: Option<Vec<String>>,
    /// Shade occupied grid cells (walls, furniture, robot-radius inflation).
    #[arg(long)]
    occupancy: bool,
}

/// Runs a `houses` subcommand.
pub fn run(cmd: Command) -> Result<ExitCode> {
    match cmd {
        Command::Check(args) => check(args),
        Command::Show(args) => show(args),
    }
}

#[derive(Serialize)]
struct HouseLine {
    index: usize,
    name: String,
    rooms: usize,
    containers: usize,
    small_objects: usize,
    unreachable_containers: Vec<String>,
    grid: String,
    free_cells: usize,
    milliseconds: f64,
    error: Option<String>,
}

#[derive(Serialize)]
struct CheckReport {
    source: String,
    houses: usize,
    valid: usize,
    invalid: usize,
    containers: usize,
    small_objects: usize,
    unreachable_containers: usize,
    seconds: f64,
    median_ms_per_house: f64,
    invalid_houses: Vec<String>,
    per_house: Vec<HouseLine>,
}

fn check(args: CheckArgs) -> Result<ExitCode> {
    let started = Instant::now();
    // A check reports every bad house, so it never stops at the first.
    args.grid.validate()?;
    let loaded = args.houses.load_with(true)?;
    if loaded.scenes.is_empty() && loaded.skipped.is_empty() {
        bail!("no houses to check in {}", loaded.source);
    }
    let params = args.grid.params();
    let bar = progress(loaded.scenes.len(), "checking");
    let mut lines: Vec<HouseLine> = loaded
        .scenes
        .par_iter()
        .map(|scene| {
            let t = Instant::now();
            let house = &scene.house;
            let mut line = HouseLine {
                index: house.index,
                name: house.name.clone(),
                rooms: house.rooms.len(),
                containers: house.containers.len(),
                small_objects: scene.truth.object_count(),
                unreachable_containers: vec![],
                grid: String::new(),
                free_cells: 0,
                milliseconds: 0.0,
                error: None,
            };
            match OccupancyGrid::build(house, &params) {
                Ok(grid) => {
                    line.grid = format!("{}x{}", grid.width(), grid.height());
                    line.free_cells = grid.free_count();
                    match Distances::compute(house, &grid) {
                        Ok(_) => {}
                        Err(WorldError::Unreachable { names, .. }) => {
                            line.unreachable_containers = names
                        }
                        Err(e) => line.error = Some(e.to_string()),
                    }
                }
                Err(e) => line.error = Some(e.to_string()),
            }
            line.milliseconds = t.elapsed().as_secs_f64() * 1e3;
            bar.inc(1);
            line
        })
        .collect();
    bar.finish_and_clear();
    lines.sort_by_key(|l| l.index);
    let mut ms: Vec<f64> = lines.iter().map(|l| l.milliseconds).collect();
    ms.sort_by(f64::total_cmp);
    let bad_maps = lines
        .iter()
        .filter(|l| l.error.is_some() || !l.unreachable_containers.is_empty())
        .count();
    let report = CheckReport {
        source: loaded.source.clone(),
        houses: lines.len() + loaded.skipped.len(),
        valid: lines.len() - bad_maps,
        invalid: loaded.skipped.len() + bad_maps,
        containers: lines.iter().map(|l| l.containers).sum(),
        small_objects: lines.iter().map(|l| l.small_objects).sum(),
        unreachable_containers: lines.iter().map(|l| l.unreachable_containers.len()).sum(),
        seconds: started.elapsed().as_secs_f64(),
        median_ms_per_house: ms.get(ms.len() / 2).copied().unwrap_or(0.0),
        invalid_houses: loaded.skipped.clone(),
        per_house: lines,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "{:>5}  {:<34} {:>5} {:>10} {:>7} {:>11} {:>9} {:>8}",
            "index", "house", "rooms", "containers", "objects", "unreachable", "grid", "ms"
        );
        for l in &report.per_house {
            println!(
                "{:>5}  {:<34} {:>5} {:>10} {:>7} {:>11} {:>9} {:>8.1}",
                l.index,
                truncate(&l.name, 34),
                l.rooms,
                l.containers,
                l.small_objects,
                l.unreachable_containers.len(),
                l.grid,
                l.milliseconds
            );
            for name in &l.unreachable_containers {
                println!("       unreachable: {name}");
            }
            if let Some(e) = &l.error {
                println!("       error: {e}");
            }
        }
        for e in &report.invalid_houses {
            println!("invalid: {e}");
        }
        println!(
            "total: {} houses, {} valid, {} invalid, {} containers, {} small objects, {} unreachable containers, {:.2} s (median {:.1} ms per house)",
            report.houses,
            report.valid,
            report.invalid,
            report.containers,
            report.small_objects,
            report.unreachable_containers,
            report.seconds,
            report.median_ms_per_house
        );
    }
    Ok(if report.invalid == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

fn truncate(s: &str, n: usize) -> String {
    if s.chars().count() <= n {
        s.to_string()
    } else {
        let tail: String = s
            .chars()
            .rev()
            .take(n - 1)
            .collect::<Vec<_>>()
            .into_iter()
            .rev()
            .collect();
        format!("…{tail}")
    }
}

/// Resolves `start`, a container id or a container type to a place.
pub fn place_named(house: &House, name: &str) -> Result<Place> {
    if name.eq_ignore_ascii_case("start") {
        return Ok(Place::Start);
    }
    if let Some(i) = house.container_index(name) {
        return Ok(Place::Container(i));
    }
    if let Some(i) = house
        .containers
        .iter()
        .position(|c| c.object_type.as_str().eq_ignore_ascii_case(name))
    {
        return Ok(Place::Container(i));
    }
    let known: Vec<String> = house
        .containers
        .iter()
        .map(|c| format!("{} ({})", c.id, c.object_type))
        .collect();
    bail!(
        "{}: no place named `{name}`; use `start`, a container id or type: {}",
        house.name,
        known.join(", ")
    )
}

fn show(args: ShowArgs) -> Result<ExitCode> {
    let mut houses = args.houses.clone();
    if houses.range.is_none() {
        houses.range = Some(
            format!("{}", args.index)
                .parse()
                .map_err(|e| anyhow::anyhow!("{e}"))?,
        );
    }
    args.grid.validate()?;
    let loaded = houses.load_with(false)?;
    let scene = loaded
        .scenes
        .into_iter()
        .find(|s| s.house.index == args.index)
        .with_context(|| format!("no house with index {} in {}", args.index, loaded.source))?;
    let house = &scene.house;
    let needs_grid = args.path.is_some() || args.occupancy;
    let grid = if needs_grid {
        Some(OccupancyGrid::build(house, &args.grid.params())?)
    } else {
        None
    };
    let mut opts = PlanOptions::default();
    if let (Some(names), Some(grid)) = (&args.path, &grid) {
        let from = place_named(house, &names[0])?;
        let to = place_named(house, &names[1])?;
        let distances = Distances::compute(house, grid)?;
        let points = distances
            .path(from, to)
            .context("no path between these places")?;
        let metres = distances.between(from, to);
        opts.paths.push(PlanPath {
            label: format!("{} → {}: {metres:.2} m", names[0], names[1]),
            color: Rgb {
                r: 220,
                g: 40,
                b: 40,
            },
            points,
        });
    }
    let free = grid
        .as_ref()
        .map(|g| move |p| g.cell_of(p).is_some_and(|c| g.is_free(c)));
    if args.occupancy {
        opts.occupancy = free
            .as_ref()
            .map(|f| f as &dyn Fn(ferret_world::Point) -> bool);
    }
    crate::output::write_with_path(&args.out, |p| {
        draw_floor_plan(house, &opts, p)?;
        Ok(())
    })?;
    println!(
        "wrote {} ({}: {} rooms, {} containers)",
        args.out.display(),
        house.name,
        house.rooms.len(),
        house.containers.len()
    );
    Ok(ExitCode::SUCCESS)
}
