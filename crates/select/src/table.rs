//! Real and replay costs of every candidate strategy on every house.

use std::collections::HashSet;

use crate::SelectError;

/// Largest accepted gap between the replay cost of the deployed strategy and its real cost,
/// relative to `max(1 m, |cost|)`.
///
/// Replay of the deployed strategy should reproduce its trial exactly; the tolerance only absorbs
/// floating-point summation order, so anything larger points at a bug in the replay.
pub const REPLAY_TOLERANCE: f64 = 1e-6;

/// Name that is never accepted as a candidate: the oracle knows where the target is.
pub const ORACLE: &str = "oracle";

/// Costs (metres) of every candidate strategy on one trial per house, real and replayed.
///
/// * `cost[h][i]`: real cost of strategy `i` deployed on house `h`'s trial.
/// * `replay[h][j][i]`: replay cost of strategy `i` given that strategy `j` was deployed on house
///   `h`; `replay[h][j][j] == cost[h][j]`.
///
/// The table is what a deployment experiment draws trials from. Shapes and finiteness are checked
/// once, at construction, so that selection itself never fails on a table.
#[derive(Debug, Clone, PartialEq)]
pub struct CostTable {
    strategies: Vec<String>,
    houses: Vec<String>,
    /// Row-major `[house][strategy]`.
    cost: Vec<f64>,
    /// Row-major `[house][deployed][strategy]`.
    replay: Vec<f64>,
    /// The house each row's trial was run in, when rows are trials of several targets per house
    /// (see [`CostTable::grouped`]); `None` when every row is a house of its own.
    groups: Option<Vec<usize>>,
}

impl CostTable {
    /// Builds a table from nested rows, validating it.
    ///
    /// Errors: no strategies or houses, duplicate names, `oracle` among the strategies, rows of
    /// the wrong length, non-finite costs, or a replay of the deployed strategy that differs from
    /// its real cost by more than [`REPLAY_TOLERANCE`].
    ///
    /// ```
    /// use ferret_select::CostTable;
    /// let table = CostTable::new(
    ///     vec!["a".into(), "b".into()],
    ///     vec!["house-0".into()],
    ///     vec![vec![3.0, 5.0]],
    ///     vec![vec![vec![3.0, 6.0], vec![4.0, 5.0]]],
    /// )?;
    /// assert_eq!(table.replay_costs(0, 1), Some(&[4.0, 5.0][..]));
    /// # Ok::<(), ferret_select::SelectError>(())
    /// ```
    pub fn new(
        strategies: Vec<String>,
        houses: Vec<String>,
        cost: Vec<Vec<f64>>,
        replay: Vec<Vec<Vec<f64>>>,
    ) -> Result<Self, SelectError> {
        check_names(&strategies, &houses)?;
        let flat_cost = flatten_costs(&cost, strategies.len(), houses.len())?;
        let s = strategies.len();
        check_len("replay houses", houses.len(), replay.len())?;
        let mut flat_replay = Vec::with_capacity(houses.len() * s * s);
        for (h, by_deployed) in replay.iter().enumerate() {
            check_len(&format!("replay rows of house {h}"), s, by_deployed.len())?;
            for (j, row) in by_deployed.iter().enumerate() {
                check_len(
                    &format!("replay costs of house {h} with strategy {j} deployed"),
                    s,
                    row.len(),
                )?;
                for (i, &value) in row.iter().enumerate() {
                    if !value.is_finite() {
                        return Err(SelectError::NonFiniteReplay {
                            house: h,
                            deployed: j,
                            strategy: i,
                            value,
                        });
                    }
                }
                let real = flat_cost[h * s + j];
                let own = row[j];
                if (own - real).abs() > REPLAY_TOLERANCE * real.abs().max(1.0) {
                    return Err(SelectError::ReplayOfDeployed {
                        house: h,
                        strategy: j,
                        cost: real,
                        replay: own,
                    });
                }
                flat_replay.extend_from_slice(row);
            }
        }
        Ok(Self {
            strategies,
            houses,
            cost: flat_cost,
            replay: flat_replay,
            groups: None,
        })
    }

    /// Marks rows as trials of the same house: `groups[row]` is the row's house number. A
    /// deployment then draws distinct houses and one trial of each (a robot is not sent to the
    /// same house twice in a deployment), instead of distinct rows.
    ///
    /// Errors: `groups` of the wrong length.
    pub fn grouped(mut self, groups: Vec<usize>) -> Result<Self, SelectError> {
        check_len("row groups", self.houses.len(), groups.len())?;
        self.groups = Some(groups);
        Ok(self)
    }

    /// The rows of each house, in order of the house's first row: one row each unless the table
    /// is [`grouped`](CostTable::grouped).
    pub fn groups(&self) -> Vec<Vec<usize>> {
        match &self.groups {
            None => (0..self.houses.len()).map(|h| vec![h]).collect(),
            Some(g) => {
                let mut order: Vec<usize> = Vec::new();
                let mut rows: std::collections::HashMap<usize, Vec<usize>> =
                    std::collections::HashMap::new();
                for (row, &house) in g.iter().enumerate() {
                    let entry = rows.entry(house).or_default();
                    if entry.is_empty() {
                        order.push(house);
                    }
                    entry.push(row);
                }
                order
                    .into_iter()
                    .map(|h| rows.remove(&h).unwrap_or_default())
                    .collect()
            }
        }
    }

    /// Number of distinct houses: rows, unless the table is grouped.
    pub fn n_groups(&self) -> usize {
        match &self.groups {
            None => self.houses.len(),
            Some(g) => g.iter().collect::<HashSet<_>>().len(),
        }
    }

    /// Builds a table whose replay costs equal the real costs (`replay[h][j][i] = cost[h][i]`):
    /// a perfect replay, as for synthetic bandits and for checking selection in isolation.
    pub fn with_exact_replay(
        strategies: Vec<String>,
        houses: Vec<String>,
        cost: Vec<Vec<f64>>,
    ) -> Result<Self, SelectError> {
        check_names(&strategies, &houses)?;
        let flat_cost = flatten_costs(&cost, strategies.len(), houses.len())?;
        let s = strategies.len();
        let mut replay = Vec::with_capacity(flat_cost.len() * s);
        for row in flat_cost.chunks_exact(s) {
            for _ in 0..s {
                replay.extend_from_slice(row);
            }
        }
        Ok(Self {
            strategies,
            houses,
            cost: flat_cost,
            replay,
            groups: None,
        })
    }

    /// Candidate strategy names, in index order.
    pub fn strategies(&self) -> &[String] {
        &self.strategies
    }

    /// House labels, in index order.
    pub fn houses(&self) -> &[String] {
        &self.houses
    }

    /// Number of candidate strategies (at least 1).
    pub fn n_strategies(&self) -> usize {
        self.strategies.len()
    }

    /// Number of houses (at least 1).
    pub fn n_houses(&self) -> usize {
        self.houses.len()
    }

    /// Index of a strategy by name.
    pub fn strategy_index(&self, name: &str) -> Option<usize> {
        self.strategies.iter().position(|s| s == name)
    }

    /// Real costs of all strategies on house `house`, or `None` if out of range.
    pub fn costs(&self, house: usize) -> Option<&[f64]> {
        let s = self.n_strategies();
        self.cost.get(house * s..(house + 1) * s)
    }

    /// Replay costs of all strategies on house `house` given that `deployed` was deployed, or
    /// `None` if either index is out of range. Entry `deployed` is its real cost.
    pub fn replay_costs(&self, house: usize, deployed: usize) -> Option<&[f64]> {
        let s = self.n_strategies();
        if house >= self.n_houses() || deployed >= s {
            return None;
        }
        Some(self.replay_row(house, deployed))
    }

    /// Mean real cost of every strategy over all houses.
    pub fn mean_costs(&self) -> Vec<f64> {
        let s = self.n_strategies();
        let mut sums = vec![0.0; s];
        for row in self.cost.chunks_exact(s) {
            for (sum, &c) in sums.iter_mut().zip(row) {
                *sum += c;
            }
        }
        let n = self.n_houses() as f64;
        sums.into_iter().map(|sum| sum / n).collect()
    }

    /// The best single strategy: lowest mean real cost over all houses (lowest index on a tie).
    pub fn best_strategy(&self) -> usize {
        let means = self.mean_costs();
        let mut best = 0;
        for (i, &m) in means.iter().enumerate() {
            if m < means[best] {
                best = i;
            }
        }
        best
    }

    /// Real cost; indices are valid by construction of the callers in this crate.
    pub(crate) fn cost_at(&self, house: usize, strategy: usize) -> f64 {
        self.cost[house * self.n_strategies() + strategy]
    }

    pub(crate) fn replay_row(&self, house: usize, deployed: usize) -> &[f64] {
        let s = self.n_strategies();
        let start = (house * s + deployed) * s;
        &self.replay[start..start + s]
    }
}

fn check_names(strategies: &[String], houses: &[String]) -> Result<(), SelectError> {
    if strategies.is_empty() {
        return Err(SelectError::NoStrategies);
    }
    if houses.is_empty() {
        return Err(SelectError::NoHouses);
    }
    let mut seen = HashSet::new();
    for name in strategies {
        if name == ORACLE {
            return Err(SelectError::OracleCandidate);
        }
        if !seen.insert(name.as_str()) {
            return Err(SelectError::DuplicateStrategy(name.clone()));
        }
    }
    let mut seen = HashSet::new();
    for label in houses {
        if !seen.insert(label.as_str()) {
            return Err(SelectError::DuplicateHouse(label.clone()));
        }
    }
    Ok(())
}

fn check_len(what: &str, expected: usize, found: usize) -> Result<(), SelectError> {
    if expected == found {
        Ok(())
    } else {
        Err(SelectError::Shape {
            what: what.to_owned(),
            expected,
            found,
        })
    }
}

fn flatten_costs(
    cost: &[Vec<f64>],
    strategies: usize,
    houses: usize,
) -> Result<Vec<f64>, SelectError> {
    check_len("cost rows", houses, cost.len())?;
    let mut flat = Vec::with_capacity(houses * strategies);
    for (h, row) in cost.iter().enumerate() {
        check_len(&format!("costs of house {h}"), strategies, row.len())?;
        for (i, &value) in row.iter().enumerate() {
            if !value.is_finite() {
                return Err(SelectError::NonFiniteCost {
                    house: h,
                    strategy: i,
                    value,
                });
            }
        }
        flat.extend_from_slice(row);
    }
    Ok(flat)
}
