//! `ferret prompts list` and `ferret prompts show NAME --houses PATH --index I --target TYPE
//! [--container ID]`: the prompt templates, and the exact text a strategy would send.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{Context, Result, anyhow, bail};
use ferret_llm::message::transcript;
use ferret_llm::{
    DirectContext, HouseContext, LlmConfig, PromptKind, PromptLibrary, QueryPlan, Shape,
    question_set,
};
use ferret_world::procthor::{AssetDatabase, HouseRange, LoadOptions, load_scenes};
use ferret_world::{ObjectType, Place, Scene};

use crate::common::GridArgs;

/// Prompt templates.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// List the prompt templates (the seven shipped ones and those of the config's [prompts]),
    /// each with its kind.
    List(ListArgs),
    /// Print the exact messages a prompt sends for a house and target.
    Show(ShowArgs),
}

/// `ferret prompts list`.
#[derive(clap::Args, Debug)]
pub struct ListArgs {
    /// Configuration (TOML) whose [prompts] table names more templates.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Print each template's source too.
    #[arg(long)]
    pub source: bool,
}

/// `ferret prompts show`.
#[derive(clap::Args, Debug)]
pub struct ShowArgs {
    /// The prompt: p-context-a, p-context-b, p-minimal, p-yesno, p-choice, p-batch, p-direct, a
    /// name from the config's [prompts], or a path to a template file.
    pub name: String,
    /// ProcTHOR houses (.json, .jsonl, .jsonl.gz); generated houses when not given.
    #[arg(long, value_name = "PATH")]
    pub houses: Option<PathBuf>,
    /// The house's 0-based index in the file (or among the generated houses, below 10000).
    #[arg(long, value_name = "I", default_value_t = 0)]
    pub index: usize,
    /// The generator's asset-database.json (see `ferret eval --help`).
    #[arg(long, value_name = "PATH")]
    pub asset_db: Option<PathBuf>,
    /// Seed of the generated houses.
    #[arg(long, value_name = "S", default_value_t = 0)]
    pub house_seed: u64,
    /// The target object type, CamelCase as in ProcTHOR (RemoteControl).
    #[arg(long, value_name = "TYPE")]
    pub target: String,
    /// Probability prompts: only the question about this container (its id). P-DIRECT: the
    /// robot stands at this container, which is searched; without it the robot is at its start.
    #[arg(long, value_name = "ID")]
    pub container: Option<String>,
    /// Configuration (TOML) whose [prompts] table names more templates.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    #[command(flatten)]
    pub grid: GridArgs,
}

/// Runs `ferret prompts ...`.
pub fn run(cmd: Command) -> Result<ExitCode> {
    match cmd {
        Command::List(args) => list(&args),
        Command::Show(args) => show(&args),
    }
}

fn library(config: Option<&std::path::Path>) -> Result<PromptLibrary> {
    let config = LlmConfig::load_default(config)?;
    let mut lib = PromptLibrary::new();
    for (name, path) in &config.prompts {
        lib.add_file(name, path)?;
    }
    Ok(lib)
}

fn list(args: &ListArgs) -> Result<ExitCode> {
    let lib = library(args.config.as_deref())?;
    for name in lib.names() {
        let kind = match lib.kind(&name) {
            PromptKind::Percent if name == ferret_llm::P_DIRECT => "direct: the next container",
            PromptKind::Percent => "percent: one question per container type and room",
            PromptKind::YesNo => "yesno: one question per container type and room type",
            PromptKind::Choice { .. } => "choice: one question per house and target, a letter",
            PromptKind::Batch { yesno: false, .. } => {
                "batch: one question per house and target, a percentage per place"
            }
            PromptKind::Batch { yesno: true, .. } => {
                "batch: one question per house and target, Yes or No per place"
            }
        };
        println!("{name:<14} {kind}");
        if args.source {
            println!("{}\n", lib.source(&name).unwrap_or_default());
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn load_scene(args: &ShowArgs) -> Result<Scene> {
    match &args.houses {
        None => {
            ferret_world::generate::default_scenes(args.index.saturating_add(1), args.house_seed)
                .with_context(|| format!("--index {}: generating houses", args.index))?
                .into_iter()
                .nth(args.index)
                .ok_or_else(|| anyhow!("no generated house {}", args.index))
        }
        Some(path) => {
            let db = args
                .asset_db
                .as_deref()
                .map(AssetDatabase::load)
                .transpose()?;
            let opts = LoadOptions {
                shard: None,
                asset_db: db.as_ref(),
                range: HouseRange::single(args.index),
                skip_invalid: false,
                ..Default::default()
            };
            load_scenes(path, &opts)?
                .scenes
                .into_iter()
                .next()
                .ok_or_else(|| anyhow!("{}: no house {}", path.display(), args.index))
        }
    }
}

fn show(args: &ShowArgs) -> Result<ExitCode> {
    let mut lib = library(args.config.as_deref())?;
    let name = lib.resolve(&args.name)?;
    let scene = load_scene(args)?;
    let house = &scene.house;
    let target = ObjectType::new(args.target.clone());
    // A prompt for a type the house does not hold is still worth reading (how a model is asked
    // about things it will not find), so a name the house does not list is only flagged.
    if let Err(e) = ferret_world::check_target(&args.target, &scene.truth.target_types()) {
        eprintln!("warning: {e}; showing the prompt for {target} anyway");
    }
    let container = match &args.container {
        None => None,
        Some(id) => Some(house.container_index(id).ok_or_else(|| {
            anyhow!(
                "{} has no container `{id}` (its containers: {})",
                house.name,
                house
                    .containers
                    .iter()
                    .map(|c| c.id.as_str())
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        })?),
    };
    let kind = lib.kind(&name);
    if kind != PromptKind::Percent {
        // Yes/no questions name room types; listing questions name every place at once.
        let set = question_set(&lib, &name, house, &target)?;
        println!(
            "# {name} on {} (target {target}): {} question(s) for {} container(s)",
            house.name,
            set.questions.len(),
            house.containers.len()
        );
        for (i, (question, asked)) in set.questions.iter().enumerate() {
            let holders: Vec<&str> = (0..house.containers.len())
                .filter(|&c| match (&set.shape, asked) {
                    (Shape::PerQuery { of_container }, _) => of_container[c] == i,
                    (Shape::Listing(l), asked) => asked
                        .places()
                        .is_some_and(|places| places.contains(&l.of_container[c])),
                })
                .map(|c| house.containers[c].id.as_str())
                .collect();
            if container.is_some_and(|c| !holders.contains(&house.containers[c].id.as_str())) {
                continue;
            }
            println!(
                "\n## question {} (containers {})\n{}",
                i + 1,
                holders.join(", "),
                transcript(&question.messages)
            );
        }
        return Ok(ExitCode::SUCCESS);
    }
    let ctx = HouseContext::new(house);
    let plan = QueryPlan::new(house, &target);

    // A probability template renders with the probability context; P-DIRECT-like templates need
    // the direct one (strict rendering tells them apart).
    let probe = plan
        .queries
        .first()
        .map(|q| lib.probability_messages(&name, &ctx, q));
    match probe {
        Some(Ok(_)) => {
            let queries: Vec<usize> = match container {
                Some(c) => vec![plan.of_container[c]],
                None => (0..plan.queries.len()).collect(),
            };
            println!(
                "# {name} on {} (target {target}): {} distinct question(s) for {} container(s)",
                house.name,
                plan.queries.len(),
                house.containers.len()
            );
            for q in queries {
                let holders: Vec<&str> = (0..house.containers.len())
                    .filter(|&c| plan.of_container[c] == q)
                    .map(|c| house.containers[c].id.as_str())
                    .collect();
                let messages = lib.probability_messages(&name, &ctx, &plan.queries[q])?;
                println!(
                    "\n## question {} (containers {})\n{}",
                    q + 1,
                    holders.join(", "),
                    transcript(&messages)
                );
            }
        }
        other => {
            let (_, distances) = ferret_world::distance::build(house, &args.grid.params())
                .with_context(|| format!("building the map of {}", house.name))?;
            let (robot, unsearched): (Place, Vec<usize>) = match container {
                Some(c) => (
                    Place::Container(c),
                    (0..house.containers.len()).filter(|&i| i != c).collect(),
                ),
                None => (Place::Start, (0..house.containers.len()).collect()),
            };
            let (dctx, _) =
                DirectContext::new(house, &ctx, &distances, &target, robot, &unsearched)?;
            match lib.direct_messages(&name, &dctx) {
                Ok(messages) => {
                    println!(
                        "# {name} on {} (target {target})\n{}",
                        house.name,
                        transcript(&messages)
                    );
                }
                Err(direct) => match other {
                    Some(Err(prob)) => bail!("{prob}\n(as a P-DIRECT template: {direct})"),
                    _ => return Err(direct.into()),
                },
            }
        }
    }
    Ok(ExitCode::SUCCESS)
}
