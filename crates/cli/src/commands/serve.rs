//! `ferret serve`: the planner and strategy selection as an HTTP service for a real robot (see
//! docs/serve.md). A thin face: scenes load as `ferret houses` loads them, strategies build from
//! the same registry as `ferret eval`, and the service crate drives the same trial step and
//! selector as `ferret deploy`.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{Context, Result, bail};
use ferret_plan::Strategy;
use ferret_select::ORACLE;
use ferret_serve::{HttpOptions, Service, Store};
use ferret_world::procthor::HouseRange;

use super::eval::{DEFAULT_STRATEGIES, PlanningArgs};
use super::llm_setup::{LlmArgs, full_registry};
use crate::common::{GridArgs, HouseArgs};

/// Serve scenes, deployments and trials over HTTP (JSON; OpenAPI at /openapi.json). A robot
/// creates a deployment, starts a trial (scene, target, pose), goes where the reply says, reports
/// what it saw, and repeats; when it finds the target, the other strategies are replayed and
/// selection learns, as in `ferret deploy`. Everything is stored in --db before each reply, so
/// the server can be killed and restarted at any moment.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// A scene file (.yaml/.yml, or .json with `ferret_scene`) or a ProcTHOR house file (every
    /// house becomes a scene named like `multiroom-val150.jsonl.gz#3`). Repeatable.
    #[arg(long = "scene", value_name = "FILE", required = true)]
    scenes: Vec<PathBuf>,
    /// Which houses of ProcTHOR files, by 0-based index: `0..150`, `7`.
    #[arg(long, value_name = "A..B")]
    range: Option<HouseRange>,
    /// The ProcTHOR generator's asset-database.json, for ProcTHOR files.
    #[arg(long, value_name = "PATH")]
    asset_db: Option<PathBuf>,
    #[command(flatten)]
    grid: GridArgs,
    #[command(flatten)]
    planning: PlanningArgs,
    #[command(flatten)]
    llm: LlmArgs,
    /// Strategies deployments may choose from, comma separated (the oracle never: a robot has no
    /// ground truth).
    #[arg(long, value_delimiter = ',', default_value = DEFAULT_STRATEGIES)]
    strategies: Vec<String>,
    /// Address to listen on. Anything but loopback exposes the robot's planner to the network:
    /// set a token.
    #[arg(long, default_value = "127.0.0.1:8080")]
    listen: SocketAddr,
    /// The SQLite database holding scenes, deployments, trials and replies.
    #[arg(long, value_name = "FILE", default_value = "ferret-serve.sqlite")]
    db: PathBuf,
    /// Environment variable holding the bearer token; when it is set, requests need
    /// `Authorization: Bearer <token>` (all but /health).
    #[arg(long, value_name = "VAR", default_value = "FERRET_SERVE_TOKEN")]
    token_env: String,
    /// Allow browser pages from this origin (CORS); repeatable. Off by default.
    #[arg(long, value_name = "URL")]
    cors_origin: Vec<String>,
}

/// Builds the service the arguments describe.
fn build_service(args: &Args, store: Store) -> Result<Service> {
    let (grid, planning, llm, strategies) =
        (&args.grid, &args.planning, &args.llm, &args.strategies);
    grid.validate()?;
    planning.validate()?;
    crate::common::check_distinct("--strategies", strategies)?;
    let specs: Vec<String> = strategies
        .iter()
        .filter(|s| s.as_str() != ORACLE)
        .cloned()
        .collect();
    if specs.is_empty() {
        bail!("--strategies: give at least one strategy other than the oracle");
    }
    let setup = full_registry(planning, llm, &specs)?;
    let candidates: Vec<Arc<dyn Strategy>> = specs
        .iter()
        .map(|s| setup.registry.build(s))
        .collect::<Result<_, _>>()?;
    let service = Service::new(store, grid.params(), candidates)
        .map_err(|e| anyhow::anyhow!("{}", e.message))?;
    for path in &args.scenes {
        let houses = HouseArgs {
            houses: Some(path.clone()),
            range: args.range,
            asset_db: args.asset_db.clone(),
            skip_invalid: false,
            generate: 0,
            house_seed: 0,
        };
        let loaded = houses.load()?;
        for scene in loaded.scenes {
            let name = scene.house.name.clone();
            service
                .add_scene(&name, scene)
                .map_err(|e| anyhow::anyhow!("{}: scene {name}: {}", path.display(), e.message))?;
        }
    }
    Ok(service)
}

/// Runs `ferret serve`.
pub fn run(args: Args) -> Result<ExitCode> {
    let store = Store::open(&args.db)?;
    let service = build_service(&args, store)?;
    let token = std::env::var(&args.token_env)
        .ok()
        .filter(|t| !t.is_empty());
    if token.is_none() && !args.listen.ip().is_loopback() {
        eprintln!(
            "warning: listening on {} without a token (set {})",
            args.listen, args.token_env
        );
    }
    let options = HttpOptions {
        token,
        cors_origins: args.cors_origin.clone(),
    };
    let names = service.strategy_names();
    let app = ferret_serve::router(Arc::new(service), &options)
        .map_err(|e| anyhow::anyhow!("--cors-origin: {}", e.message))?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the HTTP runtime")?;
    runtime.block_on(async move {
        let listener = tokio::net::TcpListener::bind(args.listen)
            .await
            .with_context(|| format!("listening on {}", args.listen))?;
        let addr = listener.local_addr()?;
        // Tests and scripts read this line to learn the port (with --listen 127.0.0.1:0).
        println!(
            "ferret serve: listening on http://{addr} (db {}; strategies {})",
            args.db.display(),
            names.join(", ")
        );
        axum::serve(listener, app)
            .with_graceful_shutdown(shutdown())
            .await
            .context("serving HTTP")
    })?;
    eprintln!("ferret serve: stopped");
    Ok(ExitCode::SUCCESS)
}

/// Ctrl-C or SIGTERM.
async fn shutdown() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        () = ctrl_c => {},
        () = term => {},
    }
}
