//! `ferret scene check`: load a scene file (and its map), build its grid and report every
//! container: room, where the robot stands to search it, how far it is from the start.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Result, bail};
use ferret_world::distance::Place;
use ferret_world::{Distances, OccupancyGrid, SceneFile, WorldError};
use serde::Serialize;

use crate::common::GridArgs;

/// Scene files: a home described for a real robot, in YAML or JSON (format version 1).
///
/// A scene names rooms (name, type, polygon), containers (id, type, room, pose [x, y, yaw°],
/// size, optional access point and contents), optional doors, the robot's start, and optionally a
/// ROS map_server map (`map: {ros: map.yaml}`) to navigate on instead of walls drawn from the
/// polygons. The format is documented in crates/world/src/scene.rs; examples/apartment/ holds one.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Load a scene, build its grid and distances, list its containers. Exits non-zero when the
    /// scene is invalid or a container cannot be reached from the start.
    Check(CheckArgs),
}

/// Arguments of `scene check`.
#[derive(clap::Args, Debug)]
pub struct CheckArgs {
    /// The scene file.
    file: PathBuf,
    #[command(flatten)]
    grid: GridArgs,
    /// Print JSON instead of the table.
    #[arg(long)]
    json: bool,
}

#[derive(Serialize)]
struct ContainerLine {
    id: String,
    r#type: String,
    room: Option<String>,
    contents: Vec<String>,
    access: Option<[f64; 2]>,
    from_start_m: Option<f64>,
}

#[derive(Serialize)]
struct Report {
    file: String,
    name: String,
    rooms: usize,
    map: Option<String>,
    grid: String,
    containers: Vec<ContainerLine>,
    unreachable: Vec<String>,
}

/// Runs a `scene` subcommand.
pub fn run(cmd: Command) -> Result<ExitCode> {
    match cmd {
        Command::Check(args) => check(args),
    }
}

fn check(args: CheckArgs) -> Result<ExitCode> {
    args.grid.validate()?;
    let scene = SceneFile::load(&args.file)?;
    let house = &scene.house;
    let grid = OccupancyGrid::build(house, &args.grid.params())?;
    let (distances, unreachable) = match Distances::compute(house, &grid) {
        Ok(d) => (Some(d), Vec::new()),
        Err(WorldError::Unreachable { names, .. }) => (None, names),
        Err(e) => bail!(e),
    };
    let report = Report {
        file: args.file.display().to_string(),
        name: house.name.clone(),
        rooms: house.rooms.len(),
        map: house.map.as_ref().map(|m| {
            format!(
                "{} ({}×{} cells of {} m)",
                m.source, m.width, m.height, m.resolution
            )
        }),
        grid: format!(
            "{}×{} cells of {} m",
            grid.width(),
            grid.height(),
            grid.resolution()
        ),
        containers: house
            .containers
            .iter()
            .enumerate()
            .map(|(i, c)| ContainerLine {
                id: c.id.clone(),
                r#type: c.object_type.to_string(),
                room: house.container_room(i).map(|r| r.id.clone()),
                contents: scene
                    .truth
                    .contents(i)
                    .iter()
                    .map(|o| o.object_type.to_string())
                    .collect(),
                access: grid.access_cell(i).map(|cell| {
                    let p = grid.center(cell);
                    [p.x, p.z]
                }),
                from_start_m: distances
                    .as_ref()
                    .map(|d| d.between(Place::Start, Place::Container(i))),
            })
            .collect(),
        unreachable,
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        println!(
            "scene {} ({}): {} rooms, {} containers",
            report.name,
            report.file,
            report.rooms,
            report.containers.len()
        );
        if let Some(m) = &report.map {
            println!("map: {m}");
        }
        println!("grid: {}", report.grid);
        println!(
            "{:<16} {:<14} {:<14} {:>16} {:>12}  contents",
            "container", "type", "room", "access (x, y)", "from start m"
        );
        for c in &report.containers {
            let access = c.access.map_or("unreachable".to_string(), |a| {
                format!("({:.2}, {:.2})", a[0], a[1])
            });
            let from = c
                .from_start_m
                .map_or("-".to_string(), |d| format!("{d:.2}"));
            println!(
                "{:<16} {:<14} {:<14} {:>16} {:>12}  {}",
                c.id,
                c.r#type,
                c.room.as_deref().unwrap_or("-"),
                access,
                from,
                c.contents.join(", ")
            );
        }
    }
    if report.unreachable.is_empty() {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!(
            "error: {} container(s) cannot be reached from the start: {}",
            report.unreachable.len(),
            report.unreachable.join(", ")
        );
        Ok(ExitCode::FAILURE)
    }
}
