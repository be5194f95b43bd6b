//! `ferret bench planner`: decision latency of the exact planner on random instances.
//! `ferret bench serve`: `ferret serve` under load, many robots at once over real HTTP.

use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result};
use ferret_plan::{TourProblem, solve_exact};
use serde::Serialize;

/// Benchmarks.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Median decision latency of the exact planner (one full Held–Karp solve) for several numbers
    /// of containers, on random instances in a 20 m × 20 m house.
    Planner(PlannerArgs),
    /// Load on `ferret serve`: many concurrent deployments (simulated robots) over HTTP on
    /// 127.0.0.1, each running its trials to the end; requests per second, latency of the
    /// "next container" replies, errors. By default one server in this process on a real
    /// SQLite file (WAL, synchronous FULL) in a temporary directory; with --replicas or a
    /// PostgreSQL --db, that many `ferret serve` processes on one database, each robot on one
    /// replica and moving to the next when its replica fails. Every write carries a request
    /// id and is retried until acknowledged; at the end every trial is read back and each
    /// acknowledged observation must be stored exactly once.
    Serve(Box<ServeArgs>),
}

/// Arguments of `bench serve`.
#[derive(clap::Args, Debug)]
pub struct ServeArgs {
    #[command(flatten)]
    houses: crate::common::HouseArgs,
    #[command(flatten)]
    grid: crate::common::GridArgs,
    #[command(flatten)]
    planning: super::eval::PlanningArgs,
    #[command(flatten)]
    llm: super::llm_setup::LlmArgs,
    /// Candidate strategies of every deployment.
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "optimistic+greedy,model/uniform,model/uniform/exact"
    )]
    strategies: Vec<String>,
    /// Concurrent deployments (robots).
    #[arg(long, default_value_t = 50)]
    deployments: usize,
    /// Trials per deployment; deployment d runs houses d·trials .. in file order (wrapping).
    #[arg(long, default_value_t = 20)]
    trials: usize,
    /// Seed of the targets.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// `ferret serve` processes sharing --db (needs --houses: each replica loads the file).
    #[arg(long, value_name = "N", default_value_t = 1)]
    replicas: usize,
    /// The database: a PostgreSQL URL (`postgres://user@host:port/database`, which should be
    /// empty or hold only earlier benchmarks) or an SQLite file; default a new SQLite file in a
    /// temporary directory.
    #[arg(long, value_name = "URL|FILE")]
    db: Option<String>,
    /// Kill (SIGKILL) the first replica this many seconds into the run; its robots carry on
    /// against the others.
    #[arg(long, value_name = "SECS")]
    kill_replica_after: Option<f64>,
    /// The robots (one per `--deployments`) share one deployment, as a fleet does: its trials
    /// overlap and each start's choice depends on the others'. Starts refused (409) are counted.
    #[arg(long)]
    shared_deployment: bool,
    /// Every trial starts from a pose of its own (a reachable free cell of its scene and a
    /// heading, drawn with --seed) and searches for a target drawn for it, so no two trials
    /// are alike and no kept replay is found again: what robots that set out where their last
    /// trial left them see. By default every trial starts at its scene's start, and each scene
    /// has one target.
    #[arg(long)]
    fresh_trials: bool,
    /// Run the servers as processes of this `ferret` binary (another version's, to compare
    /// servers under the same robots in one run) instead of this one.
    #[arg(long, value_name = "PATH")]
    serve_bin: Option<std::path::PathBuf>,
    /// Replay costs each server keeps per scene and pose (`ferret serve --kept-replays`); 0
    /// replays every candidate at every trial end.
    #[arg(long, value_name = "N", default_value_t = ferret_serve::ServiceOptions::default().kept_replays)]
    kept_replays: usize,
    /// Plans' first steps each server keeps per scene (`ferret serve --kept-plans`; 0 solves
    /// every plan); by default the server's own default (and the option is not passed to
    /// servers of --serve-bin, which may predate it).
    #[arg(long, value_name = "N")]
    kept_plans: Option<usize>,
    /// PostgreSQL connections per replica.
    #[arg(long, value_name = "N", default_value_t = ferret_serve::PostgresOptions::default().pool_size)]
    db_pool: usize,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
}

/// Arguments of `bench planner`.
#[derive(clap::Args, Debug)]
pub struct PlannerArgs {
    /// Container counts to measure.
    #[arg(long, value_delimiter = ',', default_value = "4,8,12,16,20")]
    sizes: Vec<usize>,
    /// Random instances per size (fewer are used for large sizes so the run stays short).
    #[arg(long, default_value_t = 200)]
    instances: usize,
    /// Print JSON instead of a table.
    #[arg(long)]
    json: bool,
    /// Seed of the instances.
    #[arg(long, default_value_t = 0)]
    seed: u64,
}

#[derive(Serialize)]
struct Line {
    containers: usize,
    instances: usize,
    median_us: f64,
    p90_us: f64,
    table_mib: f64,
}

/// Runs a `bench` subcommand.
pub fn run(cmd: Command) -> Result<ExitCode> {
    match cmd {
        Command::Planner(args) => planner(args),
        Command::Serve(args) => serve(*args),
    }
}

#[derive(Serialize)]
struct KindLine {
    reply: &'static str,
    count: usize,
    p50_ms: f64,
    p99_ms: f64,
    max_ms: f64,
}

/// What a reply answered, for latencies by kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Reply {
    Start,
    Step,
    End,
}

#[derive(Serialize)]
struct ServeLine {
    replicas: usize,
    /// Whether every robot ran its trials in one shared deployment.
    shared_deployment: bool,
    /// Whether every trial started from a pose of its own with a target of its own.
    fresh_trials: bool,
    database: String,
    /// Replay costs each server keeps per scene and pose.
    kept_replays: usize,
    /// Plans' first steps each server keeps per scene, when given (else its default).
    kept_plans: Option<usize>,
    deployments: usize,
    trials: usize,
    requests: usize,
    /// Attempts beyond the first of a request (a replica down, a request id in flight).
    retries: usize,
    /// Trial starts answered 409 (then retried).
    refused_starts: usize,
    errors: usize,
    seconds: f64,
    requests_per_second: f64,
    next_p50_ms: f64,
    next_p99_ms: f64,
    next_max_ms: f64,
    /// The same per kind of reply: a trial's start, an observation that leaves it searching, the
    /// observation that ends it (which replays every candidate).
    by_reply: Vec<KindLine>,
    /// SQLite only: the file and its log.
    database_mib: Option<f64>,
    /// Replica killed, and when.
    killed_after_s: Option<f64>,
    /// Acknowledged observations read back.
    verified_observations: usize,
    /// Acknowledged observations missing from their trial.
    lost_observations: usize,
    /// Stored observations beyond the acknowledged ones (a write counted twice).
    duplicated_observations: usize,
    /// Deployments whose stored trials are not the ones their robot started.
    mismatched_deployments: usize,
    /// Median start of each robot's trials 11–30 and of its last 20, when it ran 60 or more:
    /// whether a start costs more as its deployment's history grows.
    start_early_p50_ms: Option<f64>,
    start_late_p50_ms: Option<f64>,
}

/// Trials a robot runs before its early starts are timed, and how many are timed at each end.
const EARLY_FROM: usize = 10;
const TIMED_STARTS: usize = 20;

/// The most robots `bench serve` runs (one thread each).
const MAX_BENCH_DEPLOYMENTS: usize = 10_000;
/// The most trials in all (each planned up front).
const MAX_BENCH_TRIALS: usize = 1_000_000;
/// The most `ferret serve` processes it starts.
const MAX_BENCH_REPLICAS: usize = 64;

fn serve(args: ServeArgs) -> Result<ExitCode> {
    use std::sync::Arc;

    if args.deployments == 0 || args.trials == 0 || args.replicas == 0 {
        anyhow::bail!("--deployments, --trials and --replicas must be at least 1");
    }
    // Every trial is planned up front and every deployment is a robot thread: bounds that a
    // machine can hold, refused before anything is allocated.
    if args.deployments > MAX_BENCH_DEPLOYMENTS
        || args.replicas > MAX_BENCH_REPLICAS
        || args.deployments.saturating_mul(args.trials) > MAX_BENCH_TRIALS
    {
        anyhow::bail!(
            "--deployments {} × --trials {} on --replicas {}: at most {MAX_BENCH_DEPLOYMENTS} deployments, {MAX_BENCH_TRIALS} trials in all and {MAX_BENCH_REPLICAS} replicas",
            args.deployments,
            args.trials,
            args.replicas
        );
    }
    let in_process = args.replicas == 1
        && args.serve_bin.is_none()
        && args.kill_replica_after.is_none()
        && !args
            .db
            .as_deref()
            .is_some_and(ferret_serve::is_postgres_url);
    if !in_process && args.houses.houses.is_none() {
        anyhow::bail!(
            "--replicas, --kill-replica-after, --serve-bin and a PostgreSQL --db run `ferret serve` processes, which load --houses: give a house file (`ferret generate --out FILE` writes one)"
        );
    }
    if let Some(k) = args.kill_replica_after
        && (args.replicas < 2 || !(k.is_finite() && k >= 0.0))
    {
        anyhow::bail!(
            "--kill-replica-after needs --replicas 2 or more and a number of seconds ≥ 0"
        );
    }
    let loaded = args.houses.load()?;
    if loaded.scenes.is_empty() {
        anyhow::bail!("no houses in {}", loaded.source);
    }
    let dir = tempfile::tempdir()?;
    let db = args.db.clone().unwrap_or_else(|| {
        dir.path()
            .join("bench.sqlite")
            .to_string_lossy()
            .into_owned()
    });
    let plans = work_list(&args, &loaded.scenes)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    // Either one server in this process, or replicas as processes of their own.
    let mut replicas: Vec<std::process::Child> = Vec::new();
    let mut urls = Vec::new();
    let mut server = None;
    if in_process {
        let store = ferret_serve::Store::open(std::path::Path::new(&db))?;
        let candidates = {
            let setup =
                ferret_lab::Strategies::builder(&args.planning.settings(), &args.llm.settings())
                    .for_specs(&args.strategies)
                    .build()?;
            args.strategies
                .iter()
                .map(|s| setup.registry.build(s))
                .collect::<Result<Vec<_>, _>>()?
        };
        let defaults = ferret_serve::ServiceOptions::default();
        let options = ferret_serve::ServiceOptions {
            kept_replays: args.kept_replays,
            kept_plans: args.kept_plans.unwrap_or(defaults.kept_plans),
            ..defaults
        };
        let service =
            ferret_serve::Service::with_options(store, args.grid.params(), candidates, options)
                .map_err(|e| anyhow::anyhow!("{}", e.message))?;
        let bar = crate::common::progress(loaded.scenes.len(), "scenes");
        for scene in loaded.scenes {
            let name = scene.house.name.clone();
            service.add_scene(&name, scene).map_err(|e| {
                // Most scene errors name the house already.
                if e.message.starts_with(&name) {
                    anyhow::anyhow!("{}", e.message)
                } else {
                    anyhow::anyhow!("{name}: {}", e.message)
                }
            })?;
            bar.inc(1);
        }
        bar.finish_and_clear();
        let listener = runtime.block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))?;
        let addr = listener.local_addr()?;
        // The server's own guards and connection loop, as `ferret serve` runs them.
        let options = ferret_serve::HttpOptions {
            listen: Some(addr),
            ..ferret_serve::HttpOptions::default()
        };
        let app = ferret_serve::router(Arc::new(service), &options)
            .map_err(|e| anyhow::anyhow!("{}", e.message))?;
        server = Some(runtime.spawn(ferret_serve::serve(
            listener,
            app,
            ferret_serve::ServeOptions::default(),
            std::future::pending(),
        )));
        urls.push(format!("http://{addr}"));
    } else {
        drop(loaded);
        for i in 0..args.replicas {
            let (child, url) =
                spawn_replica(&args, &db, &dir.path().join(format!("replica-{i}.log")))
                    .with_context(|| format!("starting replica {i}"))?;
            replicas.push(child);
            urls.push(url);
        }
    }
    let total_trials = args.deployments * args.trials;
    let bar = crate::common::progress(total_trials, "trials");
    let kill_at = args.kill_replica_after;
    let outcome = runtime.block_on(async {
        let client = reqwest::Client::builder()
            .timeout(std::time::Duration::from_secs(60))
            .build()?;
        let urls = Arc::new(urls.clone());
        let shared = if args.shared_deployment {
            let mut creator = Robot::new(client.clone(), urls.clone(), usize::MAX);
            let created = creator.post("/deployments", serde_json::json!({})).await;
            Some(
                created
                    .and_then(|d| d["id"].as_i64())
                    .ok_or_else(|| anyhow::anyhow!("the shared deployment was not created"))?,
            )
        } else {
            None
        };
        let started = Instant::now();
        let tasks: Vec<_> = plans
            .into_iter()
            .enumerate()
            .map(|(r, trials)| {
                let (client, urls, bar) = (client.clone(), urls.clone(), bar.clone());
                tokio::spawn(async move {
                    let mut robot = Robot::new(client, urls, r);
                    robot.run(trials, &bar, shared).await;
                    robot
                })
            })
            .collect();
        let mut killed = None;
        if let Some(after) = kill_at {
            tokio::time::sleep(std::time::Duration::from_secs_f64(after)).await;
            if let Some(first) = replicas.first_mut() {
                // `Child::kill` is SIGKILL on Unix: no shutdown, no flush.
                first.kill()?;
                first.wait()?;
                killed = Some(started.elapsed().as_secs_f64());
            }
        }
        let mut robots = Vec::new();
        for t in tasks {
            robots.push(t.await?);
        }
        let seconds = started.elapsed().as_secs_f64();
        // Read every trial back from a replica that is still up.
        let alive = usize::from(killed.is_some());
        let check = Robot::new(client.clone(), Arc::new(urls[alive..].to_vec()), 0);
        let mut verified = Verified::default();
        for robot in &robots {
            check.verify(robot, shared.is_some(), &mut verified).await;
        }
        anyhow::Ok((robots, seconds, killed, verified))
    });
    bar.finish_and_clear();
    if let Some(s) = server {
        s.abort();
    }
    for mut child in replicas {
        // Replicas stop on SIGTERM; kill is enough for a benchmark's throwaway processes.
        let _ = child.kill();
        let _ = child.wait();
    }
    let (robots, seconds, killed, verified) = outcome?;
    let sorted = |kind: Option<Reply>| {
        let mut ms: Vec<f64> = robots
            .iter()
            .flat_map(|r| r.latencies.iter())
            .filter(|(k, _)| kind.is_none_or(|kind| *k == kind))
            .map(|(_, d)| d.as_secs_f64() * 1e3)
            .collect();
        ms.sort_by(f64::total_cmp);
        ms
    };
    let quantile = |ms: &[f64], q: f64| {
        ms.get(((ms.len() as f64 - 1.0) * q).round() as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    let ms = sorted(None);
    let pick = |q: f64| quantile(&ms, q);
    let by_kind: Vec<KindLine> = [
        (Reply::Start, "start"),
        (Reply::Step, "step"),
        (Reply::End, "end"),
    ]
    .into_iter()
    .map(|(kind, name)| {
        let ms = sorted(Some(kind));
        KindLine {
            reply: name,
            count: ms.len(),
            p50_ms: quantile(&ms, 0.5),
            p99_ms: quantile(&ms, 0.99),
            max_ms: ms.last().copied().unwrap_or(f64::NAN),
        }
    })
    .collect();
    let by_history = |late: bool| {
        let mut ms: Vec<f64> = robots
            .iter()
            .flat_map(|r| {
                let n = r.starts.len();
                let from = if late {
                    n.saturating_sub(TIMED_STARTS)
                } else {
                    EARLY_FROM
                };
                r.starts.iter().skip(from).take(TIMED_STARTS)
            })
            .map(|d| d.as_secs_f64() * 1e3)
            .collect();
        ms.sort_by(f64::total_cmp);
        (args.trials >= 3 * TIMED_STARTS).then(|| quantile(&ms, 0.5))
    };
    let requests: usize = robots.iter().map(|r| r.requests).sum();
    let refused_starts: usize = robots.iter().map(|r| r.refused_starts).sum();
    let errors: usize = robots.iter().map(|r| r.errors).sum::<usize>() + verified.errors;
    let size = |p: &std::path::Path| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    let line = ServeLine {
        replicas: args.replicas,
        shared_deployment: args.shared_deployment,
        fresh_trials: args.fresh_trials,
        kept_replays: args.kept_replays,
        kept_plans: args.kept_plans,
        database: if ferret_serve::is_postgres_url(&db) {
            "postgres".into()
        } else {
            "sqlite".into()
        },
        deployments: args.deployments,
        trials: args.trials,
        requests,
        retries: robots.iter().map(|r| r.retries).sum(),
        refused_starts,
        errors,
        seconds,
        requests_per_second: requests as f64 / seconds,
        next_p50_ms: pick(0.5),
        next_p99_ms: pick(0.99),
        next_max_ms: ms.last().copied().unwrap_or(f64::NAN),
        by_reply: by_kind,
        database_mib: (!ferret_serve::is_postgres_url(&db)).then(|| {
            let file = std::path::PathBuf::from(&db);
            let wal = std::path::PathBuf::from(format!("{db}-wal"));
            (size(&file) + size(&wal)) as f64 / (1024.0 * 1024.0)
        }),
        killed_after_s: killed,
        verified_observations: verified.observations,
        lost_observations: verified.lost,
        duplicated_observations: verified.duplicated,
        mismatched_deployments: verified.mismatched,
        start_early_p50_ms: by_history(false),
        start_late_p50_ms: by_history(true),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&line)?);
    } else {
        println!(
            "{} replica(s) on {} keeping {} replays per scene, {} {} × {} trials{}: {} requests in {:.1} s = {:.0} requests/s; next-container reply p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms; {} retries ({} refused starts), {} errors",
            line.replicas,
            line.database,
            line.kept_replays,
            line.deployments,
            if line.shared_deployment {
                "robots sharing one deployment"
            } else {
                "deployments"
            },
            line.trials,
            if line.fresh_trials {
                " (each from a pose of its own)"
            } else {
                ""
            },
            line.requests,
            line.seconds,
            line.requests_per_second,
            line.next_p50_ms,
            line.next_p99_ms,
            line.next_max_ms,
            line.retries,
            line.refused_starts,
            line.errors,
        );
        for k in &line.by_reply {
            println!(
                "  {:<5} {:>6} replies: p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms",
                k.reply, k.count, k.p50_ms, k.p99_ms, k.max_ms
            );
        }
        if let (Some(early), Some(late)) = (line.start_early_p50_ms, line.start_late_p50_ms) {
            println!(
                "  starts as the history grows: p50 {early:.1} ms for each robot's trials {}–{}, {late:.1} ms for its last {TIMED_STARTS}",
                EARLY_FROM + 1,
                EARLY_FROM + TIMED_STARTS
            );
        }
        if let Some(k) = line.killed_after_s {
            println!("replica 0 killed (SIGKILL) after {k:.1} s");
        }
        println!(
            "read back: {} acknowledged observations, {} lost, {} duplicated; {} deployments with other trials than their robot started{}",
            line.verified_observations,
            line.lost_observations,
            line.duplicated_observations,
            line.mismatched_deployments,
            line.database_mib
                .map(|m| format!("; database {m:.1} MiB"))
                .unwrap_or_default()
        );
    }
    let clean =
        errors == 0 && verified.lost == 0 && verified.duplicated == 0 && verified.mismatched == 0;
    Ok(if clean {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// Starts `ferret serve` on `db` with the benchmark's houses and strategies, on a free port of
/// 127.0.0.1; returns the process and its URL once it listens.
fn spawn_replica(
    args: &ServeArgs,
    db: &str,
    log: &std::path::Path,
) -> Result<(std::process::Child, String)> {
    use std::io::BufRead;
    let exe = match &args.serve_bin {
        Some(bin) => bin.clone(),
        None => std::env::current_exe().context("finding the ferret executable")?,
    };
    let mut cmd = std::process::Command::new(exe);
    cmd.arg("serve");
    if let Some(h) = &args.houses.houses {
        cmd.arg("--scene").arg(h);
    }
    if let Some(r) = &args.houses.range {
        cmd.arg("--range").arg(r.to_string());
    }
    if let Some(a) = &args.houses.asset_db {
        cmd.arg("--asset-db").arg(a);
    }
    if let Some(p) = &args.planning.prior {
        cmd.arg("--prior").arg(p);
    }
    if let Some(c) = &args.llm.config {
        cmd.arg("--config").arg(c);
    }
    cmd.args([
        "--resolution",
        &args.grid.resolution.to_string(),
        "--robot-radius",
        &args.grid.robot_radius.to_string(),
        "--wall-thickness",
        &args.grid.wall_thickness.to_string(),
        "--max-containers",
        &args.planning.max_containers.to_string(),
        "--exact-max",
        &args.planning.exact_max.to_string(),
        "--strategies",
        &args.strategies.join(","),
        "--db",
        db,
        "--db-pool",
        &args.db_pool.to_string(),
        "--kept-replays",
        &args.kept_replays.to_string(),
        "--listen",
        "127.0.0.1:0",
    ]);
    if let Some(n) = args.kept_plans {
        cmd.args(["--kept-plans", &n.to_string()]);
    }
    cmd.stdout(std::process::Stdio::piped())
        .stderr(std::fs::File::create(log)?);
    let mut child = cmd.spawn().context("spawning ferret serve")?;
    let stdout = child.stdout.take().context("the replica's output")?;
    let mut lines = std::io::BufReader::new(stdout).lines();
    for line in lines.by_ref() {
        let line = line?;
        if let Some(rest) = line.split("listening on ").nth(1)
            && let Some(url) = rest.split_whitespace().next()
        {
            // Keep reading its output in the background so it never blocks on a full pipe.
            std::thread::spawn(move || lines.for_each(drop));
            return Ok((child, url.to_string()));
        }
    }
    let _ = child.kill();
    let _ = child.wait();
    anyhow::bail!(
        "ferret serve exited before listening: {}",
        std::fs::read_to_string(log).unwrap_or_default().trim()
    )
}

/// A trial a robot runs: scene, target, start pose (`None`: the scene's start), and what
/// each container holds, to answer its searches.
type RobotTrial = (
    String,
    String,
    Option<[f64; 3]>,
    std::collections::HashMap<String, Vec<String>>,
);

/// The trials of each robot: robot d runs houses d·trials .. in file order (wrapping), with the
/// target drawn for its house with --seed, from the house's start; or, with --fresh-trials,
/// from a pose and with a target drawn for the trial itself, none twice.
fn work_list(args: &ServeArgs, scenes: &[ferret_world::Scene]) -> Result<Vec<Vec<RobotTrial>>> {
    use rand::{Rng, SeedableRng};

    // The reachable free cells of each scene, built when a fresh trial first needs them.
    let mut reachable: Vec<Option<Vec<ferret_world::Point>>> = vec![None; scenes.len()];
    let mut drawn = std::collections::HashSet::new();
    let mut plans = Vec::with_capacity(args.deployments);
    for d in 0..args.deployments {
        let mut trials = Vec::with_capacity(args.trials);
        for k in 0..args.trials {
            let n = d * args.trials + k;
            let i = n % scenes.len();
            let scene = &scenes[i];
            let (target, pose) = if args.fresh_trials {
                let cells = match &mut reachable[i] {
                    Some(cells) => cells,
                    slot => {
                        let grid =
                            ferret_world::OccupancyGrid::build(&scene.house, &args.grid.params())
                                .with_context(|| format!("house {}", scene.house.name))?;
                        let cells = grid
                            .cells()
                            .filter(|(c, _)| grid.is_reachable(*c))
                            .map(|(c, _)| grid.center(c))
                            .collect();
                        slot.insert(cells)
                    }
                };
                if cells.is_empty() {
                    anyhow::bail!("house {}: no reachable free cell", scene.house.name);
                }
                // Drawn again (a new seed) until the trial is one not drawn before.
                let mut attempt = 0u64;
                loop {
                    let seed = args
                        .seed
                        .wrapping_add((n as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15))
                        .wrapping_add(attempt.wrapping_mul(0xbf58_476d_1ce4_e5b9));
                    let target =
                        ferret_plan::draw_trial(&scene.house, &scene.truth, seed, 0.0)?.target;
                    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
                    let at = cells[rng.random_range(0..cells.len())];
                    let yaw = rng.random_range(-180.0..180.0_f64).round();
                    let key = (i, at.x.to_bits(), at.z.to_bits(), target.to_string());
                    if drawn.insert(key) || attempt >= 1_000 {
                        break (target, Some([at.x, at.z, yaw]));
                    }
                    attempt += 1;
                }
            } else {
                let target =
                    ferret_plan::draw_trial(&scene.house, &scene.truth, args.seed, 0.0)?.target;
                (target, None)
            };
            let contents = scene
                .house
                .containers
                .iter()
                .enumerate()
                .map(|(c, container)| {
                    let held = scene
                        .truth
                        .contents(c)
                        .iter()
                        .map(|o| o.object_type.to_string())
                        .collect();
                    (container.id.clone(), held)
                })
                .collect();
            trials.push((scene.house.name.clone(), target.to_string(), pose, contents));
        }
        plans.push(trials);
    }
    Ok(plans)
}

/// What was read back after the run.
#[derive(Default)]
struct Verified {
    observations: usize,
    lost: usize,
    duplicated: usize,
    mismatched: usize,
    errors: usize,
}

/// One simulated robot: a deployment and its trials, run to the end against its replica (and
/// the next one when a request to it fails).
struct Robot {
    client: reqwest::Client,
    urls: std::sync::Arc<Vec<String>>,
    /// The replica it talks to now.
    at: usize,
    id: usize,
    /// Writes so far, for request ids.
    writes: usize,
    latencies: Vec<(Reply, std::time::Duration)>,
    /// Each trial's start, in order.
    starts: Vec<std::time::Duration>,
    requests: usize,
    retries: usize,
    /// Starts answered 409.
    refused_starts: usize,
    errors: usize,
    deployment: Option<i64>,
    /// Per trial started: its id and the containers whose observation was acknowledged.
    acked: Vec<(i64, Vec<String>)>,
}

/// What makes this run's request ids its own: a database may hold earlier runs' replies.
fn run_tag() -> &'static str {
    static TAG: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    TAG.get_or_init(|| {
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos());
        format!("bench-{}-{nanos:x}", std::process::id())
    })
}

/// Attempts of one request before the robot gives up on it (about a minute with the pauses).
const ATTEMPTS: u32 = 60;

impl Robot {
    fn new(client: reqwest::Client, urls: std::sync::Arc<Vec<String>>, id: usize) -> Self {
        let at = id % urls.len().max(1);
        Self {
            client,
            urls,
            at,
            id,
            writes: 0,
            latencies: Vec::new(),
            starts: Vec::new(),
            requests: 0,
            retries: 0,
            refused_starts: 0,
            errors: 0,
            deployment: None,
            acked: Vec::new(),
        }
    }

    /// POSTs `body` with a request id of its own until a replica acknowledges it; `None` when
    /// refused (4xx other than 409) or out of attempts.
    async fn post(&mut self, path: &str, mut body: serde_json::Value) -> Option<serde_json::Value> {
        self.writes += 1;
        body["request_id"] = format!("{}-robot-{}-{}", run_tag(), self.id, self.writes).into();
        self.requests += 1;
        for attempt in 0..ATTEMPTS {
            if attempt > 0 {
                self.retries += 1;
                // Another replica, after a pause that grows to half a second.
                self.at = (self.at + 1) % self.urls.len();
                tokio::time::sleep(std::time::Duration::from_millis(
                    (20 * u64::from(attempt)).min(500),
                ))
                .await;
            }
            let t = Instant::now();
            let sent = self
                .client
                .post(format!("{}{path}", self.urls[self.at]))
                .json(&body)
                .send()
                .await;
            let Ok(reply) = sent else { continue };
            let status = reply.status();
            let Ok(value) = reply.json::<serde_json::Value>().await else {
                continue;
            };
            if status.is_success() {
                let kind = if value["status"] == "searching" {
                    if path.ends_with("/trials") {
                        Reply::Start
                    } else {
                        Reply::Step
                    }
                } else {
                    Reply::End
                };
                self.latencies.push((kind, t.elapsed()));
                return Some(value);
            }
            // 409: the same request in flight (on a replica that may have died) or the
            // deployment busy; 5xx: the replica or its database in trouble. Both pass.
            if status.as_u16() == 409 || status.is_server_error() {
                if status.as_u16() == 409 && path.ends_with("/trials") {
                    self.refused_starts += 1;
                }
                continue;
            }
            tracing::warn!(%path, reply = %value, "request refused");
            return None;
        }
        tracing::warn!(%path, "no replica acknowledged the request");
        None
    }

    /// Runs `trials` in a deployment of its own, or in `shared`.
    async fn run(
        &mut self,
        trials: Vec<RobotTrial>,
        bar: &indicatif::ProgressBar,
        shared: Option<i64>,
    ) {
        use serde_json::json;
        let id = match shared {
            Some(id) => id,
            None => {
                let created = self.post("/deployments", json!({})).await;
                // The latencies that count are those of replies carrying a next container.
                self.latencies.clear();
                match created.and_then(|d| d["id"].as_i64()) {
                    Some(id) => id,
                    None => {
                        self.errors += 1;
                        return;
                    }
                }
            }
        };
        self.deployment = Some(id);
        for (scene, target, pose, contents) in trials {
            let mut start = json!({"scene": scene, "target": target});
            if let Some(pose) = pose {
                start["pose"] = json!(pose);
            }
            let Some(mut reply) = self.post(&format!("/deployments/{id}/trials"), start).await
            else {
                self.errors += 1;
                break;
            };
            if let Some((_, took)) = self.latencies.last() {
                self.starts.push(*took);
            }
            let trial = reply["trial"].as_i64().unwrap_or_default();
            self.acked.push((trial, Vec::new()));
            while reply["status"] == "searching" {
                let next = reply["next"]["container"]
                    .as_str()
                    .unwrap_or_default()
                    .to_string();
                let seen = contents.get(&next).cloned().unwrap_or_default();
                let found = seen.contains(&target);
                match self
                    .post(
                        &format!("/trials/{trial}/observations"),
                        json!({"container": next, "found": found, "objects": seen}),
                    )
                    .await
                {
                    Some(r) => {
                        if let Some((_, acked)) = self.acked.last_mut() {
                            acked.push(next);
                        }
                        reply = r;
                    }
                    None => {
                        self.errors += 1;
                        break;
                    }
                }
            }
            bar.inc(1);
        }
    }

    async fn get(&self, path: &str) -> Option<serde_json::Value> {
        for attempt in 0..ATTEMPTS {
            if attempt > 0 {
                tokio::time::sleep(std::time::Duration::from_millis(100)).await;
            }
            let url = &self.urls[attempt as usize % self.urls.len()];
            if let Ok(r) = self.client.get(format!("{url}{path}")).send().await
                && r.status().is_success()
                && let Ok(v) = r.json().await
            {
                return Some(v);
            }
        }
        None
    }

    /// Reads `robot`'s deployment and trials back: its trials exactly, each acknowledged
    /// observation once.
    async fn verify(&self, robot: &Robot, shared: bool, out: &mut Verified) {
        let Some(id) = robot.deployment else { return };
        match self.get(&format!("/deployments/{id}")).await {
            Some(dep) => {
                let stored: Vec<i64> = dep["trials"]
                    .as_array()
                    .map(|t| t.iter().filter_map(|t| t["trial"].as_i64()).collect())
                    .unwrap_or_default();
                let started: Vec<i64> = robot.acked.iter().map(|(t, _)| *t).collect();
                // A shared deployment holds every robot's trials: this robot's must be among
                // them, in its order.
                let mismatched = if shared {
                    let mine: Vec<i64> = stored
                        .iter()
                        .copied()
                        .filter(|t| started.contains(t))
                        .collect();
                    mine != started
                } else {
                    stored != started
                };
                if mismatched {
                    out.mismatched += 1;
                }
            }
            None => out.errors += 1,
        }
        for (trial, acked) in &robot.acked {
            let Some(t) = self.get(&format!("/trials/{trial}")).await else {
                out.errors += 1;
                continue;
            };
            let searched: Vec<String> = t["searched"]
                .as_array()
                .map(|s| {
                    s.iter()
                        .filter_map(|c| c.as_str().map(str::to_string))
                        .collect()
                })
                .unwrap_or_default();
            out.observations += acked.len();
            out.lost += acked.iter().filter(|c| !searched.contains(c)).count();
            out.duplicated += searched
                .len()
                .saturating_sub(searched.iter().filter(|c| acked.contains(c)).count())
                + acked
                    .iter()
                    .map(|c| {
                        searched
                            .iter()
                            .filter(|s| *s == c)
                            .count()
                            .saturating_sub(1)
                    })
                    .sum::<usize>();
        }
    }
}

fn planner(args: PlannerArgs) -> Result<ExitCode> {
    let mut lines = Vec::new();
    for &n in &args.sizes {
        if n > ferret_plan::planner::MAX_EXACT {
            anyhow::bail!(
                "{n} containers exceed the exact planner's limit of {}",
                ferret_plan::planner::MAX_EXACT
            );
        }
        // Keep each size to a few seconds: 2^n·n² work per solve.
        let work = (1u64 << n) * (n * n) as u64;
        let instances = args
            .instances
            .max(1)
            .min((2_000_000_000 / work.max(1)).max(5) as usize);
        let mut us: Vec<f64> = (0..instances)
            .map(|i| {
                let p = TourProblem::random(
                    n,
                    args.seed
                        .wrapping_mul(1_000_003)
                        .wrapping_add((n * 10_000 + i) as u64),
                );
                let t = Instant::now();
                let solved = solve_exact(&p);
                let e = t.elapsed().as_secs_f64() * 1e6;
                std::hint::black_box(solved);
                e
            })
            .collect();
        us.sort_by(f64::total_cmp);
        lines.push(Line {
            containers: n,
            instances,
            median_us: us[us.len() / 2],
            p90_us: us[(us.len() * 9) / 10],
            table_mib: ((1u64 << n) * n as u64 * 8) as f64 / (1024.0 * 1024.0),
        });
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&lines)?);
    } else {
        println!(
            "{:>10} {:>9} {:>14} {:>14} {:>10}",
            "containers", "instances", "median", "p90", "table"
        );
        for l in &lines {
            println!(
                "{:>10} {:>9} {:>14} {:>14} {:>7.1} MiB",
                l.containers,
                l.instances,
                human(l.median_us),
                human(l.p90_us),
                l.table_mib
            );
        }
    }
    Ok(ExitCode::SUCCESS)
}

fn human(us: f64) -> String {
    if us < 1e3 {
        format!("{us:.1} µs")
    } else if us < 1e6 {
        format!("{:.2} ms", us / 1e3)
    } else {
        format!("{:.2} s", us / 1e6)
    }
}
