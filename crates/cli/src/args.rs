//! The command-line arguments several commands share: houses, grid, planner, LLM and protocol
//! options. Each turns into the experiment layer's settings; validation lives there.

use std::path::PathBuf;

use anyhow::{Result, bail};
use ferret_lab::{HouseSource, LlmSettings, LoadedHouses, PlanningSettings};
use ferret_world::procthor::HouseRange;
use ferret_world::{AccessRule, ContainerSet, GridParams};

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
    /// Houses to generate when --houses is not given (at most 10000).
    #[arg(long, value_name = "N", default_value_t = 100, value_parser = house_count)]
    pub generate: usize,
    /// Seed of the generated houses.
    #[arg(long, value_name = "S", default_value_t = 0)]
    pub house_seed: u64,
}

/// A count of houses to generate, at most [`ferret_world::generate::MAX_HOUSES`].
pub fn house_count(s: &str) -> std::result::Result<usize, String> {
    let max = ferret_world::generate::MAX_HOUSES;
    let n: usize = s
        .parse()
        .map_err(|_| format!("{s:?} is not a count of houses (0 to {max})"))?;
    if n > max {
        return Err(format!(
            "{n} is more than the {max} houses generated at once"
        ));
    }
    Ok(n)
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
    /// (generated houses and scene files name their containers themselves), each house kept
    /// with only what training counts (see [`ferret_lab::HouseSource::load_types_only`]).
    pub fn load_types_only(&self, containers: ContainerSet) -> Result<LoadedHouses> {
        Ok(self.source().load_types_only(containers)?)
    }

    /// Like [`load`](Self::load), only the houses of `shard` (see
    /// [`HouseSource::load_shard`]).
    pub fn load_shard(
        &self,
        containers: ContainerSet,
        shard: Option<ferret_lab::Shard>,
    ) -> Result<LoadedHouses> {
        Ok(HouseSource {
            skip_invalid: self.skip_invalid,
            ..self.source()
        }
        .load_shard(containers, shard)?)
    }

    fn load_inner(&self, skip_invalid: bool, containers: ContainerSet) -> Result<LoadedHouses> {
        Ok(HouseSource {
            skip_invalid,
            ..self.source()
        }
        .load_for(containers)?)
    }

    /// Where these arguments say the houses come from.
    pub fn source(&self) -> HouseSource {
        HouseSource {
            houses: self.houses.clone(),
            range: self.range,
            asset_db: self.asset_db.clone(),
            skip_invalid: self.skip_invalid,
            generate: self.generate,
            house_seed: self.house_seed,
        }
    }
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

/// Planner and prior options shared by `eval`, `select` and `deploy`.
#[derive(clap::Args, Clone, Debug)]
pub struct PlanningArgs {
    /// A prior from `ferret prior train`. Without it, model/prior uses a prior trained on 500
    /// generated houses (seed 1000003, never the evaluation houses).
    #[arg(long, value_name = "FILE")]
    pub prior: Option<PathBuf>,
    /// Containers the planner considers per decision in model strategies without a limit suffix:
    /// the 2 nearest plus the most likely, as in the paper (K = 8).
    #[arg(long, value_name = "K", default_value_t = 8)]
    pub max_containers: usize,
    /// Largest exact problem for `/exact` strategies, at most 22 (2^n·n memory: 16 → 8 MB,
    /// 20 → 160 MB).
    #[arg(long, value_name = "N", default_value_t = 16)]
    pub exact_max: usize,
    /// Search cost R per container, metres (0 in the paper).
    #[arg(long, value_name = "M", default_value_t = 0.0)]
    pub search_cost: f64,
    /// Target types the prior must not have seen, to measure what a source knows where the
    /// prior has no evidence. Types fall into N folds by a fixed hash of their name. `K/N`: the
    /// prior forgets fold K's types and only trials with a target of that fold run; `N`: every
    /// trial runs, each planned over a prior that forgot its target's fold. Recorded in
    /// run.json.
    #[arg(long, value_name = "K/N|N")]
    pub holdout_types: Option<ferret_plan::HoldOut>,
    /// Word embeddings (a folder; `scripts/embeddings.sh install` prints one) for the names a
    /// learned prior's file lacks: furniture, rooms or objects its training houses never had.
    /// Opened only when such a name comes up.
    #[arg(long, value_name = "DIR", env = "FERRET_EMBEDDINGS")]
    pub embeddings: Option<PathBuf>,
}

impl PlanningArgs {
    /// The settings, without the command line.
    pub fn settings(&self) -> PlanningSettings {
        PlanningSettings {
            prior: self.prior.clone(),
            max_containers: self.max_containers,
            exact_max: self.exact_max,
            search_cost: self.search_cost,
            holdout: self.holdout_types,
            embeddings: self.embeddings.clone(),
        }
    }

    /// Refuses unusable planner options, naming the option, before any output is touched.
    pub fn validate(&self) -> Result<()> {
        Ok(self.settings().validate()?)
    }
}

/// Where LLM endpoints and cached answers live.
#[derive(clap::Args, Clone, Debug)]
pub struct LlmArgs {
    /// Endpoint configuration (TOML, see ferret.example.toml); `ferret.toml` in the working
    /// directory when present.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// The response cache (SQLite). Every answer is stored before it is used, so an interrupted
    /// run loses nothing and a rerun asks nothing twice.
    #[arg(long, value_name = "FILE", default_value = ferret_llm::DEFAULT_CACHE_PATH)]
    pub llm_cache: PathBuf,
    /// Answer LLM queries from the cache only; a missing answer is an error naming the prompt.
    #[arg(long)]
    pub offline: bool,
    /// When an LLM endpoint fails (after its retries), go on without the strategies that use it
    /// instead of stopping the run. Answers already received stay in the cache either way.
    #[arg(long)]
    pub keep_going: bool,
    /// Exit with an error when an LLM strategy's share of answers that could not be read (after
    /// re-asks) exceeds this fraction, e.g. 0.02. Results are written first.
    #[arg(long, value_name = "SHARE", value_parser = parse_share)]
    pub max_fallback_share: Option<f64>,
    /// Fusion weights from `ferret calibrate --fit-fusion`: makes `fused/<prompt>/<llm>`
    /// available, the prior and the LLM's likelihoods combined as fitted on training houses.
    #[arg(long, value_name = "FILE")]
    pub fusion: Option<PathBuf>,
}

fn parse_share(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|e| format!("`{s}` is not a number: {e}"))?;
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} is not a share between 0 and 1"))
    }
}

impl LlmArgs {
    /// The settings, without the command line.
    pub fn settings(&self) -> LlmSettings {
        LlmSettings {
            config: self.config.clone(),
            llm_cache: self.llm_cache.clone(),
            offline: self.offline,
            keep_going: self.keep_going,
            max_fallback_share: self.max_fallback_share,
            fusion: self.fusion.clone(),
        }
    }
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

/// Household tasks instead of one target per trial.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct TaskArgs {
    /// Household tasks instead of one target per trial: `all:N` asks for N distinct object
    /// types of each house (drawn from --seed, every one wanted) and `any:N` for any one of N,
    /// N from 1 to 4. Opening a container reveals all of it: a target seen while looking for
    /// another is found. Add `sequential/<spec>` (e.g. sequential/model/prior) to --strategies
    /// for one search after another.
    #[arg(long, value_name = "all:N|any:N", conflicts_with = "tasks")]
    pub task: Option<ferret_plan::TaskShape>,
    /// Where every task of --task brings what it found, its cost counting the way there:
    /// `start` ("bring it to me"), `room:<RoomType>` (the centre of the house's first room of
    /// that type, e.g. room:Kitchen) or `container:<ObjectType>` (the first of that type, e.g.
    /// container:Sofa).
    #[arg(long, value_name = "start|room:TYPE|container:TYPE", requires = "task")]
    pub deliver: Option<ferret_lab::Deliver>,
    /// Tasks given one per trial in a CSV file with the columns house (index in the house
    /// file), targets (1 to 4 types separated by spaces or +), goal (all or any) and
    /// destination (start, container:<id>, room:<id>, a point <x>,<z> in metres, or empty).
    /// Every line is checked before anything runs.
    #[arg(long, value_name = "FILE", value_parser = parse_task_file)]
    pub tasks: Option<TaskFile>,
}

/// A team of robots on every trial.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct TeamArgs {
    /// Robots working together on every trial, 1 to 4: a container one opens is known to all,
    /// and the cost is the makespan (metres until the goal held; robots drive at equal speed).
    /// A plain spec coordinates its robots (each plans knowing where the others are heading);
    /// independent/<spec> runs the single-robot plan on each, blind to the others, and
    /// split/<spec> divides the rooms among them. trials.csv gains robots, total_travel_m and
    /// searched_by.
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u8).range(1..=4))]
    pub robots: Option<u8>,
    /// Where the robots start: `together` (all at the house's start) or `spread` (the first at
    /// the start, the others on reachable floor drawn from --seed).
    #[arg(
        long,
        value_name = "together|spread",
        requires = "robots",
        default_value = "together"
    )]
    pub starts: ferret_plan::TeamStarts,
}

impl TeamArgs {
    /// The team these options ask for, if any.
    pub fn team(&self) -> Option<ferret_plan::TeamSettings> {
        self.robots.map(|robots| ferret_plan::TeamSettings {
            robots: usize::from(robots),
            starts: self.starts,
        })
    }
}

/// The lines of a tasks file.
#[derive(Clone, Debug)]
pub struct TaskFile(Vec<ferret_lab::TaskLine>);

/// Reads a tasks file while the arguments are parsed, so that a bad line is a usage error.
fn parse_task_file(path: &str) -> Result<TaskFile, String> {
    ferret_lab::read_task_file(std::path::Path::new(path))
        .map(TaskFile)
        .map_err(|e| ferret_world::error_chain(&e))
}

impl TaskArgs {
    /// The tasks these options ask for, if any.
    pub fn tasks(&self) -> Option<ferret_lab::Tasks> {
        match (&self.task, &self.tasks) {
            (Some(shape), _) => Some(ferret_lab::Tasks::Drawn {
                shape: *shape,
                deliver: self.deliver.clone(),
            }),
            (None, Some(file)) => Some(ferret_lab::Tasks::Listed {
                lines: file.0.clone(),
            }),
            (None, None) => None,
        }
    }
}
