//! The deployment experiment of the paper (section VI-C): many deployments, each a random
//! sequence of distinct houses ([`HouseOrder`]), run once with every selection method of
//! [`Method::ALL`], each method a [`LiveDeployment`] whose trials are looked up in a cost table
//! instead of run.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::numpy::LegacyRandomState;
use crate::selector::{SelectorVariant, check_c};
use crate::{CostTable, DEFAULT_C, HouseOrder, LiveDeployment, Method, SelectError};

/// Most deployment trials (`deployments × trials_per_deployment`) one experiment keeps: every
/// trial is held in memory (about 40 bytes each, so 5 M take 200 MB), and the paper's experiment
/// needs 50 000.
pub const MAX_EXPERIMENT_TRIALS: usize = 5_000_000;

/// Parameters of a deployment experiment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ExperimentOptions {
    /// Number of independent deployments (paper: 500).
    pub deployments: usize,
    /// Trials per deployment, each on a distinct house (paper: 100).
    pub trials_per_deployment: usize,
    /// Exploration constant in metres (paper: 5 m).
    pub c: f64,
    /// Seed; deployment `d` draws from a random stream derived from `(seed, d)` only.
    pub seed: u64,
    /// Make replay selection deploy every strategy once first, as UCB does (see
    /// [`ReplaySelection::untried_first`](crate::ReplaySelection::untried_first)). Default `false`: the paper's replay selection.
    #[serde(default)]
    pub replay_untried_first: bool,
    /// Draw each deployment's houses with replacement, as the paper's reference code does, so
    /// a house may come twice and a deployment may be longer than the number of houses.
    /// Default `false`: distinct houses, as the paper's text says.
    #[serde(default)]
    pub with_replacement: bool,
    /// Score untried strategies 0 in UCB, as the reference code does, instead of deploying
    /// each once first (see [`Ucb::untried_score`](crate::Ucb::untried_score)). Default `false`.
    #[serde(default)]
    pub ucb_untried_zero: bool,
    /// Draw as the reference code's results script does: deployment `d` seeds numpy's legacy
    /// generator with `seed + d`, shuffles the houses, then per trial draws a house with
    /// replacement (`choice`) and breaks score ties with `choice` from the same stream, so the
    /// two methods see different houses after their first tie. The best strategy and its
    /// curve come from the same draws without tie-breaks, i.e. the reference's table average.
    /// Implies drawing with replacement. Default `false`.
    #[serde(default)]
    pub reference_draws: bool,
}

impl ExperimentOptions {
    /// The selectors' variant these options ask for.
    pub fn variant(&self) -> SelectorVariant {
        SelectorVariant {
            replay_untried_first: self.replay_untried_first,
            ucb_untried_zero: self.ucb_untried_zero,
        }
    }
}

impl Default for ExperimentOptions {
    fn default() -> Self {
        Self {
            deployments: 500,
            trials_per_deployment: 100,
            c: DEFAULT_C,
            seed: 0,
            replay_untried_first: false,
            with_replacement: false,
            ucb_untried_zero: false,
            reference_draws: false,
        }
    }
}

/// What one method did in one deployment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MethodRun {
    /// The method.
    pub method: Method,
    /// Strategy chosen at trial `k` (index `k − 1`).
    pub chosen: Vec<usize>,
    /// Real cost of that choice at trial `k` (index `k − 1`), metres.
    pub costs: Vec<f64>,
    /// The rows this method's trials used, when they differ from the deployment's
    /// ([`ExperimentOptions::reference_draws`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub houses: Option<Vec<usize>>,
}

/// One deployment: its house order, shared by every method, and what each method did.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeploymentRecord {
    /// Row of the cost table used by trial `k` (index `k − 1`): distinct rows from distinct
    /// houses (when the table is [grouped](CostTable::grouped)), unless drawn with replacement.
    pub houses: Vec<usize>,
    /// What each method did on these houses, in the order of [`Method::ALL`].
    pub runs: Vec<MethodRun>,
}

impl DeploymentRecord {
    /// The rows method `method`'s trials used.
    pub fn houses_of(&self, method: Method) -> &[usize] {
        self.run(method)
            .and_then(|r| r.houses.as_deref())
            .unwrap_or(&self.houses)
    }

    /// The run of method `method`, if it ran.
    pub fn run(&self, method: Method) -> Option<&MethodRun> {
        self.runs.iter().find(|r| r.method == method)
    }
}

/// Curves of one method against `k`, averaged over deployments. Index `k − 1` holds trial `k`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MethodSummary {
    /// The method.
    pub method: Method,
    /// Mean cost of trials `1..=k`, averaged over deployments (metres).
    pub avg_cost: Vec<f64>,
    /// Sum over trials `1..=k` of `cost(chosen) − cost(best single strategy)` on the same house,
    /// averaged over deployments (metres).
    pub cum_regret: Vec<f64>,
    /// Cumulative regret as the paper's figure 4 reports it: `Σ_{j ≤ k} (avg_cost_j − m*)`, where
    /// `m*` is the best single strategy's mean cost over all houses. It sums the gaps of the
    /// running averages, not of the trials, so it is larger than `cum_regret` while selection
    /// still pays for early mistakes. The paper's numbers match this definition.
    pub paper_regret: Vec<f64>,
    /// `choice_fraction[k − 1][i]`: fraction of deployments that chose strategy `i` at trial `k`.
    pub choice_fraction: Vec<Vec<f64>>,
}

/// Everything a deployment experiment produced.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ExperimentResult {
    /// The options it ran with.
    pub options: ExperimentOptions,
    /// Candidate strategy names, in index order.
    pub strategies: Vec<String>,
    /// Mean real cost of every strategy over all houses of the table.
    pub mean_costs: Vec<f64>,
    /// The best single strategy: lowest mean real cost over all houses.
    pub best_strategy: usize,
    /// Mean cost of trials `1..=k` had the best single strategy been used throughout, averaged
    /// over deployments (the paper's "best performance" curve).
    pub best_avg_cost: Vec<f64>,
    /// The curves of each method, in the order of [`Method::ALL`].
    pub summaries: Vec<MethodSummary>,
    /// Every deployment, in index order.
    pub deployments: Vec<DeploymentRecord>,
}

impl ExperimentResult {
    /// Curves of method `method`, if it ran.
    pub fn summary(&self, method: Method) -> Option<&MethodSummary> {
        self.summaries.iter().find(|s| s.method == method)
    }

    /// Number of trials per deployment (`k` runs over `1..=trials()`).
    pub fn trials(&self) -> usize {
        self.options.trials_per_deployment
    }
}

/// Runs the deployment experiment on `table`.
///
/// Each deployment draws `trials_per_deployment` distinct houses in random order; every method
/// of [`Method::ALL`] then runs over that same order, each trial observing the chosen strategy's real cost
/// and the replay costs of all strategies given that choice. Deployments run in parallel, and the
/// result depends only on the table and the options, not on the number of threads.
///
/// Errors: zero deployments or trials, more than [`MAX_EXPERIMENT_TRIALS`] trials in all, more
/// trials per deployment than houses, or an invalid `c`.
///
/// ```
/// use ferret_select::{CostTable, ExperimentOptions, Method, run_experiment};
/// let table = CostTable::with_exact_replay(
///     vec!["good".into(), "bad".into()],
///     (0..10).map(|h| format!("house-{h}")).collect(),
///     (0..10).map(|h| vec![10.0 + h as f64, 30.0]).collect(),
/// )?;
/// let opts = ExperimentOptions {
///     deployments: 20,
///     trials_per_deployment: 10,
///     seed: 1,
///     ..ExperimentOptions::default()
/// };
/// let result = run_experiment(&table, &opts)?;
/// assert_eq!(result.best_strategy, 0);
/// let regret = |m| result.summary(m).map(|s| s.cum_regret[9]);
/// assert!(regret(Method::ReplaySelection) <= regret(Method::Ucb));
/// # Ok::<(), ferret_select::SelectError>(())
/// ```
pub fn run_experiment(
    table: &CostTable,
    opts: &ExperimentOptions,
) -> Result<ExperimentResult, SelectError> {
    check_options(table, opts)?;
    tracing::debug!(
        deployments = opts.deployments,
        trials = opts.trials_per_deployment,
        strategies = table.n_strategies(),
        houses = table.n_houses(),
        c = opts.c,
        seed = opts.seed,
        "running deployment experiment"
    );
    let base = ChaCha8Rng::seed_from_u64(opts.seed);
    let deployments = (0..opts.deployments)
        .into_par_iter()
        .map(|d| run_deployment(table, opts, &base, d))
        .collect::<Result<Vec<_>, _>>()?;

    let best = if opts.reference_draws {
        reference_best(table, &deployments, opts.trials_per_deployment)
    } else {
        table.best_strategy()
    };
    let best_avg = best_avg_cost(table, &deployments, best, opts.trials_per_deployment);
    let best_mean = if opts.reference_draws {
        best_avg.last().copied().unwrap_or(f64::NAN)
    } else {
        table.mean_costs()[best]
    };
    let result = ExperimentResult {
        options: *opts,
        strategies: table.strategies().to_vec(),
        mean_costs: table.mean_costs(),
        best_strategy: best,
        best_avg_cost: best_avg,
        summaries: Method::ALL
            .into_iter()
            .map(|method| {
                summarise(
                    table,
                    &deployments,
                    (best, best_mean),
                    opts.trials_per_deployment,
                    method,
                )
            })
            .collect(),
        deployments,
    };
    for s in &result.summaries {
        if let Some(regret) = s.cum_regret.last() {
            tracing::debug!(method = %s.method, regret, "deployment experiment done");
        }
    }
    Ok(result)
}

fn check_options(table: &CostTable, opts: &ExperimentOptions) -> Result<(), SelectError> {
    if opts.deployments == 0 {
        return Err(SelectError::InvalidOption {
            name: "deployments",
            reason: "must be at least 1".to_owned(),
        });
    }
    if opts.trials_per_deployment == 0 {
        return Err(SelectError::InvalidOption {
            name: "trials-per-deployment",
            reason: "must be at least 1".to_owned(),
        });
    }
    if opts
        .deployments
        .checked_mul(opts.trials_per_deployment)
        .is_none_or(|n| n > MAX_EXPERIMENT_TRIALS)
    {
        return Err(SelectError::InvalidOption {
            name: "deployments",
            reason: format!(
                "{} deployments × {} trials exceed the limit of {MAX_EXPERIMENT_TRIALS} trials",
                opts.deployments, opts.trials_per_deployment
            ),
        });
    }
    if !opts.with_replacement
        && !opts.reference_draws
        && opts.trials_per_deployment > table.n_groups()
    {
        return Err(SelectError::TooManyTrials {
            trials: opts.trials_per_deployment,
            houses: table.n_groups(),
        });
    }
    check_c(opts.c)
}

/// Independent random stream `purpose` of deployment `d`: depends on `(seed, d, purpose)` only.
/// Purposes: 0 the house draw, 3 a trial's pick among a house's trials, and the tie-breaks of
/// method `m` (see [`method_stream`]).
fn stream(base: &ChaCha8Rng, d: usize, purpose: u64) -> ChaCha8Rng {
    let mut rng = base.clone();
    rng.set_stream((d as u64).wrapping_mul(4).wrapping_add(purpose));
    rng
}

/// The tie-break stream of the `m`-th method of [`Method::ALL`] in deployment `d`. The first
/// two methods use purposes 1 and 2 of [`stream`], so their deployments stay what they have
/// always been; further methods use streams with the top bit set, which `stream` never reaches
/// below 2^61 deployments.
fn method_stream(base: &ChaCha8Rng, d: usize, m: usize) -> ChaCha8Rng {
    if m < 2 {
        return stream(base, d, 1 + m as u64);
    }
    let mut rng = base.clone();
    rng.set_stream((1 << 63) | (d as u64).wrapping_mul(64).wrapping_add(m as u64));
    rng
}

fn run_deployment(
    table: &CostTable,
    opts: &ExperimentOptions,
    base: &ChaCha8Rng,
    d: usize,
) -> Result<DeploymentRecord, SelectError> {
    if opts.reference_draws {
        return run_reference_deployment(table, opts, base, d);
    }
    let groups = table.groups();
    let draw = stream(base, d, 0);
    let order = if opts.with_replacement {
        HouseOrder::with_replacement(groups.len(), opts.trials_per_deployment, draw)?
    } else {
        HouseOrder::sampled(groups.len(), opts.trials_per_deployment, draw)?
    };
    // One trial of each drawn house; a house with one trial draws nothing more, so a table of
    // one trial per house gives the same deployments grouped or not.
    let mut order = order.picking_from(stream(base, d, 3));
    let drawn = order.houses().to_vec();
    let houses: Vec<usize> = drawn
        .into_iter()
        .map(|g| match groups[g].as_slice() {
            [only] => *only,
            rows => rows[order.pick(rows.len())],
        })
        .collect();
    let runs = Method::ALL
        .into_iter()
        .enumerate()
        .map(|(m, method)| {
            let mut live = LiveDeployment::with_selector(
                method.configured(table.n_strategies(), opts.c, opts.variant())?,
                opts.c,
                method_stream(base, d, m),
            );
            run_on_table(&mut live, table, &houses)
        })
        .collect::<Result<_, _>>()?;
    Ok(DeploymentRecord { houses, runs })
}

/// A deployment drawn as the reference code draws it (see
/// [`ExperimentOptions::reference_draws`]); a house with several trials picks one from ferret's
/// stream 3 of the deployment, as [`run_deployment`] does.
fn run_reference_deployment(
    table: &CostTable,
    opts: &ExperimentOptions,
    base: &ChaCha8Rng,
    d: usize,
) -> Result<DeploymentRecord, SelectError> {
    let groups = table.groups();
    let seed = opts.seed.wrapping_add(d as u64) as u32;
    let shuffled = || {
        let mut np = LegacyRandomState::new(seed);
        let mut order: Vec<usize> = (0..groups.len()).collect();
        np.shuffle(&mut order);
        (np, order)
    };
    let mut pick = stream(base, d, 3);
    let mut row_of = |g: usize| match groups[g].as_slice() {
        [only] => *only,
        rows => rows[pick.random_range(0..rows.len())],
    };
    // The sequence without tie-breaks: the reference's table draws, for the best strategy.
    let (mut np, order) = shuffled();
    let houses: Vec<usize> = (0..opts.trials_per_deployment)
        .map(|_| row_of(order[np.choice(order.len())]))
        .collect();
    let mut run = |mut live: LiveDeployment| -> Result<MethodRun, SelectError> {
        let method = live.method();
        let (mut np, order) = shuffled();
        live.reserve(opts.trials_per_deployment);
        let mut rows = Vec::with_capacity(opts.trials_per_deployment);
        let mut chosen = Vec::with_capacity(opts.trials_per_deployment);
        let mut costs = Vec::with_capacity(opts.trials_per_deployment);
        for _ in 0..opts.trials_per_deployment {
            let h = row_of(order[np.choice(order.len())]);
            let i = live.choose_with(&mut |ties| np.choice(ties));
            let (cost, replay) = trial_costs(table, h, i)?;
            live.finish(cost, replay)?;
            rows.push(h);
            chosen.push(i);
            costs.push(cost);
        }
        Ok(MethodRun {
            method,
            chosen,
            costs,
            houses: Some(rows),
        })
    };
    let runs = Method::ALL
        .into_iter()
        .map(|method| {
            let selector = method.configured(table.n_strategies(), opts.c, opts.variant())?;
            // Ties come from numpy's stream; ferret's is never drawn from.
            run(LiveDeployment::with_selector(
                selector,
                opts.c,
                stream(base, d, 1),
            ))
        })
        .collect::<Result<_, _>>()?;
    Ok(DeploymentRecord { houses, runs })
}

/// The strategy with the lowest mean, over deployments, of its average cost on each
/// deployment's tie-free houses: the reference's table average.
fn reference_best(table: &CostTable, deployments: &[DeploymentRecord], trials: usize) -> usize {
    (0..table.n_strategies())
        .map(|s| {
            let avg = best_avg_cost(table, deployments, s, trials);
            (avg.last().copied().unwrap_or(f64::INFINITY), s)
        })
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
        .map_or(0, |(_, s)| s)
}

/// Runs the live deployment `live` over `houses` (rows) of `table`, one trial at a time, exactly
/// as a robot would: choose, pay the chosen strategy's real cost, learn it with every
/// candidate's replay cost.
///
/// Exposed so that custom selectors ([`LiveDeployment::with_selector`]) can be evaluated on a
/// table the same way as the built-in ones.
///
/// # Errors
/// A house outside the table or a choice outside its strategies.
pub fn run_on_table(
    live: &mut LiveDeployment,
    table: &CostTable,
    houses: &[usize],
) -> Result<MethodRun, SelectError> {
    live.reserve(houses.len());
    let mut chosen = Vec::with_capacity(houses.len());
    let mut costs = Vec::with_capacity(houses.len());
    for &h in houses {
        let i = live.choose();
        let (cost, replay) = trial_costs(table, h, i)?;
        live.finish(cost, replay)?;
        chosen.push(i);
        costs.push(cost);
    }
    Ok(MethodRun {
        method: live.method(),
        chosen,
        costs,
        houses: None,
    })
}

/// The real cost of strategy `i` on row `h` (what was paid; its replay is equal) and every
/// candidate's replay cost given that `i` was deployed.
fn trial_costs(table: &CostTable, h: usize, i: usize) -> Result<(f64, &[f64]), SelectError> {
    if h >= table.n_houses() {
        return Err(SelectError::HouseOutOfRange {
            index: h,
            houses: table.n_houses(),
        });
    }
    let replay = table
        .replay_costs(h, i)
        .ok_or(SelectError::StrategyOutOfRange {
            index: i,
            strategies: table.n_strategies(),
        })?;
    Ok((table.cost_at(h, i), replay))
}

fn best_avg_cost(
    table: &CostTable,
    deployments: &[DeploymentRecord],
    best: usize,
    trials: usize,
) -> Vec<f64> {
    let mut avg = vec![0.0; trials];
    for dep in deployments {
        let mut sum = 0.0;
        for (k, &h) in dep.houses.iter().enumerate() {
            sum += table.cost_at(h, best);
            avg[k] += sum / (k + 1) as f64;
        }
    }
    let n = deployments.len() as f64;
    avg.iter_mut().for_each(|a| *a /= n);
    avg
}

fn summarise(
    table: &CostTable,
    deployments: &[DeploymentRecord],
    (best, best_mean): (usize, f64),
    trials: usize,
    method: Method,
) -> MethodSummary {
    let s = table.n_strategies();
    let mut avg_cost = vec![0.0; trials];
    let mut cum_regret = vec![0.0; trials];
    let mut counts = vec![vec![0usize; s]; trials];
    for dep in deployments {
        let Some(run) = dep.run(method) else {
            continue;
        };
        let mut sum = 0.0;
        let mut regret = 0.0;
        for (k, ((&h, &i), &c)) in dep
            .houses_of(method)
            .iter()
            .zip(&run.chosen)
            .zip(&run.costs)
            .enumerate()
        {
            sum += c;
            regret += c - table.cost_at(h, best);
            avg_cost[k] += sum / (k + 1) as f64;
            cum_regret[k] += regret;
            counts[k][i] += 1;
        }
    }
    let n = deployments.len() as f64;
    avg_cost.iter_mut().for_each(|a| *a /= n);
    cum_regret.iter_mut().for_each(|r| *r /= n);
    let paper_regret = avg_cost
        .iter()
        .scan(0.0, |sum, &a| {
            *sum += a - best_mean;
            Some(*sum)
        })
        .collect();
    let choice_fraction = counts
        .into_iter()
        .map(|row| row.into_iter().map(|c| c as f64 / n).collect())
        .collect();
    MethodSummary {
        method,
        avg_cost,
        cum_regret,
        paper_regret,
        choice_fraction,
    }
}
