//! `ferret bench planner`: decision latency of the exact planner on random instances.
//! `ferret bench serve`: `ferret serve` under load, many robots at once over real HTTP.

use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result};
use ferret_plan::{TourProblem, solve_exact};
use ferret_serve::load::{self, EARLY_FROM, FleetSettings, LoadReport, Replica, TIMED_STARTS};
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
    /// Concurrent deployments (robots; with --team, homes).
    #[arg(long, default_value_t = 50)]
    deployments: usize,
    /// Robots per home (1 to 4): above 1, each deployment is a home whose trials a team of
    /// this many robots searches together, each robot asking for its own containers and
    /// talking to a replica of its own; the run then counts containers claimed twice.
    #[arg(long, value_name = "N", default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=4))]
    team: u8,
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
    /// Browser pages watching the fleet, spread over the replicas: each reads the live event
    /// stream (`GET /events`) and fetches what the live page would (the watched trial's
    /// picture on its events, its deployment when a trial ends), to measure what open pages
    /// cost the robots.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pages: usize,
    /// Pages that open the event stream and never read it (clients that stopped reading).
    #[arg(long, value_name = "N", default_value_t = 0)]
    stalled_pages: usize,
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
    /// Targets wanted at once, 1 to 4: with 2 or more, the task planner's table over (searched
    /// set, found set, position) with a destination, as a household task of `all` that many
    /// targets plans it; with 1, the single-target Held–Karp table.
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u8).range(1..=4))]
    targets: u8,
}

#[derive(Serialize)]
struct Line {
    targets: usize,
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

/// A `bench serve` run: what was asked, beside what the fleet measured.
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
    /// Robots searching each trial together.
    team: u8,
    trials: usize,
    #[serde(flatten)]
    measured: LoadReport,
    /// SQLite only: the file and its log.
    database_mib: Option<f64>,
}

/// The most robots `bench serve` runs (one thread each).
const MAX_BENCH_DEPLOYMENTS: usize = 10_000;
/// The most trials in all (each planned up front).
const MAX_BENCH_TRIALS: usize = 1_000_000;
/// The most `ferret serve` processes it starts.
const MAX_BENCH_REPLICAS: usize = 64;
/// The most watching pages (each an open connection).
const MAX_BENCH_PAGES: usize = 1_000;

fn serve(args: ServeArgs) -> Result<ExitCode> {
    check_serve_args(&args)?;
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
    let plans = load::robot_trials(
        &loaded.scenes,
        args.deployments,
        args.trials,
        args.seed,
        args.fresh_trials,
        &args.grid.params(),
    )?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    // Either one server in this process, or replicas as processes of their own.
    let mut replicas = Vec::new();
    let mut server = None;
    let urls = if in_process(&args) {
        let service = bench_service(&args, &db, loaded.scenes)?;
        let (url, task) = load::serve_in_process(&runtime, service)?;
        server = Some(task);
        vec![url]
    } else {
        drop(loaded);
        for i in 0..args.replicas {
            let log = dir.path().join(format!("replica-{i}.log"));
            replicas.push(
                Replica::spawn(replica_command(&args, &db)?, &log)
                    .with_context(|| format!("starting replica {i}"))?,
            );
        }
        replicas.iter().map(|r| r.url().to_string()).collect()
    };
    let bar = crate::common::progress(args.deployments * args.trials, "trials");
    let on_trial = {
        let bar = bar.clone();
        std::sync::Arc::new(move || bar.inc(1))
    };
    let settings = FleetSettings {
        shared_deployment: args.shared_deployment,
        kill_first_after: args
            .kill_replica_after
            .map(std::time::Duration::from_secs_f64),
        pages: args.pages,
        stalled_pages: args.stalled_pages,
        team: usize::from(args.team),
    };
    let run = load::drive(&runtime, urls, plans, settings, &mut replicas, on_trial);
    bar.finish_and_clear();
    if let Some(s) = server {
        s.abort();
    }
    drop(replicas);
    let size = |p: &std::path::Path| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    let postgres = ferret_serve::is_postgres_url(&db);
    let line = ServeLine {
        replicas: args.replicas,
        shared_deployment: args.shared_deployment,
        fresh_trials: args.fresh_trials,
        kept_replays: args.kept_replays,
        kept_plans: args.kept_plans,
        database: if postgres { "postgres" } else { "sqlite" }.into(),
        deployments: args.deployments,
        team: args.team,
        trials: args.trials,
        measured: run?.report(args.trials),
        database_mib: (!postgres).then(|| {
            let file = std::path::PathBuf::from(&db);
            let wal = std::path::PathBuf::from(format!("{db}-wal"));
            (size(&file) + size(&wal)) as f64 / (1024.0 * 1024.0)
        }),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&line)?);
    } else {
        print_serve_line(&line);
    }
    Ok(if line.measured.is_clean() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// Refuses sizes past the bounds and options that do not go together, before anything is
/// allocated.
fn check_serve_args(args: &ServeArgs) -> Result<()> {
    if args.deployments == 0 || args.trials == 0 || args.replicas == 0 {
        anyhow::bail!("--deployments, --trials and --replicas must be at least 1");
    }
    // Every trial is planned up front and every deployment is a robot thread: bounds that a
    // machine can hold.
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
    if args.pages + args.stalled_pages > MAX_BENCH_PAGES {
        anyhow::bail!(
            "--pages {} + --stalled-pages {}: at most {MAX_BENCH_PAGES} in all",
            args.pages,
            args.stalled_pages
        );
    }
    if !in_process(args) && args.houses.houses.is_none() {
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
    Ok(())
}

/// One server in this process, unless the run needs `ferret serve` processes.
fn in_process(args: &ServeArgs) -> bool {
    args.replicas == 1
        && args.serve_bin.is_none()
        && args.kill_replica_after.is_none()
        && !args
            .db
            .as_deref()
            .is_some_and(ferret_serve::is_postgres_url)
}

/// The service of an in-process run: the strategies and options `ferret serve` would have,
/// on the SQLite file `db`, with `scenes` added.
fn bench_service(
    args: &ServeArgs,
    db: &str,
    scenes: Vec<ferret_world::Scene>,
) -> Result<ferret_serve::Service> {
    let store = ferret_serve::Store::open(std::path::Path::new(db))?;
    let setup = ferret_lab::Strategies::builder(&args.planning.settings(), &args.llm.settings())
        .for_specs(&args.strategies)
        .build()?;
    let candidates = args
        .strategies
        .iter()
        .map(|s| setup.registry.build(s))
        .collect::<Result<Vec<_>, _>>()?;
    let defaults = ferret_serve::ServiceOptions::default();
    let options = ferret_serve::ServiceOptions {
        kept_replays: args.kept_replays,
        kept_plans: args.kept_plans.unwrap_or(defaults.kept_plans),
        ..defaults
    };
    let service =
        ferret_serve::Service::with_options(store, args.grid.params(), candidates, options)
            .map_err(|e| anyhow::anyhow!("{}", e.message))?;
    let bar = crate::common::progress(scenes.len(), "scenes");
    for scene in scenes {
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
    Ok(service)
}

/// `ferret serve` on `db` with the benchmark's houses and strategies, on a free port of
/// 127.0.0.1.
fn replica_command(args: &ServeArgs, db: &str) -> Result<std::process::Command> {
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
    Ok(cmd)
}

fn print_serve_line(line: &ServeLine) {
    let m = &line.measured;
    println!(
        "{} replica(s) on {} keeping {} replays per scene, {} {} × {} trials{}: {} requests in {:.1} s = {:.0} requests/s; next-container reply p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms; {} retries ({} refused starts), {} errors",
        line.replicas,
        line.database,
        line.kept_replays,
        line.deployments,
        match (line.shared_deployment, line.team) {
            (true, 1) => "robots sharing one deployment".to_string(),
            (false, 1) => "deployments".to_string(),
            (true, n) => format!("homes of {n} robots sharing one deployment"),
            (false, n) => format!("homes of {n} robots"),
        },
        line.trials,
        if line.fresh_trials {
            " (each from a pose of its own)"
        } else {
            ""
        },
        m.requests,
        m.seconds,
        m.requests_per_second,
        m.next_p50_ms,
        m.next_p99_ms,
        m.next_max_ms,
        m.retries,
        m.refused_starts,
        m.errors,
    );
    for k in &m.by_reply {
        println!(
            "  {:<5} {:>6} replies: p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms",
            k.reply, k.count, k.p50_ms, k.p99_ms, k.max_ms
        );
    }
    if let (Some(early), Some(late)) = (m.start_early_p50_ms, m.start_late_p50_ms) {
        println!(
            "  starts as the history grows: p50 {early:.1} ms for each robot's trials {}–{}, {late:.1} ms for its last {TIMED_STARTS}",
            EARLY_FROM + 1,
            EARLY_FROM + TIMED_STARTS
        );
    }
    if let Some(k) = m.killed_after_s {
        println!("replica 0 killed (SIGKILL) after {k:.1} s");
    }
    if let Some(p) = &m.pages {
        println!(
            "pages: {} reading, {} stalled; {} events received ({} resync), {} fetches, {} stream errors",
            p.pages, p.stalled_pages, p.events, p.resyncs, p.fetches, p.stream_errors
        );
    }
    if let Some([first, max, last]) = m.server_rss_mib {
        println!(
            "replica 0 resident memory from a quarter into the run: {first:.1} MiB, {max:.1} MiB at most, {last:.1} MiB at the end"
        );
    }
    if let Some(d) = m.double_claims {
        println!("teams: {d} containers claimed by two robots at once");
    }
    println!(
        "read back: {} acknowledged observations, {} lost, {} duplicated; {} deployments with other trials than their robot started{}",
        m.verified_observations,
        m.lost_observations,
        m.duplicated_observations,
        m.mismatched_deployments,
        line.database_mib
            .map(|m| format!("; database {m:.1} MiB"))
            .unwrap_or_default()
    );
}

fn planner(args: PlannerArgs) -> Result<ExitCode> {
    let m = usize::from(args.targets);
    let largest = if m == 1 {
        ferret_plan::planner::MAX_EXACT
    } else {
        ferret_plan::task_table::max_candidates(m)
    };
    let mut lines = Vec::new();
    for &n in &args.sizes {
        if n > largest {
            anyhow::bail!(
                "{n} containers exceed the exact planner's limit of {largest} for {m} target(s)"
            );
        }
        // Keep each size to a few seconds: 2^n·n² work per solve (times 3^m for tasks).
        let work = (1u64 << n) * (n * n) as u64 * if m == 1 { 1 } else { 3u64.pow(m as u32) };
        let instances = args
            .instances
            .max(1)
            .min((2_000_000_000 / work.max(1)).max(5) as usize);
        let mut us: Vec<f64> = (0..instances)
            .map(|i| {
                let seed = args
                    .seed
                    .wrapping_mul(1_000_003)
                    .wrapping_add((n * 10_000 + i) as u64);
                let t;
                if m == 1 {
                    let p = TourProblem::random(n, seed);
                    t = Instant::now();
                    std::hint::black_box(solve_exact(&p));
                } else {
                    let p = ferret_plan::TaskProblem::random(n, m, true, seed);
                    t = Instant::now();
                    std::hint::black_box(ferret_plan::solve_task(&p));
                }
                t.elapsed().as_secs_f64() * 1e6
            })
            .collect();
        us.sort_by(f64::total_cmp);
        let entries = if m == 1 {
            (1u64 << n) * n as u64
        } else {
            ferret_plan::task_table::table_entries(n, m) as u64
        };
        lines.push(Line {
            targets: m,
            containers: n,
            instances,
            median_us: us[us.len() / 2],
            p90_us: us[(us.len() * 9) / 10],
            table_mib: (entries * 8) as f64 / (1024.0 * 1024.0),
        });
    }
    if args.json {
        println!("{}", serde_json::to_string_pretty(&lines)?);
    } else {
        println!(
            "{:>7} {:>10} {:>9} {:>14} {:>14} {:>10}",
            "targets", "containers", "instances", "median", "p90", "table"
        );
        for l in &lines {
            println!(
                "{:>7} {:>10} {:>9} {:>14} {:>14} {:>7.1} MiB",
                l.targets,
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
