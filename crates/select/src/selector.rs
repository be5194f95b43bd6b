//! Bandit selectors: UCB (paper eq. 2) and replay selection (paper eq. 5).
//!
//! Costs are minimised, so the "upper confidence bound" of the paper is a lower bound on the
//! expected cost: `mean_cost_i − c·sqrt(ln k / n_i)`.
//!
//! Conventions shared by both selectors:
//! * `k` is the number of trials observed so far. The choice for trial `k + 1` uses the
//!   statistics of trials `1..=k`, as in the paper.
//! * `n_i ≤ k`, so whenever the bonus `sqrt(ln k / n_i)` is evaluated, `n_i ≥ 1` and `k ≥ 1`;
//!   `ln 1 = 0`, so after a single trial the bonus of the one strategy tried is zero (its score is
//!   its cost). `ln 0` never occurs.
//! * A strategy never deployed (`n_i = 0`) has an unbounded bonus: its UCB score is `−∞`.
//! * The strategy with the lowest score is chosen; exact ties are broken uniformly at random with
//!   the caller's RNG (the RNG is only drawn from when there is a tie).

use std::fmt;
use std::str::FromStr;

use rand::{Rng, RngCore};
use serde::{Deserialize, Serialize};

use crate::SelectError;

/// Per-strategy statistics of a deployment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StrategyStats {
    /// Trials in which this strategy was deployed (`n_i`).
    pub deployed: usize,
    /// Mean cost over those trials, metres; `None` before its first.
    pub mean_cost: Option<f64>,
    /// Mean over all trials of its real cost where deployed and its replay cost elsewhere
    /// (`None` before the first trial).
    pub replay_mean: Option<f64>,
    /// Its selection score for the next trial (lower is chosen; `-inf` means "must be tried",
    /// serialized as `null` in JSON).
    pub score: f64,
}

/// Default exploration constant `c` in metres: the paper's 100 grid cells of 0.05 m.
pub const DEFAULT_C: f64 = 5.0;

/// A bandit that picks the strategy for the next trial and learns from each finished trial.
///
/// One trial at a time and no look-ahead, so the same selector drives both the offline deployment
/// experiment and a live robot loop:
///
/// ```
/// use ferret_select::{ReplaySelection, Selector};
/// use rand::SeedableRng;
/// let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
/// let mut selector = ReplaySelection::new(3, 5.0)?;
/// for _ in 0..10 {
///     let chosen = selector.choose(&mut rng);
///     // Deploy `chosen`, measure its cost, then replay every strategy on the same trial.
///     let replay = [12.0, 20.0, 30.0];
///     selector.observe(chosen, replay[chosen], &replay)?;
/// }
/// assert_eq!(selector.choose(&mut rng), 0);
/// # Ok::<(), ferret_select::SelectError>(())
/// ```
pub trait Selector {
    /// Which selection method this is.
    fn method(&self) -> Method;

    /// Number of candidate strategies.
    fn n_strategies(&self) -> usize;

    /// Number of trials observed so far (`k`).
    fn trials(&self) -> usize;

    /// Selection score of strategy `i` for the next trial (lower is better; `−∞` means "must be
    /// tried"). Out-of-range indices give NaN.
    fn score(&self, i: usize) -> f64;

    /// Selection scores of all strategies for the next trial.
    fn scores(&self) -> Vec<f64> {
        (0..self.n_strategies()).map(|i| self.score(i)).collect()
    }

    /// Strategy for the next trial: the lowest score, exact ties broken uniformly with `rng`.
    fn choose(&mut self, rng: &mut dyn RngCore) -> usize {
        argmin_random_tie(self.n_strategies(), |i| self.score(i), rng)
    }

    /// Strategy for the next trial: the lowest score; among `t > 1` exact ties (in index order)
    /// the one at `pick(t)`, which must be below `t`. For another generator's tie-breaks, such
    /// as the reference code's numpy `choice`.
    fn choose_with(&mut self, pick: &mut dyn FnMut(usize) -> usize) -> usize {
        argmin_tie(self.n_strategies(), |i| self.score(i), pick)
    }

    /// Records a finished trial: strategy `chosen` was deployed and cost `cost` metres.
    ///
    /// `replay_costs[i]` is the replay cost of strategy `i` on this trial given that `chosen`
    /// was deployed. Entry `chosen` is not read (the real `cost` is used instead). UCB ignores
    /// `replay_costs` entirely, so it may pass an empty slice.
    ///
    /// Errors (nothing is recorded): `chosen` out of range, a non-finite cost, or (replay
    /// selection) a replay slice of the wrong length or with a non-finite entry.
    fn observe(
        &mut self,
        chosen: usize,
        cost: f64,
        replay_costs: &[f64],
    ) -> Result<(), SelectError>;

    /// Why strategy `name`, whose statistics are `stats`, has the lowest score, in one sentence
    /// for a person watching a deployment (called after at least one trial).
    fn why_lowest(&self, name: &str, stats: &StrategyStats) -> String {
        format!(
            "{name}: lowest {} score {:.2} m",
            self.method().label(),
            stats.score
        )
    }
}

/// A selection method, as named in reports and on the command line.
///
/// This enum is the registry of selectors: a new one is a type implementing [`Selector`] plus
/// a variant here, with its [`name`](Method::name), [`label`](Method::label),
/// [`short_label`](Method::short_label) and
/// [`configured`](Method::configured) constructor. Everything else — the deployment
/// experiment, its tables and pictures, live deployments, `ferret deploy` and `ferret serve` —
/// goes through [`Method::ALL`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum Method {
    /// Black-box UCB on deployed costs only (paper eq. 2).
    #[serde(rename = "ucb")]
    Ucb,
    /// UCB constrained from below by offline replay costs (paper eq. 5).
    #[serde(rename = "replay")]
    ReplaySelection,
}

impl Method {
    /// Every method, in report order: the first is the baseline the others are compared with.
    pub const ALL: [Method; 2] = [Method::Ucb, Method::ReplaySelection];

    /// Short machine name (`ucb`, `replay`), used in CSV files, on the command line and in the
    /// HTTP API.
    pub fn name(self) -> &'static str {
        match self {
            Method::Ucb => "ucb",
            Method::ReplaySelection => "replay",
        }
    }

    /// The method whose [`name`](Method::name) is exactly `name`.
    pub fn from_name(name: &str) -> Option<Method> {
        Method::ALL.into_iter().find(|m| m.name() == name)
    }

    /// Human label as in the paper's table.
    pub fn label(self) -> &'static str {
        match self {
            Method::Ucb => "UCB selection",
            Method::ReplaySelection => "Replay selection",
        }
    }

    /// A short label for comparisons ("Replay vs. UCB").
    pub fn short_label(self) -> &'static str {
        match self {
            Method::Ucb => "UCB",
            Method::ReplaySelection => "Replay",
        }
    }

    /// A fresh selector of this method over `strategies` candidates with exploration constant
    /// `c` (metres), in its default variant.
    pub fn selector(
        self,
        strategies: usize,
        c: f64,
    ) -> Result<Box<dyn Selector + Send>, SelectError> {
        self.configured(strategies, c, SelectorVariant::default())
    }

    /// A fresh selector of this method over `strategies` candidates with exploration constant
    /// `c` (metres) in `variant` (the reference code's switches).
    pub fn configured(
        self,
        strategies: usize,
        c: f64,
        variant: SelectorVariant,
    ) -> Result<Box<dyn Selector + Send>, SelectError> {
        Ok(match self {
            Method::Ucb => Box::new(Ucb::new(strategies, c)?.untried_score(
                if variant.ucb_untried_zero {
                    0.0
                } else {
                    f64::NEG_INFINITY
                },
            )),
            Method::ReplaySelection => Box::new(
                ReplaySelection::new(strategies, c)?.untried_first(variant.replay_untried_first),
            ),
        })
    }
}

/// How a selector treats strategies it has not deployed yet. The default is the paper's: UCB
/// deploys each once first, replay selection trusts replay costs from the start.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct SelectorVariant {
    /// Replay selection deploys every strategy once first, as UCB does (see
    /// [`ReplaySelection::untried_first`]).
    pub replay_untried_first: bool,
    /// UCB scores untried strategies 0, as the reference code does (see
    /// [`Ucb::untried_score`]).
    pub ucb_untried_zero: bool,
}

impl fmt::Display for Method {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl FromStr for Method {
    type Err = SelectError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s == "replay-selection" {
            return Ok(Method::ReplaySelection);
        }
        Method::from_name(s).ok_or_else(|| SelectError::InvalidOption {
            name: "method",
            reason: format!(
                "unknown method `{s}` (expected {})",
                Method::ALL.map(|m| format!("`{}`", m.name())).join(" or ")
            ),
        })
    }
}

/// Deployed-cost statistics shared by both selectors.
#[derive(Debug, Clone, PartialEq)]
struct Deployed {
    c: f64,
    trials: usize,
    pulls: Vec<usize>,
    cost_sum: Vec<f64>,
}

impl Deployed {
    fn new(strategies: usize, c: f64) -> Result<Self, SelectError> {
        if strategies == 0 {
            return Err(SelectError::NoStrategies);
        }
        check_c(c)?;
        Ok(Self {
            c,
            trials: 0,
            pulls: vec![0; strategies],
            cost_sum: vec![0.0; strategies],
        })
    }

    /// `mean_cost_i − c·sqrt(ln k / n_i)`, `−∞` for an untried strategy.
    fn lower_bound(&self, i: usize) -> f64 {
        let n = self.pulls[i];
        if n == 0 {
            return f64::NEG_INFINITY;
        }
        let n = n as f64;
        // k ≥ n ≥ 1 here, so ln k ≥ 0.
        let k = self.trials as f64;
        self.cost_sum[i] / n - self.c * (k.ln() / n).sqrt()
    }

    fn check(&self, chosen: usize, cost: f64) -> Result<(), SelectError> {
        if chosen >= self.pulls.len() {
            return Err(SelectError::StrategyOutOfRange {
                index: chosen,
                strategies: self.pulls.len(),
            });
        }
        if !cost.is_finite() {
            return Err(SelectError::NonFiniteObservation {
                strategy: chosen,
                value: cost,
            });
        }
        Ok(())
    }

    fn record(&mut self, chosen: usize, cost: f64) {
        self.trials += 1;
        self.pulls[chosen] += 1;
        self.cost_sum[chosen] += cost;
    }
}

/// Validates the exploration constant: finite and non-negative (0 is greedy).
pub(crate) fn check_c(c: f64) -> Result<(), SelectError> {
    if c.is_finite() && c >= 0.0 {
        Ok(())
    } else {
        Err(SelectError::InvalidOption {
            name: "c",
            reason: format!("exploration constant must be finite and >= 0, got {c}"),
        })
    }
}

/// UCB selection (paper eq. 2): `argmin_i mean_cost_i − c·sqrt(ln k / n_i)`.
///
/// By default every strategy is deployed once (in random order) before any is deployed twice.
/// [`Ucb::untried_score`] gives untried strategies a finite score instead, as the paper's
/// reference code does (its NaN and infinite scores become 0).
#[derive(Debug, Clone, PartialEq)]
pub struct Ucb {
    stats: Deployed,
    untried: f64,
}

impl Ucb {
    /// UCB over `strategies` candidates with exploration constant `c` metres.
    ///
    /// Errors: no strategies, or `c` negative or not finite.
    pub fn new(strategies: usize, c: f64) -> Result<Self, SelectError> {
        Ok(Self {
            stats: Deployed::new(strategies, c)?,
            untried: f64::NEG_INFINITY,
        })
    }

    /// The score of a strategy never deployed: `−∞` by default (each is tried once first); the
    /// reference code's 0 puts an untried strategy below every tried one whose lower bound is
    /// positive and above those whose bound is negative, so with cheap trials it may never be
    /// tried. A NaN is taken as 0.
    pub fn untried_score(mut self, score: f64) -> Self {
        self.untried = if score.is_nan() { 0.0 } else { score };
        self
    }

    /// How often each strategy has been deployed (`n_i`).
    pub fn pulls(&self) -> &[usize] {
        &self.stats.pulls
    }
}

impl Selector for Ucb {
    fn method(&self) -> Method {
        Method::Ucb
    }

    fn n_strategies(&self) -> usize {
        self.stats.pulls.len()
    }

    fn trials(&self) -> usize {
        self.stats.trials
    }

    fn score(&self, i: usize) -> f64 {
        if i >= self.n_strategies() {
            return f64::NAN;
        }
        if self.stats.pulls[i] == 0 {
            return self.untried;
        }
        self.stats.lower_bound(i)
    }

    fn observe(
        &mut self,
        chosen: usize,
        cost: f64,
        _replay_costs: &[f64],
    ) -> Result<(), SelectError> {
        self.stats.check(chosen, cost)?;
        self.stats.record(chosen, cost);
        Ok(())
    }

    fn why_lowest(&self, name: &str, stats: &StrategyStats) -> String {
        if stats.score == f64::NEG_INFINITY {
            return format!(
                "{name}: UCB deploys every strategy once, and it has not been deployed"
            );
        }
        format!(
            "{name}: lowest UCB score {:.2} m (mean cost {:.2} m over {} trial(s), less the exploration bonus)",
            stats.score,
            stats.mean_cost.unwrap_or(f64::NAN),
            stats.deployed
        )
    }
}

/// Replay selection (paper eq. 5):
/// `argmin_i max(replay_mean_i, mean_cost_i − c·sqrt(ln k / n_i))`.
///
/// `replay_mean_i` averages over all `k` trials the real cost where `i` was deployed and its
/// replay cost elsewhere. Replay costs are pessimistic, so they bound the optimistic UCB score
/// from below and rule out poor strategies without deploying them.
///
/// Untried strategies: their UCB term is `−∞`, so their score is their replay mean — they are
/// deployed only when replay says they may be best. This follows the paper's reference
/// implementation and is the point of replay selection. [`ReplaySelection::untried_first`]
/// switches to UCB's "deploy every strategy once first" instead. Before the first trial nothing
/// is known and the choice is uniform.
#[derive(Debug, Clone, PartialEq)]
pub struct ReplaySelection {
    stats: Deployed,
    replay_sum: Vec<f64>,
    untried_first: bool,
}

impl ReplaySelection {
    /// Replay selection over `strategies` candidates with exploration constant `c` metres.
    ///
    /// Errors: no strategies, or `c` negative or not finite.
    pub fn new(strategies: usize, c: f64) -> Result<Self, SelectError> {
        Ok(Self {
            stats: Deployed::new(strategies, c)?,
            replay_sum: vec![0.0; strategies],
            untried_first: false,
        })
    }

    /// When `true`, every strategy is deployed once before replay costs are trusted, as in UCB.
    /// Default `false` (see the type's documentation).
    pub fn untried_first(mut self, yes: bool) -> Self {
        self.untried_first = yes;
        self
    }

    /// How often each strategy has been deployed (`n_i`).
    pub fn pulls(&self) -> &[usize] {
        &self.stats.pulls
    }

    /// `replay_mean_i` over the trials so far, or `None` before the first trial.
    pub fn replay_mean(&self, i: usize) -> Option<f64> {
        let sum = self.replay_sum.get(i)?;
        (self.stats.trials > 0).then(|| sum / self.stats.trials as f64)
    }
}

impl Selector for ReplaySelection {
    fn method(&self) -> Method {
        Method::ReplaySelection
    }

    fn n_strategies(&self) -> usize {
        self.stats.pulls.len()
    }

    fn trials(&self) -> usize {
        self.stats.trials
    }

    fn score(&self, i: usize) -> f64 {
        if i >= self.n_strategies() {
            return f64::NAN;
        }
        if self.stats.trials == 0 || (self.untried_first && self.stats.pulls[i] == 0) {
            return f64::NEG_INFINITY;
        }
        let replay_mean = self.replay_sum[i] / self.stats.trials as f64;
        replay_mean.max(self.stats.lower_bound(i))
    }

    fn observe(
        &mut self,
        chosen: usize,
        cost: f64,
        replay_costs: &[f64],
    ) -> Result<(), SelectError> {
        self.stats.check(chosen, cost)?;
        if replay_costs.len() != self.n_strategies() {
            return Err(SelectError::Shape {
                what: "replay costs of a trial".to_owned(),
                expected: self.n_strategies(),
                found: replay_costs.len(),
            });
        }
        if let Some((i, &value)) = replay_costs
            .iter()
            .enumerate()
            .find(|&(i, v)| i != chosen && !v.is_finite())
        {
            return Err(SelectError::NonFiniteObservation { strategy: i, value });
        }
        self.stats.record(chosen, cost);
        for (i, (sum, &replay)) in self.replay_sum.iter_mut().zip(replay_costs).enumerate() {
            *sum += if i == chosen { cost } else { replay };
        }
        Ok(())
    }

    fn why_lowest(&self, name: &str, stats: &StrategyStats) -> String {
        format!(
            "{name}: lowest replay-selection score {:.2} m (replay mean {:.2} m over {} trial(s); deployed {} time(s))",
            stats.score,
            stats.replay_mean.unwrap_or(f64::NAN),
            self.stats.trials,
            stats.deployed
        )
    }
}

/// Index of the smallest `score(i)` for `i in 0..n`; exact ties are broken uniformly with `rng`,
/// which is drawn from only when there is a tie. NaN scores are never chosen unless all are NaN.
pub(crate) fn argmin_random_tie(
    n: usize,
    score: impl Fn(usize) -> f64,
    rng: &mut dyn RngCore,
) -> usize {
    argmin_tie(n, score, &mut |ties| rng.random_range(0..ties))
}

/// Index of the smallest `score(i)`; among `t > 1` exact ties, the `pick(t)`-th in index order
/// (`pick` is called only for ties). NaN scores are never chosen unless all are NaN.
pub(crate) fn argmin_tie(
    n: usize,
    score: impl Fn(usize) -> f64,
    pick: &mut dyn FnMut(usize) -> usize,
) -> usize {
    let mut best: Option<(f64, usize)> = None;
    let mut ties = 0usize;
    for i in 0..n {
        let s = score(i);
        match best {
            _ if s.is_nan() => {}
            Some((b, _)) if s == b => ties += 1,
            Some((b, _)) if s > b => {}
            _ => {
                best = Some((s, i));
                ties = 1;
            }
        }
    }
    let Some((best, first)) = best else {
        return 0;
    };
    if ties == 1 {
        return first;
    }
    let mut pick = pick(ties);
    for i in first..n {
        if score(i) == best {
            if pick == 0 {
                return i;
            }
            pick -= 1;
        }
    }
    first
}
