//! First steps of exact plans, kept per house and shared by its searches. A model strategy
//! plans over a candidate set by solving a Held–Karp table (16 candidates: 2¹⁶ rows, the most
//! costly part of a search and of every replay), and each new position brings a new candidate
//! set, so a search solves at most of its decisions. The table depends on the candidates,
//! their probabilities and the travel between them, not on where the robot stands; the
//! decision from where it stands reads one entry per candidate. So a search that meets a
//! candidate set another search of the same house solved before takes its decision from those
//! entries, exactly as the table would give it, and solves the table only if it then follows
//! the plan further (when its next candidate set is this one less what it searched).

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};

use crate::planner::{Solution, TourProblem};

/// The first steps of solved tables, for one house's travel distances between containers
/// (share it only between searches of the same house on the same grid). Bounded by entry
/// count (a set of 16 candidates is about 500 bytes): once full, it starts again empty.
#[derive(Debug)]
pub struct PlanMemo {
    capacity: usize,
    steps: Mutex<HashMap<PlanKey, Arc<[f64]>>>,
    hits: AtomicU64,
}

/// What a table depends on besides the house: the candidates (container indices, ascending),
/// their probabilities and the search cost, as bits.
#[derive(Debug, Hash, PartialEq, Eq)]
struct PlanKey {
    candidates: Vec<usize>,
    p: Vec<u64>,
    search_cost: u64,
}

impl PlanKey {
    fn new(candidates: &[usize], problem: &TourProblem) -> Self {
        Self {
            candidates: candidates.to_vec(),
            p: problem.p.iter().map(|p| p.get().to_bits()).collect(),
            search_cost: problem.search_cost.to_bits(),
        }
    }
}

impl PlanMemo {
    /// A memo keeping the first steps of at most `capacity` candidate sets (0 keeps none).
    pub fn new(capacity: usize) -> Self {
        Self {
            capacity,
            steps: Mutex::default(),
            hits: AtomicU64::new(0),
        }
    }

    /// Most candidate sets kept.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Decisions taken from the memo instead of a solved table so far.
    pub fn hits(&self) -> u64 {
        self.hits.load(Ordering::Relaxed)
    }

    /// The first steps of the table of `problem` over `candidates`, when one was kept.
    pub(crate) fn first_steps(
        &self,
        candidates: &[usize],
        problem: &TourProblem,
    ) -> Option<Arc<[f64]>> {
        let found = self
            .steps
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .get(&PlanKey::new(candidates, problem))
            .cloned();
        if found.is_some() {
            self.hits.fetch_add(1, Ordering::Relaxed);
        }
        found
    }

    /// Keeps the first steps of `solution`, the table of `problem` over `candidates`.
    pub(crate) fn keep(&self, candidates: &[usize], problem: &TourProblem, solution: &Solution) {
        if self.capacity == 0 {
            return;
        }
        let mut steps = self.steps.lock().unwrap_or_else(PoisonError::into_inner);
        if steps.len() >= self.capacity {
            steps.clear();
        }
        steps.insert(
            PlanKey::new(candidates, problem),
            solution.first_steps().into(),
        );
    }
}
