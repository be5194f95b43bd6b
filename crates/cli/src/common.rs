//! What several commands share: loading houses (or generating them), building maps in parallel
//! with a progress bar, and logging.

use std::io::IsTerminal;
use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use ferret_world::procthor::{AssetDatabase, HouseRange, LoadOptions, load_scenes};
use ferret_world::{
    AccessRule, ContainerSet, Distances, GridParams, OccupancyGrid, Scene, WorldError,
};
use indicatif::{ParallelProgressIterator, ProgressBar, ProgressStyle};
use rayon::prelude::*;

/// Sends `tracing` output to stderr; `-v` raises the level, `RUST_LOG` overrides.
pub fn init_tracing(verbose: u8) {
    let default = match verbose {
        0 => "warn",
        1 => "info",
        _ => "debug",
    };
    let filter = tracing_subscriber::EnvFilter::try_from_default_env()
        .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new(default));
    // Colour codes only for a terminal: in a log file or a pipe they are noise.
    let _ = tracing_subscriber::fmt()
        .with_env_filter(filter)
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .try_init();
}

/// Where houses come from.
#[derive(clap::Args, Clone, Debug)]
pub struct HouseArgs {
    /// ProcTHOR houses: a .json house, or .jsonl / .jsonl.gz with one house per line; or a scene
    /// file (.yaml/.yml, or .json with `ferret_scene`; see `ferret scene --help`). Without it,
    /// ferret generates houses (see --generate and --house-seed). Limits that keep memory
    /// bounded, each an error naming file and house: 64 MiB per line (house), 2000 containers
    /// per house, 16.7 M grid cells per house (see --resolution).
    #[arg(long, value_name = "PATH")]
    pub houses: Option<PathBuf>,
    /// Which houses of the file, by 0-based index: `0..150`, `7`, `3..`, `..10`.
    #[arg(long, value_name = "A..B")]
    pub range: Option<HouseRange>,
    /// The ProcTHOR generator's asset-database.json: object types and bounding boxes per assetId.
    /// Without it, ferret's own assetId→type mapping and per-type sizes are used.
    #[arg(long, value_name = "PATH")]
    pub asset_db: Option<PathBuf>,
    /// Report invalid houses and go on with the rest instead of stopping at the first.
    #[arg(long)]
    pub skip_invalid: bool,
    /// Houses to generate when --houses is not given.
    #[arg(long, value_name = "N", default_value_t = 100)]
    pub generate: usize,
    /// Seed of the generated houses.
    #[arg(long, value_name = "S", default_value_t = 0)]
    pub house_seed: u64,
}

/// Houses ready for use, and what was skipped on the way.
pub struct LoadedHouses {
    /// The valid houses.
    pub scenes: Vec<Scene>,
    /// One message per skipped house.
    pub skipped: Vec<String>,
    /// Where they came from, for reports.
    pub source: String,
}

impl HouseArgs {
    /// Loads the houses these arguments name, or generates the default ones.
    pub fn load(&self) -> Result<LoadedHouses> {
        self.load_with(self.skip_invalid)
    }

    /// Like [`load`](Self::load) with an explicit skip-invalid choice.
    pub fn load_with(&self, skip_invalid: bool) -> Result<LoadedHouses> {
        self.load_inner(skip_invalid, ContainerSet::Receptacles)
    }

    /// Like [`load`](Self::load), ProcTHOR files read with the container set `containers`
    /// (generated houses and scene files name their containers themselves).
    pub fn load_for(&self, containers: ContainerSet) -> Result<LoadedHouses> {
        self.load_inner(self.skip_invalid, containers)
    }

    fn load_inner(&self, skip_invalid: bool, containers: ContainerSet) -> Result<LoadedHouses> {
        let Some(path) = &self.houses else {
            let scenes = ferret_world::generate::default_scenes(self.generate, self.house_seed)
                .context("generating the default houses")?;
            let scenes = match &self.range {
                Some(r) => scenes
                    .into_iter()
                    .filter(|s| r.contains(s.house.index))
                    .collect(),
                None => scenes,
            };
            return Ok(LoadedHouses {
                scenes,
                skipped: vec![],
                source: format!(
                    "{} generated houses (seed {})",
                    self.generate, self.house_seed
                ),
            });
        };
        if ferret_world::scene::is_scene_file(path) {
            let scene = ferret_world::SceneFile::load(path)?;
            return Ok(LoadedHouses {
                scenes: vec![scene],
                skipped: vec![],
                source: path.display().to_string(),
            });
        }
        let db = match &self.asset_db {
            Some(p) => Some(AssetDatabase::load(p)?),
            None => None,
        };
        let opts = LoadOptions {
            asset_db: db.as_ref(),
            range: self.range.unwrap_or_default(),
            skip_invalid,
            containers,
        };
        let report = load_scenes(path, &opts)?;
        Ok(LoadedHouses {
            scenes: report.scenes,
            skipped: report.skipped.iter().map(ToString::to_string).collect(),
            source: match &self.range {
                Some(r) => format!("{} [{r}]", path.display()),
                None => path.display().to_string(),
            },
        })
    }
}

/// Refuses a list option naming the same value twice (`--strategies a,b,a`): its results would
/// be counted twice or overwrite each other.
pub fn check_distinct(option: &str, values: &[String]) -> Result<()> {
    let mut seen = std::collections::HashSet::new();
    for v in values {
        if !seen.insert(v.as_str()) {
            bail!("{option}: `{v}` is given twice");
        }
    }
    Ok(())
}

/// Occupancy-grid options.
#[derive(clap::Args, Clone, Debug)]
pub struct GridArgs {
    /// Grid cell size, metres (the paper's 0.05).
    #[arg(long, value_name = "M", default_value_t = GridParams::default().resolution)]
    pub resolution: f64,
    /// Robot radius by which walls and furniture are inflated, metres.
    #[arg(long, value_name = "M", default_value_t = GridParams::default().robot_radius)]
    pub robot_radius: f64,
    /// Thickness given to walls, metres.
    #[arg(long, value_name = "M", default_value_t = GridParams::default().wall_thickness)]
    pub wall_thickness: f64,
}

impl GridArgs {
    /// Refuses unusable grid options, naming the option, before any house is loaded or any
    /// output touched.
    pub fn validate(&self) -> Result<()> {
        let min = GridParams::MIN_RESOLUTION;
        if !(self.resolution.is_finite() && self.resolution >= min) {
            bail!(
                "--resolution {}: the cell size must be a finite number ≥ {min} m",
                self.resolution
            );
        }
        // Zero is meaningful for both: a point robot, walls as thin as the cells they cross.
        for (name, value) in [
            ("--robot-radius", self.robot_radius),
            ("--wall-thickness", self.wall_thickness),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                bail!("{name} {value}: must be a finite number ≥ 0 m");
            }
        }
        Ok(())
    }

    /// The grid parameters with access points chosen by `access`.
    pub fn params_for(&self, access: AccessRule) -> GridParams {
        GridParams {
            access,
            ..self.params()
        }
    }

    /// The grid parameters.
    pub fn params(&self) -> GridParams {
        GridParams {
            resolution: self.resolution,
            robot_radius: self.robot_radius,
            wall_thickness: self.wall_thickness,
            ..GridParams::default()
        }
    }
}

/// A progress bar in ferret's style (hidden when stderr is not a terminal).
pub fn progress(len: usize, what: &str) -> ProgressBar {
    let bar = ProgressBar::new(len as u64);
    bar.set_style(
        ProgressStyle::with_template(
            "{spinner} {msg:<14} [{bar:40}] {pos}/{len} ({elapsed}, eta {eta})",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .progress_chars("=> "),
    );
    bar.set_message(what.to_string());
    bar.enable_steady_tick(Duration::from_millis(200));
    bar
}

/// A house with its map, or why it has none.
pub type Mapped = std::result::Result<(OccupancyGrid, Distances), WorldError>;

/// Builds grid and distances for every scene, in parallel, with a progress bar.
pub fn build_maps(scenes: &[Scene], params: &GridParams) -> Vec<Mapped> {
    let bar = progress(scenes.len(), "maps");
    let maps = scenes
        .par_iter()
        .progress_with(bar.clone())
        .map(|s| ferret_world::distance::build(&s.house, params))
        .collect();
    bar.finish_and_clear();
    maps
}

/// The protocol switches shared by `eval`, `select` and `deploy` (see docs/protocol.md).
#[derive(clap::Args, Clone, Debug, Default)]
pub struct ProtocolArgs {
    /// Every protocol setting at once: `ferret` (the default) or `paper` (the paper's reference
    /// code). The single switches below override its parts.
    #[arg(long, value_name = "ferret|paper")]
    pub protocol: Option<ferret_plan::ProtocolName>,
    /// What the robot knows before a trial: nothing searched (`empty`), or the reference code's
    /// partly searched house (`paper`).
    #[arg(long, value_name = "empty|paper")]
    pub initial_belief: Option<ferret_plan::InitialBelief>,
    /// Which top-level objects of a ProcTHOR file are containers: the asset database's
    /// receptacles (`receptacles`), or every top-level object but 15 ignored types, holding its
    /// direct children that are not furniture themselves (`furniture`, the reference code's).
    #[arg(long, value_name = "receptacles|furniture")]
    pub containers: Option<ferret_plan::ContainerSet>,
    /// Where the robot stands to search a container: the reachable cell of its room nearest its
    /// footprint (`footprint`), or the reachable cell nearest its centre (`nearest-free`, the
    /// reference code's).
    #[arg(long, value_name = "footprint|nearest-free")]
    pub access: Option<ferret_plan::AccessRule>,
    /// The reported cost of a trial: its plain path length (`plain`), or the reference code's
    /// soft cost, dearer near obstacles (`soft`). Planners always decide on plain distances.
    #[arg(long, value_name = "plain|soft")]
    pub travel_cost: Option<ferret_plan::TravelCost>,
    /// The trials' random draws: ferret's own (`ferret`), or CPython's `random` seeded with the
    /// house's index, as the reference code draws targets and initial beliefs (`python`).
    #[arg(long, value_name = "ferret|python")]
    pub rng: Option<ferret_plan::TrialRng>,
    /// UCB's score of a strategy never deployed: −∞, so each is tried once first (`first`), or
    /// 0 as the reference code scores it (`zero`).
    #[arg(long, value_name = "first|zero")]
    pub untried: Option<ferret_plan::UntriedScore>,
    /// Which object types may be targets: every contained type (`pickupable`), or those that
    /// are never a top-level object of the house (`paper`).
    #[arg(long, value_name = "pickupable|paper")]
    pub targets: Option<ferret_plan::TargetSet>,
    /// What a replay assumes: the target only where it was found (`pessimistic`), or wherever
    /// it truly is (`counterfactual`).
    #[arg(long, value_name = "pessimistic|counterfactual")]
    pub replay: Option<ferret_plan::ReplayMode>,
    /// How deployments draw houses: `distinct`, or with `replacement`.
    #[arg(long, value_name = "distinct|replacement")]
    pub draw: Option<ferret_plan::DrawMode>,
}

impl ProtocolArgs {
    /// The settings: `--protocol` (else `base`) with the single switches applied.
    pub fn resolve(&self, base: ferret_plan::Protocol) -> Result<ferret_plan::Protocol> {
        let mut p = self.protocol.map_or(base, ferret_plan::Protocol::named);
        if let Some(v) = self.initial_belief {
            p.initial_belief = v;
        }
        if let Some(v) = self.containers {
            p.containers = v;
        }
        if let Some(v) = self.targets {
            p.targets = v;
        }
        if let Some(v) = self.replay {
            p.replay = v;
        }
        if let Some(v) = self.draw {
            p.draw = v;
        }
        if let Some(v) = self.access {
            p.access = v;
        }
        if let Some(v) = self.travel_cost {
            p.travel_cost = v;
        }
        if let Some(v) = self.rng {
            p.rng = v;
        }
        if let Some(v) = self.untried {
            p.untried = v;
        }
        Ok(p)
    }
}
