//! The same household tasks in worlds drawn from the likelihood source itself: what a strategy
//! would cost if the prior were exactly right. Every house keeps its rooms and furniture; its
//! task is drawn as `ferret eval --task` draws it; then `--worlds` worlds per house place each
//! target in each container independently with the source's probability, keeping only worlds
//! where every target is somewhere (the trials `eval` runs always have their targets). Each
//! strategy runs in each world, and the table compares them as `eval` does, a (house, world)
//! being a trial.
//!
//! In the prior's own world the exact task planner is the best policy over its candidates,
//! so the gap it opens there on `sequential` is about as much as planning with these
//! likelihoods can give; on the real houses the prior is only roughly right.
//!
//! ```sh
//! cargo run --release -p ferret-lab --example prior_world -- \
//!     --houses $D/multiroom-val150.jsonl.gz --asset-db $D/databases/asset-database.json \
//!     --prior prior.json --task all:3 --deliver start --worlds 20
//! ```

use std::path::PathBuf;
use std::sync::Arc;

use clap::Parser;
use ferret_lab::report::paired_markdown;
use ferret_lab::{
    Deliver, HouseSource, LlmSettings, PlanningSettings, Strategies, Tasks, TrialDraw, TrialRow,
    paired_comparisons, summarize,
};
use ferret_plan::{Protocol, SearchProblem, Strategy, TaskShape, TrialsPerHouse, run_trial};
use ferret_world::{GridParams, GroundTruth, Scene, SmallObject};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;

/// Strategies compared in the prior's own world.
#[derive(Parser, Debug)]
struct Args {
    /// ProcTHOR houses (.jsonl.gz); generated houses without it.
    #[arg(long)]
    houses: Option<PathBuf>,
    /// The generator's asset database.
    #[arg(long)]
    asset_db: Option<PathBuf>,
    /// The prior file (`ferret prior train`); the default prior without it.
    #[arg(long)]
    prior: Option<PathBuf>,
    /// The tasks, as `ferret eval --task`.
    #[arg(long, default_value = "all:3")]
    task: TaskShape,
    /// Where they are brought, as `ferret eval --deliver`.
    #[arg(long)]
    deliver: Option<Deliver>,
    /// Worlds drawn per house.
    #[arg(long, default_value_t = 20)]
    worlds: usize,
    /// Strategies; the first that plans over a likelihood source draws the worlds.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "sequential/model/prior,model/prior,model/uniform"
    )]
    strategies: Vec<String>,
    /// Seed of the tasks and the worlds.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

/// Most draws tried for one world before a house is left out (a target the source almost
/// never places in any of its containers).
const MAX_DRAWS: usize = 10_000;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args = Args::parse();
    let source = HouseSource {
        houses: args.houses.clone(),
        range: None,
        asset_db: args.asset_db.clone(),
        skip_invalid: true,
        generate: 100,
        house_seed: 0,
    };
    let scenes = source.load_for(Default::default())?.scenes;
    let planning = PlanningSettings {
        prior: args.prior.clone(),
        ..PlanningSettings::default()
    };
    let llm = LlmSettings::default();
    let setup = Strategies::builder(&planning, &llm)
        .for_specs(&args.strategies)
        .build()?;
    let strategies: Vec<Arc<dyn Strategy>> = args
        .strategies
        .iter()
        .map(|s| setup.registry.build(s))
        .collect::<Result<_, _>>()?;
    let likelihood = strategies
        .iter()
        .find_map(|s| s.likelihood_source().cloned())
        .ok_or("no strategy plans over a likelihood source")?;
    let tasks = Tasks::Drawn {
        shape: args.task,
        deliver: args.deliver.clone(),
    };
    let draw = TrialDraw {
        seed: args.seed,
        reveal_fraction: 0.0,
        per_house: TrialsPerHouse::One,
        protocol: &Protocol::FERRET,
        holdout: None,
        tasks: Some(&tasks),
        team: None,
    };
    let grid = GridParams::default();
    let per_house: Vec<Result<Vec<TrialRow>, String>> = scenes
        .par_iter()
        .map(|scene| {
            let fail = |e: &dyn std::fmt::Display| format!("{}: {e}", scene.house.name);
            let (_, distances) =
                ferret_world::distance::build(&scene.house, &grid).map_err(|e| fail(&e))?;
            let trial = draw
                .trials(scene)
                .map_err(|e| fail(&e))?
                .into_iter()
                .next()
                .ok_or_else(|| fail(&"no task"))?;
            let p: Vec<Vec<f64>> = trial
                .task
                .targets()
                .iter()
                .map(|t| {
                    likelihood
                        .likelihoods(&scene.house, t)
                        .map(|ps| ps.iter().map(|p| p.get()).collect())
                })
                .collect::<Result<_, _>>()
                .map_err(|e| fail(&e))?;
            let legs = trial
                .task
                .destination()
                .map(|d| d.legs(&scene.house, &distances))
                .transpose()
                .map_err(|e| fail(&e))?;
            let mut problem = SearchProblem::new(&scene.house, &distances, &trial);
            if let Some(l) = legs.as_ref() {
                problem = problem.with_destination(l);
            }
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
                args.seed ^ (scene.house.index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15),
            );
            let mut rows = Vec::new();
            for w in 0..args.worlds {
                let truth = world(scene, &trial.task, &p, &mut rng).map_err(|e| fail(&e))?;
                for s in &strategies {
                    let out = run_trial(s.as_ref(), &problem, &truth).map_err(|e| fail(&e))?;
                    rows.push(TrialRow {
                        house: scene.house.name.clone(),
                        house_index: scene.house.index,
                        target: format!("{}/world{w}", trial.task.targets_label()),
                        strategy: s.name().to_string(),
                        cost_m: out.cost,
                        searches: out.searched.len(),
                        found: out.found.is_some(),
                        found_container: String::new(),
                        searched: String::new(),
                        goal_containers: 0,
                        cost_cells: None,
                        goal: None,
                        destination: None,
                        found_each: None,
                        delivery_m: None,
                        robots: None,
                        total_travel_m: None,
                        searched_by: None,
                    });
                }
            }
            Ok(rows)
        })
        .collect();
    let mut rows = Vec::new();
    for r in per_house {
        match r {
            Ok(r) => rows.extend(r),
            Err(e) => eprintln!("left out: {e}"),
        }
    }
    let houses = rows
        .iter()
        .map(|r| r.house_index)
        .collect::<std::collections::BTreeSet<_>>()
        .len();
    println!(
        "{houses} houses, {} worlds each drawn from `{}`; tasks {}{}\n",
        args.worlds,
        likelihood.name(),
        args.task,
        args.deliver
            .map(|d| format!(", brought to {d}"))
            .unwrap_or_default()
    );
    println!("| strategy | trials | mean cost (m) | 95 % CI |\n|---|---:|---:|---:|");
    for s in summarize(&rows, &args.strategies) {
        println!(
            "| {} | {} | {:.2} | ±{:.2} |",
            s.strategy, s.trials, s.mean_m, s.ci95_m
        );
    }
    println!();
    print!(
        "{}",
        paired_markdown(&paired_comparisons(&rows, &args.strategies, &[], args.seed))
    );
    Ok(())
}

/// A world of `scene`'s furniture: each target of `task` in each container with probability
/// `p[target][container]`, drawn again until every target is somewhere.
fn world(
    scene: &Scene,
    task: &ferret_plan::Task,
    p: &[Vec<f64>],
    rng: &mut impl Rng,
) -> Result<GroundTruth, String> {
    let n = scene.house.containers.len();
    for _ in 0..MAX_DRAWS {
        let mut contents = vec![Vec::new(); n];
        let mut every = true;
        for (t, row) in task.targets().iter().zip(p) {
            let mut somewhere = false;
            for (c, &pc) in row.iter().enumerate() {
                if rng.random::<f64>() < pc {
                    contents[c].push(SmallObject {
                        id: format!("{t}|{c}"),
                        object_type: t.clone(),
                    });
                    somewhere = true;
                }
            }
            every &= somewhere;
        }
        if every {
            return Ok(GroundTruth::new(contents));
        }
    }
    Err(format!(
        "{MAX_DRAWS} draws placed some target of {task} nowhere"
    ))
}
