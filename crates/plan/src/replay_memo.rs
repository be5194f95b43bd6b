//! The memo of offline replays: costs already computed in one house from one start, kept by
//! whoever serves many trials there. It sits beside [`SearchProblem`](crate::SearchProblem),
//! which carries it, and below [`replay`](crate::replay), which fills it.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

use ferret_world::TravelCost;

use crate::error::PlanError;

/// Pessimistic replay costs already computed in one house seen from one start.
///
/// A fleet's robots search the same house for the same things from the same dock, so the same
/// trial ends the same way again and again; each end replays every other candidate, which is a
/// whole simulated search (an exact planner's one solves a Held–Karp problem per decision).
/// Under the pessimistic hindsight belief a replay depends only on the house, the start (both
/// fixed by whoever owns the memo), the trial (task, containers revealed), the containers its
/// targets were found in, the strategy and the travel cost; the last five are the key, the
/// strategy by name. So a memo must not outlive what its strategies' names mean (the registry
/// that built them) nor be shared between houses or starts. Counterfactual replays, which also
/// depend on the true world, are never kept.
///
/// Bounded by entry count (a key and a cost, about a hundred bytes): once full, new replays are
/// computed and not kept.
#[derive(Debug)]
pub struct ReplayMemo {
    capacity: usize,
    /// One slot per key, filled by whichever end of that trial replays it first; the others
    /// wait on the slot instead of replaying the same thing at once (a fleet's robots that set
    /// out together end together).
    slots: Mutex<HashMap<ReplayKey, Slot>>,
    hits: AtomicU64,
}

type Slot = Arc<Mutex<Option<f64>>>;

#[derive(Debug, Hash, PartialEq, Eq)]
pub(crate) struct ReplayKey {
    pub(crate) strategy: String,
    /// The task as written (targets, goal, destination).
    pub(crate) task: String,
    pub(crate) revealed: Vec<usize>,
    /// Where each target was found.
    pub(crate) found: Vec<Option<usize>>,
    pub(crate) travel: TravelCost,
}

impl ReplayMemo {
    /// A memo keeping at most `capacity` replay costs (0 keeps none).
    pub fn new(capacity: usize) -> Self {
        Self {
            capacity,
            slots: Mutex::default(),
            hits: AtomicU64::new(0),
        }
    }

    /// Most replay costs kept.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Replay costs kept.
    pub fn len(&self) -> usize {
        let slots: Vec<Slot> = self.lock().values().cloned().collect();
        slots.iter().filter(|s| lock(s).is_some()).count()
    }

    /// True when no replay cost is kept.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Replays answered from the memo so far.
    pub fn hits(&self) -> u64 {
        self.hits.load(Ordering::Relaxed)
    }

    fn lock(&self) -> MutexGuard<'_, HashMap<ReplayKey, Slot>> {
        lock(&self.slots)
    }

    /// The kept cost of `key` (and true), else `replay`'s (and false), kept when there is
    /// room. A replay of the same key under way elsewhere is waited for, not repeated; one
    /// that fails leaves the slot empty for the next to try.
    pub(crate) fn get_or_replay(
        &self,
        key: ReplayKey,
        replay: impl FnOnce() -> Result<f64, PlanError>,
    ) -> Result<(f64, bool), PlanError> {
        let Some(slot) = self.slot(key) else {
            return Ok((replay()?, false));
        };
        let mut cost = lock(&slot);
        if let Some(c) = *cost {
            self.hits.fetch_add(1, Ordering::Relaxed);
            return Ok((c, true));
        }
        let c = replay()?;
        *cost = Some(c);
        Ok((c, false))
    }

    /// Keeps `replay`'s cost for `key` unless one is kept already or there is no room.
    pub(crate) fn fill(
        &self,
        key: ReplayKey,
        replay: impl FnOnce() -> Result<f64, PlanError>,
    ) -> Result<(), PlanError> {
        if let Some(slot) = self.slot(key) {
            let mut cost = lock(&slot);
            if cost.is_none() {
                *cost = Some(replay()?);
            }
        }
        Ok(())
    }

    /// The slot of `key`, made when there is room; `None` when there is none.
    fn slot(&self, key: ReplayKey) -> Option<Slot> {
        let mut slots = self.lock();
        if let Some(s) = slots.get(&key) {
            return Some(s.clone());
        }
        if slots.len() >= self.capacity {
            return None;
        }
        let s = Slot::default();
        slots.insert(key, s.clone());
        Some(s)
    }
}

/// Locks `m`; a poisoned lock still guards whole values (each is written in one assignment).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}
