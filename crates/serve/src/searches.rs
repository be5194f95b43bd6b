//! Trials' searches kept between requests. A trial's search is derived from its stored
//! observations and could be rebuilt on every request, but a rebuilt exact planner solves its
//! whole problem again each time, where a search kept alive answers the next step from the table
//! of its first decision. So the search of a trial that is still searching is kept after each
//! reply, keyed by the trial and how many observations it has recorded: a request that finds
//! the key (the trial's last request went to this replica, and nothing was recorded since) goes
//! on from it; any other rebuilds from the store. Bounded in number: the least recently used
//! are dropped.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use ferret_plan::{Search, Strategy, TrialSpec};

use crate::grids::Placed;

/// What a kept search borrows.
pub(crate) struct Owner {
    pub(crate) placed: Arc<Placed>,
    pub(crate) trial: TrialSpec,
    pub(crate) strategy: Arc<dyn Strategy>,
}

type Borrowed<'a> = Search<'a>;

// A search borrows its strategy, map and target; a kept one must own them, so it is stored
// with them (no other way lets a value borrow from its neighbour in a struct).
self_cell::self_cell!(
    /// A trial's search together with what it borrows.
    pub(crate) struct LiveSearch {
        owner: Owner,
        #[not_covariant]
        dependent: Borrowed,
    }
);

struct Kept {
    observations: usize,
    search: LiveSearch,
    used: u64,
}

/// The kept searches.
pub(crate) struct Searches {
    capacity: usize,
    kept: Mutex<(u64, HashMap<i64, Kept>)>,
}

impl Searches {
    /// At most `capacity` searches kept (0: none).
    pub(crate) fn new(capacity: usize) -> Self {
        Self {
            capacity,
            kept: Mutex::new((0, HashMap::new())),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, (u64, HashMap<i64, Kept>)> {
        self.kept
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Takes the search of `trial` if it was kept after exactly `observations` observations.
    pub(crate) fn take(&self, trial: i64, observations: usize) -> Option<LiveSearch> {
        let mut kept = self.lock();
        match kept.1.remove(&trial) {
            Some(k) if k.observations == observations => Some(k.search),
            _ => None,
        }
    }

    /// Keeps `search` of `trial` after `observations` observations.
    pub(crate) fn keep(&self, trial: i64, observations: usize, search: LiveSearch) {
        if self.capacity == 0 {
            return;
        }
        let mut kept = self.lock();
        let (clock, map) = &mut *kept;
        *clock += 1;
        map.insert(
            trial,
            Kept {
                observations,
                search,
                used: *clock,
            },
        );
        while map.len() > self.capacity {
            let Some(oldest) = map.iter().min_by_key(|(_, k)| k.used).map(|(id, _)| *id) else {
                break;
            };
            map.remove(&oldest);
        }
    }

    /// Forgets `trial` (it ended).
    pub(crate) fn forget(&self, trial: i64) {
        self.lock().1.remove(&trial);
    }

    /// How many are kept.
    pub(crate) fn len(&self) -> usize {
        self.lock().1.len()
    }
}
