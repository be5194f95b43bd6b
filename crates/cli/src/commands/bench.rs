//! `ferret bench planner`: decision latency of the exact planner on random instances.
//! `ferret bench serve`: `ferret serve` under load, many robots at once over real HTTP.

use std::process::ExitCode;
use std::time::Instant;

use anyhow::Result;
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
    /// "next container" replies, errors. The database is a real SQLite file (WAL, synchronous
    /// FULL) in a temporary directory.
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
struct ServeLine {
    deployments: usize,
    trials: usize,
    requests: usize,
    errors: usize,
    seconds: f64,
    requests_per_second: f64,
    next_p50_ms: f64,
    next_p99_ms: f64,
    next_max_ms: f64,
    database_mib: f64,
}

fn serve(args: ServeArgs) -> Result<ExitCode> {
    use std::sync::Arc;

    use ferret_plan::draw_trial;

    if args.deployments == 0 || args.trials == 0 {
        anyhow::bail!("--deployments and --trials must be at least 1");
    }
    let loaded = args.houses.load()?;
    if loaded.scenes.is_empty() {
        anyhow::bail!("no houses in {}", loaded.source);
    }
    let dir = tempfile::tempdir()?;
    let db = dir.path().join("bench.sqlite");
    let store = ferret_serve::Store::open(&db)?;
    // The work list: per deployment, (scene name, target) per trial, with the truth to answer.
    let mut plans = Vec::with_capacity(args.deployments);
    for d in 0..args.deployments {
        let mut trials = Vec::with_capacity(args.trials);
        for k in 0..args.trials {
            let scene = &loaded.scenes[(d * args.trials + k) % loaded.scenes.len()];
            let trial = draw_trial(&scene.house, &scene.truth, args.seed, 0.0)?;
            let contents: std::collections::HashMap<String, Vec<String>> = scene
                .house
                .containers
                .iter()
                .enumerate()
                .map(|(i, c)| {
                    let held = scene
                        .truth
                        .contents(i)
                        .iter()
                        .map(|o| o.object_type.to_string())
                        .collect();
                    (c.id.clone(), held)
                })
                .collect();
            trials.push((scene.house.name.clone(), trial.target.to_string(), contents));
        }
        plans.push(trials);
    }
    let service = ferret_serve::Service::new(store, args.grid.params(), {
        let setup = super::llm_setup::full_registry(&args.planning, &args.llm, &args.strategies)?;
        args.strategies
            .iter()
            .map(|s| setup.registry.build(s))
            .collect::<Result<Vec<_>, _>>()?
    })
    .map_err(|e| anyhow::anyhow!("{}", e.message))?;
    let bar = crate::common::progress(loaded.scenes.len(), "scenes");
    for scene in loaded.scenes {
        let name = scene.house.name.clone();
        service
            .add_scene(&name, scene)
            .map_err(|e| anyhow::anyhow!("{name}: {}", e.message))?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()?;
    let listener = runtime.block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))?;
    let addr = listener.local_addr()?;
    // The server's own guards and connection loop, as `ferret serve` runs them.
    let options = ferret_serve::HttpOptions {
        listen: Some(addr),
        ..ferret_serve::HttpOptions::default()
    };
    let app = ferret_serve::router(Arc::new(service), &options)
        .map_err(|e| anyhow::anyhow!("{}", e.message))?;
    let total_trials = args.deployments * args.trials;
    let bar = crate::common::progress(total_trials, "trials");
    let (latencies, requests, errors, seconds) = runtime.block_on(async {
        let url = format!("http://{addr}");
        let server = tokio::spawn(ferret_serve::serve(
            listener,
            app,
            ferret_serve::ServeOptions::default(),
            std::future::pending(),
        ));
        let client = reqwest::Client::new();
        let started = Instant::now();
        let tasks: Vec<_> = plans
            .into_iter()
            .map(|trials| {
                let (client, url, bar) = (client.clone(), url.clone(), bar.clone());
                tokio::spawn(async move { robot(&client, &url, trials, &bar).await })
            })
            .collect();
        let mut latencies = Vec::new();
        let (mut requests, mut errors) = (0usize, 0usize);
        for t in tasks {
            let (l, r, e) = t.await?;
            latencies.extend(l);
            requests += r;
            errors += e;
        }
        let seconds = started.elapsed().as_secs_f64();
        server.abort();
        anyhow::Ok((latencies, requests, errors, seconds))
    })?;
    bar.finish_and_clear();
    let mut ms: Vec<f64> = latencies
        .iter()
        .map(|d: &std::time::Duration| d.as_secs_f64() * 1e3)
        .collect();
    ms.sort_by(f64::total_cmp);
    let pick = |q: f64| {
        ms.get(((ms.len() as f64 - 1.0) * q).round() as usize)
            .copied()
            .unwrap_or(f64::NAN)
    };
    let size = |p: &std::path::Path| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    let line = ServeLine {
        deployments: args.deployments,
        trials: args.trials,
        requests,
        errors,
        seconds,
        requests_per_second: requests as f64 / seconds,
        next_p50_ms: pick(0.5),
        next_p99_ms: pick(0.99),
        next_max_ms: ms.last().copied().unwrap_or(f64::NAN),
        database_mib: (size(&db) + size(&dir.path().join("bench.sqlite-wal"))) as f64
            / (1024.0 * 1024.0),
    };
    if args.json {
        println!("{}", serde_json::to_string_pretty(&line)?);
    } else {
        println!(
            "{} deployments × {} trials: {} requests in {:.1} s = {:.0} requests/s; next-container reply p50 {:.1} ms, p99 {:.1} ms, max {:.1} ms; {} errors; database {:.1} MiB",
            line.deployments,
            line.trials,
            line.requests,
            line.seconds,
            line.requests_per_second,
            line.next_p50_ms,
            line.next_p99_ms,
            line.next_max_ms,
            line.errors,
            line.database_mib
        );
    }
    Ok(if errors == 0 {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

type RobotTrial = (
    String,
    String,
    std::collections::HashMap<String, Vec<String>>,
);

/// One simulated robot: a deployment, its trials to the end. Returns the latencies of the
/// replies that carry a next container (trial starts and observations), requests and errors.
async fn robot(
    client: &reqwest::Client,
    url: &str,
    trials: Vec<RobotTrial>,
    bar: &indicatif::ProgressBar,
) -> (Vec<std::time::Duration>, usize, usize) {
    use serde_json::{Value, json};
    let (mut lat, mut requests, mut errors) = (Vec::new(), 0usize, 0usize);
    let mut post =
        async |path: String, body: Value, lat: &mut Vec<std::time::Duration>| -> Option<Value> {
            requests += 1;
            let t = Instant::now();
            let r = client
                .post(format!("{url}{path}"))
                .json(&body)
                .send()
                .await
                .ok()?;
            let ok = r.status().is_success();
            let v: Value = r.json().await.ok()?;
            lat.push(t.elapsed());
            if ok {
                Some(v)
            } else {
                tracing::warn!(%path, reply = %v, "request failed");
                None
            }
        };
    let Some(dep) = post("/deployments".into(), json!({}), &mut lat).await else {
        return (lat, requests, 1);
    };
    lat.clear();
    let id = dep["id"].as_i64().unwrap_or_default();
    for (scene, target, contents) in trials {
        let Some(mut reply) = post(
            format!("/deployments/{id}/trials"),
            json!({"scene": scene, "target": target}),
            &mut lat,
        )
        .await
        else {
            errors += 1;
            break;
        };
        let trial = reply["trial"].as_i64().unwrap_or_default();
        while reply["status"] == "searching" {
            let next = reply["next"]["container"]
                .as_str()
                .unwrap_or_default()
                .to_string();
            let seen = contents.get(&next).cloned().unwrap_or_default();
            let found = seen.contains(&target);
            match post(
                format!("/trials/{trial}/observations"),
                json!({"container": next, "found": found, "objects": seen}),
                &mut lat,
            )
            .await
            {
                Some(r) => reply = r,
                None => {
                    errors += 1;
                    break;
                }
            }
        }
        bar.inc(1);
    }
    (lat, requests, errors)
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
