//! A live deployment: the selector between a robot's trials. It picks the strategy for the next
//! trial and learns from each finished one (its cost and every candidate's replay cost).
//!
//! Everything it knows is the list of finished trials and its seed, so it can be rebuilt exactly
//! from storage after a restart: [`LiveDeployment::restore`] replays the same choices, drawing the
//! same tie-breaks from the same random stream. `ferret deploy`, `ferret serve` and the
//! deployment experiment all drive it.

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::SelectError;
use crate::selector::{Method, Selector, StrategyStats};

/// A finished trial as selection sees it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FinishedTrial {
    /// Index of the deployed strategy.
    pub chosen: usize,
    /// Its cost, metres.
    pub cost: f64,
    /// Every candidate's replay cost on this trial (entry `chosen` equals `cost`).
    pub replays: Vec<f64>,
}

/// How a trial of a live deployment ended.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum TrialEnd {
    /// The target was found; selection learned from it.
    Finished(FinishedTrial),
    /// It ended without a cost to learn from (the target was nowhere); only its choice is kept,
    /// since making that choice may have drawn a tie-break.
    Abandoned {
        /// Index of the strategy that was chosen.
        chosen: usize,
    },
}

/// What happened in a deployment whose trials may overlap (several robots sharing it), in the
/// order it happened: a trial started with a choice, or a trial ended.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum DeploymentEvent {
    /// A trial started with this strategy, chosen from the trials ended so far.
    Started {
        /// Index of the chosen strategy.
        chosen: usize,
    },
    /// A trial (any open one) ended.
    Ended(TrialEnd),
}

/// A live deployment's selector state.
pub struct LiveDeployment {
    method: Method,
    c: f64,
    seed: Option<u64>,
    selector: Box<dyn Selector + Send>,
    rng: ChaCha8Rng,
    /// How each trial ended; the replays of finished ones are in `replays`, in order, so that a
    /// trial costs no allocation of its own (the deployment experiment runs 10⁵ of them).
    ends: Vec<End>,
    replays: Vec<f64>,
    /// The choice made for the trial in progress, if any.
    pending: Option<usize>,
    /// Trials started by [`choose_overlapping`](Self::choose_overlapping), so that a history
    /// replayed in pieces checks each end against the starts before it.
    started: usize,
}

/// A trial's end as stored: a [`TrialEnd`] without its replay costs.
#[derive(Clone, Copy, Debug)]
enum End {
    Finished {
        chosen: usize,
        cost: f64,
        /// How many replay costs it has in `LiveDeployment::replays`.
        replays: usize,
    },
    Abandoned {
        chosen: usize,
    },
}

impl std::fmt::Debug for LiveDeployment {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LiveDeployment")
            .field("method", &self.method)
            .field("c", &self.c)
            .field("seed", &self.seed)
            .field("finished", &self.finished_parts().count())
            .field("pending", &self.pending)
            .finish()
    }
}

impl LiveDeployment {
    /// A new deployment over `strategies` candidates.
    ///
    /// # Errors
    /// No strategies, or `c` negative or not finite.
    pub fn new(method: Method, strategies: usize, c: f64, seed: u64) -> Result<Self, SelectError> {
        let mut d = Self::with_selector(
            method.selector(strategies, c)?,
            c,
            ChaCha8Rng::seed_from_u64(seed),
        );
        d.seed = Some(seed);
        Ok(d)
    }

    /// A deployment of a configured `selector` (exploration constant `c`) whose tie-breaks come
    /// from `ties`: how the deployment experiment runs each method on its own stream, and how a
    /// custom selector runs the same loop.
    pub fn with_selector(selector: Box<dyn Selector + Send>, c: f64, ties: ChaCha8Rng) -> Self {
        Self {
            method: selector.method(),
            c,
            seed: None,
            selector,
            rng: ties,
            ends: Vec::new(),
            replays: Vec::new(),
            pending: None,
            started: 0,
        }
    }

    /// Rebuilds a deployment from how its trials ended (in order) and, if one is in progress,
    /// the strategy chosen for it. The choices are made again and must match the stored ones.
    ///
    /// # Errors
    /// [`SelectError::Live`] when a stored choice differs from the one the selector makes now
    /// (the stored data or the code changed), and the errors of [`LiveDeployment::finish`].
    pub fn restore(
        method: Method,
        strategies: usize,
        c: f64,
        seed: u64,
        history: &[TrialEnd],
        pending: Option<usize>,
    ) -> Result<Self, SelectError> {
        let mut d = Self::new(method, strategies, c, seed)?;
        for (k, end) in history.iter().enumerate() {
            let again = d.choose();
            let stored = match end {
                TrialEnd::Finished(t) => t.chosen,
                TrialEnd::Abandoned { chosen } => *chosen,
            };
            if again != stored {
                return Err(SelectError::Live(format!(
                    "trial {}: stored choice {stored} but the selector now chooses {again}",
                    k + 1
                )));
            }
            match end {
                TrialEnd::Finished(t) => d.finish(t.cost, &t.replays)?,
                TrialEnd::Abandoned { .. } => d.abandon()?,
            }
        }
        if let Some(p) = pending {
            let again = d.choose();
            if again != p {
                return Err(SelectError::Live(format!(
                    "open trial: stored choice {p} but the selector now chooses {again}"
                )));
            }
        }
        Ok(d)
    }

    /// Rebuilds a deployment whose trials may overlap from its events in the order they
    /// happened. Each start's choice is made again from the trials ended before it (drawing the
    /// same tie-breaks from the seed's stream, one draw per start in start order) and must match
    /// the stored one. A deployment of strictly sequential trials gives the same state as
    /// [`restore`](Self::restore); no trial is left pending (open trials are the caller's).
    ///
    /// # Errors
    /// [`SelectError::Live`] when a stored choice differs from the one the selector makes now,
    /// or more trials end than started; the errors of [`LiveDeployment::finish`].
    pub fn replay_events(
        method: Method,
        strategies: usize,
        c: f64,
        seed: u64,
        events: &[DeploymentEvent],
    ) -> Result<Self, SelectError> {
        let mut d = Self::new(method, strategies, c, seed)?;
        d.extend_events(events)?;
        Ok(d)
    }

    /// Goes on from the events already replayed (or made) with the ones that happened since, in
    /// order: each start's choice is made again and must match the stored one. Replaying a
    /// history in pieces gives the same state as replaying it at once, so a service can keep
    /// the state between requests and read only what is new.
    ///
    /// # Errors
    /// As [`replay_events`](Self::replay_events); the state is then partly advanced and should
    /// be dropped.
    pub fn extend_events(&mut self, events: &[DeploymentEvent]) -> Result<(), SelectError> {
        for event in events {
            match event {
                DeploymentEvent::Started { chosen } => {
                    let again = self.choose_overlapping();
                    if again != *chosen {
                        return Err(SelectError::Live(format!(
                            "trial {}: stored choice {chosen} but the selector now chooses {again}",
                            self.started
                        )));
                    }
                }
                DeploymentEvent::Ended(end) => {
                    if self.ends.len() >= self.started {
                        return Err(SelectError::Live(format!(
                            "end {} comes before any open trial started",
                            self.ends.len() + 1
                        )));
                    }
                    self.end_overlapping(end)?;
                }
            }
        }
        Ok(())
    }

    /// The strategy for a trial that may run alongside other open ones: chosen from the trials
    /// ended so far, each call a new trial (it draws the next tie-break; nothing is pending).
    pub fn choose_overlapping(&mut self) -> usize {
        self.started += 1;
        self.selector.choose(&mut self.rng)
    }

    /// Records the end of one of the open trials started by
    /// [`choose_overlapping`](Self::choose_overlapping).
    ///
    /// # Errors
    /// Costs that are not finite or replays of the wrong length (see
    /// [`finish`](Self::finish)).
    pub fn end_overlapping(&mut self, end: &TrialEnd) -> Result<(), SelectError> {
        match end {
            TrialEnd::Finished(t) => self.record_finished(t.chosen, t.cost, &t.replays),
            TrialEnd::Abandoned { chosen } => {
                self.ends.push(End::Abandoned { chosen: *chosen });
                Ok(())
            }
        }
    }

    /// Makes room for `trials` more trials, so that a deployment of known length grows its
    /// history once.
    pub fn reserve(&mut self, trials: usize) {
        self.ends.reserve(trials);
        self.replays
            .reserve(trials.saturating_mul(self.selector.n_strategies()));
    }

    /// Ends the trial in progress without learning from it.
    ///
    /// # Errors
    /// No trial in progress.
    pub fn abandon(&mut self) -> Result<(), SelectError> {
        let chosen = self.pending.take().ok_or_else(|| {
            SelectError::Live("no trial in progress: choose a strategy first".into())
        })?;
        self.ends.push(End::Abandoned { chosen });
        Ok(())
    }

    /// How every trial so far ended, in order.
    pub fn history(&self) -> Vec<TrialEnd> {
        let mut finished = self.finished();
        self.ends
            .iter()
            .filter_map(|end| match *end {
                End::Finished { .. } => finished.next().map(TrialEnd::Finished),
                End::Abandoned { chosen } => Some(TrialEnd::Abandoned { chosen }),
            })
            .collect()
    }

    /// The strategy for the next trial. Asking again before [`finish`](Self::finish) returns the
    /// same choice.
    pub fn choose(&mut self) -> usize {
        if let Some(p) = self.pending {
            return p;
        }
        let i = self.selector.choose(&mut self.rng);
        self.pending = Some(i);
        i
    }

    /// Like [`choose`](Self::choose), with ties among `t > 1` strategies broken by `pick(t)`
    /// instead of the deployment's stream (another generator's tie-breaks, such as the reference
    /// code's numpy `choice`).
    pub fn choose_with(&mut self, pick: &mut dyn FnMut(usize) -> usize) -> usize {
        if let Some(p) = self.pending {
            return p;
        }
        let i = self.selector.choose_with(pick);
        self.pending = Some(i);
        i
    }

    /// What [`choose`](Self::choose) would return, without committing to it; with no trial in
    /// progress, also what [`choose_overlapping`](Self::choose_overlapping) would return.
    pub fn peek(&self) -> usize {
        match self.pending {
            Some(p) => p,
            None => {
                let mut rng = self.rng.clone();
                crate::selector::argmin_random_tie(
                    self.selector.n_strategies(),
                    |i| self.selector.score(i),
                    &mut rng,
                )
            }
        }
    }

    /// Records the trial in progress: its strategy cost `cost` metres and the candidates' replay
    /// costs (`replays[chosen]` is ignored in favour of `cost`).
    ///
    /// # Errors
    /// No trial in progress, a non-finite cost, replays of the wrong length.
    pub fn finish(&mut self, cost: f64, replays: &[f64]) -> Result<(), SelectError> {
        let chosen = self.pending.ok_or_else(|| {
            SelectError::Live("no trial in progress: choose a strategy first".into())
        })?;
        self.record_finished(chosen, cost, replays)?;
        self.pending = None;
        Ok(())
    }

    /// The selector learns a finished trial of `chosen` and it joins the history.
    fn record_finished(
        &mut self,
        chosen: usize,
        cost: f64,
        replays: &[f64],
    ) -> Result<(), SelectError> {
        self.selector.observe(chosen, cost, replays)?;
        let start = self.replays.len();
        self.replays.extend_from_slice(replays);
        if let Some(r) = self.replays[start..].get_mut(chosen) {
            *r = cost;
        }
        self.ends.push(End::Finished {
            chosen,
            cost,
            replays: replays.len(),
        });
        Ok(())
    }

    /// The selection method.
    pub fn method(&self) -> Method {
        self.method
    }

    /// The exploration constant, metres.
    pub fn c(&self) -> f64 {
        self.c
    }

    /// The seed of the tie-breaking stream, when the deployment was made from one.
    pub fn seed(&self) -> Option<u64> {
        self.seed
    }

    /// The finished trials, in order (the abandoned ones left out).
    pub fn finished(&self) -> impl Iterator<Item = FinishedTrial> + '_ {
        self.finished_parts()
            .map(|(chosen, cost, replays)| FinishedTrial {
                chosen,
                cost,
                replays: replays.to_vec(),
            })
    }

    /// The finished trials as (chosen, cost, replays) without copying.
    fn finished_parts(&self) -> impl Iterator<Item = (usize, f64, &[f64])> + '_ {
        let mut at = 0;
        self.ends.iter().filter_map(move |end| match *end {
            End::Finished {
                chosen,
                cost,
                replays,
            } => {
                let r = &self.replays[at..at + replays];
                at += replays;
                Some((chosen, cost, r))
            }
            End::Abandoned { .. } => None,
        })
    }

    /// The choice of the trial in progress.
    pub fn pending(&self) -> Option<usize> {
        self.pending
    }

    /// Per-strategy statistics and scores for the next choice.
    pub fn stats(&self) -> Vec<StrategyStats> {
        let n = self.selector.n_strategies();
        let k = self.finished_parts().count();
        (0..n)
            .map(|i| {
                let own: Vec<f64> = self
                    .finished_parts()
                    .filter(|t| t.0 == i)
                    .map(|t| t.1)
                    .collect();
                let replay_sum: f64 = self
                    .finished_parts()
                    .map(|t| t.2.get(i).copied().unwrap_or(f64::NAN))
                    .sum();
                StrategyStats {
                    deployed: own.len(),
                    mean_cost: (!own.is_empty())
                        .then(|| own.iter().sum::<f64>() / own.len() as f64),
                    replay_mean: (k > 0).then(|| replay_sum / k as f64),
                    score: self.selector.score(i),
                }
            })
            .collect()
    }

    /// Why [`peek`](Self::peek) picks what it picks, in one sentence.
    pub fn why(&self, names: &[String]) -> String {
        let next = self.peek();
        let name = names.get(next).map_or("?", String::as_str);
        if self.pending.is_some() {
            return format!("{name} was chosen for the trial in progress");
        }
        if self.finished_parts().next().is_none() {
            return format!(
                "{name}: nothing is known before the first trial, so the choice is uniform"
            );
        }
        match self.stats().get(next) {
            Some(s) => self.selector.why_lowest(name, s),
            None => format!("{name}: no statistics"),
        }
    }
}
