//! `ferret serve`: the planner and strategy selection as an HTTP service for a real robot (see
//! docs/serve.md). A thin face: scenes load as `ferret houses` loads them, strategies build from
//! the same registry as `ferret eval`, and the service crate drives the same trial step and
//! selector as `ferret deploy`.

use std::io::Write as _;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;

use anyhow::{Context, Result, bail};
use ferret_llm::FailurePolicy;
use ferret_plan::Strategy;
use ferret_select::ORACLE;
use ferret_serve::{
    HttpOptions, PostgresOptions, SceneLimits, ServeOptions, Service, ServiceOptions, Store,
};
use ferret_world::Scene;
use ferret_world::procthor::HouseRange;

use super::eval::{DEFAULT_STRATEGIES, PlanningArgs};
use super::llm_setup::LlmArgs;
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
    /// ground truth). For trials of household tasks (several targets, a destination), add
    /// sequential/model/prior to let selection weigh one search after another against the
    /// task planner. With a --prior trained with --embeddings: model/learned (and
    /// model/learned-head, model/learned-random, model/learned-head-random), and with --fusion
    /// fused-learned/<prompt>/<llm> and fused-learned/noise; the embeddings' folder is given
    /// with --embeddings or FERRET_EMBEDDINGS for furniture and rooms the prior never saw.
    #[arg(long, value_delimiter = ',', default_value = DEFAULT_STRATEGIES)]
    strategies: Vec<String>,
    /// Address to listen on. Anything but loopback exposes the robot's planner to the network:
    /// set a token.
    #[arg(long, default_value = "127.0.0.1:8080")]
    listen: SocketAddr,
    /// The database holding scenes, deployments, trials and replies: an SQLite file, or a
    /// PostgreSQL URL (`postgres://user@host:port/database`) that several replicas of the
    /// server share (a fleet behind a load balancer; see docs/serve.md).
    #[arg(
        long,
        value_name = "FILE|URL",
        env = "FERRET_SERVE_DB",
        default_value = "ferret-serve.sqlite"
    )]
    db: String,
    /// PostgreSQL only: connections this replica keeps open, all opened as it starts; requests
    /// that need one beyond them wait (503 after 10 s). Each replica holds 2 sessions more (request
    /// claims, events): keep replicas × (this + 2) below the server's max_connections.
    #[arg(long, value_name = "N", default_value_t = PostgresOptions::default().pool_size)]
    db_pool: usize,
    /// Environment variable holding the bearer token; when it is set, requests need
    /// `Authorization: Bearer <token>` (all but /health).
    #[arg(long, value_name = "VAR", default_value = "FERRET_SERVE_TOKEN")]
    token_env: String,
    /// Allow browser pages from this origin (CORS); repeatable. Off by default: a request
    /// carrying any other `Origin` is refused (403).
    #[arg(long, value_name = "URL")]
    cors_origin: Vec<String>,
    /// Another name clients reach the server by (`robot.local`, or `name:port`), accepted in
    /// the `Host` header besides the --listen address (and `localhost` for a loopback one);
    /// repeatable. Any other `Host` is refused (403), which stops DNS-rebinding pages.
    #[arg(long, value_name = "HOST")]
    allow_host: Vec<String>,
    /// Most scenes clients may upload (413 past it; scenes given with --scene do not count).
    #[arg(long, value_name = "N", default_value_t = SceneLimits::default().max_scenes)]
    max_scenes: usize,
    /// Most grid cells of an uploaded scene at --resolution (422 past it): memory and planning
    /// time grow with them (4 M cells = 100 m × 100 m at 0.05 m, 8 MB).
    #[arg(long, value_name = "N", default_value_t = SceneLimits::default().max_cells)]
    max_scene_cells: u64,
    /// Most containers of an uploaded scene, and obstacles likewise (422 past it).
    #[arg(long, value_name = "N", default_value_t = SceneLimits::default().max_containers)]
    max_scene_containers: usize,
    /// Most vertices of all room polygons of an uploaded scene together (422 past it).
    #[arg(long, value_name = "N", default_value_t = SceneLimits::default().max_vertices)]
    max_scene_vertices: usize,
    /// Memory for grids and distances of scenes in use, MiB; the least recently used are
    /// dropped past it and built again when asked for.
    #[arg(long, value_name = "MIB", default_value_t = 256)]
    grid_cache_mib: usize,
    /// Replay costs kept per scene and pose: a trial that ends as an earlier one did (same
    /// scene, pose, target, container found in) reuses the other candidates' replays instead of
    /// simulating them again; 0 replays every time. About 128 bytes each.
    #[arg(long, value_name = "N", default_value_t = ServiceOptions::default().kept_replays)]
    kept_replays: usize,
    /// Candidate sets whose exact plans each scene keeps the first steps of (about 500 bytes
    /// each): a search or replay that meets a set another one solved takes the same decision
    /// without solving the planner's table again; 0 solves every time.
    #[arg(long, value_name = "N", default_value_t = ServiceOptions::default().kept_plans)]
    kept_plans: usize,
    /// Largest request body, KiB (413 past it).
    #[arg(long, value_name = "KIB", default_value_t = 1024)]
    max_body_kib: usize,
    /// Seconds a client has to send a request's headers (after connecting, or after its last
    /// reply).
    #[arg(long, value_name = "SECS", default_value_t = 10.0)]
    header_timeout: f64,
    /// Seconds a client has to send a request's whole body once its headers are in (408 and the
    /// connection closed past it, however slowly bytes still arrive).
    #[arg(long, value_name = "SECS", default_value_t = 10.0)]
    body_timeout: f64,
    /// Seconds after which a kept-alive connection without a request is closed.
    #[arg(long, value_name = "SECS", default_value_t = 60.0)]
    idle_timeout: f64,
    /// Most connections open at once; at the cap, the connection idle the longest is closed to
    /// make room. Lowered to fit the process's open-file limit.
    #[arg(long, value_name = "N", default_value_t = ServeOptions::default().max_connections)]
    max_connections: usize,
    /// Most live event streams (`GET /events`, one per open browser page) at once; past it a
    /// page is answered 503 and retries. Each stream holds one of --max-connections.
    #[arg(long, value_name = "N", default_value_t = ferret_serve::events::DEFAULT_MAX_STREAMS)]
    max_event_streams: usize,
    /// Serve the page and every GET route but refuse every write (403): a screen on the wall,
    /// a replica on the fleet's PostgreSQL that robots cannot drive.
    #[arg(long)]
    view_only: bool,
    /// Seconds an LLM endpoint that failed (after its retries) is not asked: trials of its
    /// strategies are refused with 503 at once meanwhile; then one question checks whether it
    /// is back.
    #[arg(long, value_name = "SECS", default_value_t = 30.0)]
    llm_retry_after: f64,
    /// Seconds a robot of a team keeps its claim on a container without a word from it
    /// (a claim, an observation); past it a teammate may be sent there. Every replica of one
    /// database should be given the same.
    #[arg(long, value_name = "SECS", default_value_t = ferret_serve::service::DEFAULT_CLAIM_TTL.as_secs_f64())]
    claim_ttl: f64,
}

fn seconds(name: &str, v: f64) -> Result<Duration> {
    if !(v.is_finite() && v > 0.0 && v <= 86_400.0) {
        bail!("{name} {v}: must be a number of seconds in (0, 86400]");
    }
    Ok(Duration::from_secs_f64(v))
}

/// Everything the arguments say, checked before any file is touched.
struct Checked {
    service: ServiceOptions,
    serve: ServeOptions,
    max_body_bytes: usize,
    llm_retry_after: Duration,
    token: Option<String>,
}

fn check(args: &Args) -> Result<Checked> {
    args.grid.validate()?;
    args.planning.validate()?;
    crate::common::check_distinct("--strategies", &args.strategies)?;
    for (name, v) in [
        ("--max-scenes", args.max_scenes),
        ("--max-scene-containers", args.max_scene_containers),
        ("--max-scene-vertices", args.max_scene_vertices),
        ("--grid-cache-mib", args.grid_cache_mib),
        ("--max-body-kib", args.max_body_kib),
        ("--max-connections", args.max_connections),
        ("--max-event-streams", args.max_event_streams),
    ] {
        if v == 0 {
            bail!("{name} 0: must be at least 1");
        }
    }
    if args.max_scene_cells == 0 || args.max_scene_cells > ferret_world::grid::MAX_CELLS {
        bail!(
            "--max-scene-cells {}: must be from 1 to {}",
            args.max_scene_cells,
            ferret_world::grid::MAX_CELLS
        );
    }
    if args.max_scene_vertices < 3 {
        bail!(
            "--max-scene-vertices {}: a room needs 3",
            args.max_scene_vertices
        );
    }
    let token = match std::env::var(&args.token_env) {
        Ok(t) if t.trim().is_empty() => bail!(
            "{} is set but empty: set a token, or unset it to run without one",
            args.token_env
        ),
        Ok(t) => Some(t.trim().to_string()),
        Err(std::env::VarError::NotPresent) => None,
        Err(std::env::VarError::NotUnicode(_)) => {
            bail!("{} is not valid UTF-8", args.token_env)
        }
    };
    HttpOptions {
        token: token.clone(),
        cors_origins: args.cors_origin.clone(),
        listen: Some(args.listen),
        allowed_hosts: args.allow_host.clone(),
        ..HttpOptions::default()
    }
    .validate()
    .map_err(|e| anyhow::anyhow!("--{}: {}", e.field, e.message))?;
    Ok(Checked {
        service: ServiceOptions {
            limits: SceneLimits {
                max_scenes: args.max_scenes,
                max_cells: args.max_scene_cells,
                max_containers: args.max_scene_containers,
                max_vertices: args.max_scene_vertices,
            },
            grid_cache_bytes: args.grid_cache_mib.saturating_mul(1 << 20),
            kept_replays: args.kept_replays,
            kept_plans: args.kept_plans,
            max_event_streams: args.max_event_streams,
            claim_ttl: seconds("--claim-ttl", args.claim_ttl)?,
            ..ServiceOptions::default()
        },
        serve: ServeOptions {
            header_timeout: seconds("--header-timeout", args.header_timeout)?,
            body_timeout: seconds("--body-timeout", args.body_timeout)?,
            idle_timeout: seconds("--idle-timeout", args.idle_timeout)?,
            max_connections: fit_open_files(args.max_connections),
        },
        max_body_bytes: args.max_body_kib.saturating_mul(1024),
        llm_retry_after: seconds("--llm-retry-after", args.llm_retry_after)?,
        token,
    })
}

/// `max` lowered to what the open-file limit leaves after the files the server itself holds,
/// once the soft limit has been raised to the hard one.
fn fit_open_files(max: usize) -> usize {
    // The database, its journal files, the LLM cache, the runtime's own descriptors.
    const RESERVED: usize = 64;
    #[cfg(unix)]
    {
        let mut lim = libc::rlimit {
            rlim_cur: 0,
            rlim_max: 0,
        };
        // SAFETY: getrlimit/setrlimit with a valid pointer to a local struct.
        if unsafe { libc::getrlimit(libc::RLIMIT_NOFILE, &mut lim) } == 0 {
            if lim.rlim_cur < lim.rlim_max {
                let raised = libc::rlimit {
                    rlim_cur: lim.rlim_max,
                    rlim_max: lim.rlim_max,
                };
                // SAFETY: as above.
                if unsafe { libc::setrlimit(libc::RLIMIT_NOFILE, &raised) } == 0 {
                    lim = raised;
                }
            }
            let room = usize::try_from(lim.rlim_cur)
                .unwrap_or(usize::MAX)
                .saturating_sub(RESERVED)
                .max(1);
            if room < max {
                eprintln!(
                    "warning: --max-connections {max} lowered to {room} to fit the open-file limit ({})",
                    lim.rlim_cur
                );
                return room;
            }
        }
    }
    max
}

/// The candidates and the scenes the arguments name, loaded before the database is opened so
/// that a bad argument leaves no file behind.
type Loaded = (Vec<Arc<dyn Strategy>>, Vec<(PathBuf, Scene)>);

fn load(args: &Args, llm_retry_after: Duration) -> Result<Loaded> {
    let (planning, llm, strategies) = (&args.planning, &args.llm, &args.strategies);
    let specs: Vec<String> = strategies
        .iter()
        .filter(|s| s.as_str() != ORACLE)
        .cloned()
        .collect();
    if specs.is_empty() {
        bail!("--strategies: give at least one strategy other than the oracle");
    }
    // A server runs for days: an LLM endpoint that fails is asked again after a pause, not
    // given up on until restart as in a batch run.
    let policy = FailurePolicy::Breaker {
        pause: llm_retry_after,
    };
    let setup = ferret_lab::Strategies::builder(&planning.settings(), &llm.settings())
        .for_specs(&specs)
        .on_failure(policy)
        .build()?;
    let candidates: Vec<Arc<dyn Strategy>> = specs
        .iter()
        .map(|s| setup.registry.build(s))
        .collect::<Result<_, _>>()?;
    let mut scenes = Vec::new();
    for path in &args.scenes {
        let houses = HouseArgs {
            houses: Some(path.clone()),
            range: args.range,
            asset_db: args.asset_db.clone(),
            skip_invalid: false,
            generate: 0,
            house_seed: 0,
        };
        scenes.extend(houses.load()?.scenes.into_iter().map(|s| (path.clone(), s)));
    }
    Ok((candidates, scenes))
}

/// Runs `ferret serve`.
pub fn run(args: Args) -> Result<ExitCode> {
    let checked = check(&args)?;
    if checked.token.is_none() && !args.listen.ip().is_loopback() {
        eprintln!(
            "warning: listening on {} without a token (set {})",
            args.listen, args.token_env
        );
    }
    let (candidates, scenes) = load(&args, checked.llm_retry_after)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("starting the HTTP runtime")?;
    let listener = runtime
        .block_on(tokio::net::TcpListener::bind(args.listen))
        .with_context(|| format!("listening on {}", args.listen))?;
    let addr = listener.local_addr()?;
    let store = Store::open_any(
        &args.db,
        PostgresOptions {
            pool_size: args.db_pool,
            ..PostgresOptions::default()
        },
    )?;
    let db = store.describe();
    let service = Service::with_options(store, args.grid.params(), candidates, checked.service)
        .map_err(|e| anyhow::anyhow!("{}", e.message))?;
    for (path, scene) in scenes {
        let name = scene.house.name.clone();
        service
            .add_scene(&name, scene)
            .map_err(|e| anyhow::anyhow!("{}: scene {name}: {}", path.display(), e.message))?;
    }
    let has_token = checked.token.is_some();
    let options = HttpOptions {
        token: checked.token,
        cors_origins: args.cors_origin.clone(),
        listen: Some(addr),
        allowed_hosts: args.allow_host.clone(),
        max_body_bytes: checked.max_body_bytes,
        view_only: args.view_only,
    };
    let names = service.strategy_names();
    let service = Arc::new(service);
    let app = ferret_serve::router(service.clone(), &options)
        .map_err(|e| anyhow::anyhow!("--{}: {}", e.field, e.message))?;
    // Open event streams would hold the stop up until the drain's deadline: they end first.
    let stopping = async move {
        shutdown().await;
        service.events().close();
    };
    runtime.block_on(async move {
        // Tests and scripts read this line to learn the port (with --listen 127.0.0.1:0).
        println!(
            "ferret serve: listening on http://{addr} (db {db}; strategies {}){}",
            names.join(", "),
            if args.view_only { "; view-only" } else { "" }
        );
        // Whoever started the server may have read the line above and closed the pipe: this
        // one is for a person, and is not worth stopping the server for.
        let _ = writeln!(
            std::io::stdout(),
            "ferret serve: live view at http://{addr}/ (open it in a browser{})",
            if has_token {
                "; it asks for the token once"
            } else {
                ""
            }
        );
        ferret_serve::serve(listener, app, checked.serve, stopping)
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
