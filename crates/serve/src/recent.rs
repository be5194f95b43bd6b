//! Trials' latest states as their last write answered them, for reads that would otherwise
//! plan again what the write just planned: a page's picture of a trial (`/trials/{id}/view`)
//! after each observation. A state is kept with how many observations the trial had and where
//! it stood, and is used only while the stored trial still has exactly those, so it is the state
//! any replica would compute from the rows. Bounded in number: the oldest are dropped.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use crate::api::TrialState;
use crate::model::TrialStatus;

/// Each trial's kept state with when it was kept, and the clock.
type Kept = (u64, HashMap<i64, (u64, Arc<TrialState>)>);

/// The kept states.
pub(crate) struct RecentStates {
    capacity: usize,
    kept: Mutex<Kept>,
}

impl RecentStates {
    /// At most `capacity` states kept (0: none).
    pub(crate) fn new(capacity: usize) -> Self {
        Self {
            capacity,
            kept: Mutex::new((0, HashMap::new())),
        }
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Kept> {
        self.kept
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// Keeps `state` as its trial's latest.
    pub(crate) fn keep(&self, state: Arc<TrialState>) {
        if self.capacity == 0 {
            return;
        }
        let mut kept = self.lock();
        let (clock, map) = &mut *kept;
        *clock += 1;
        map.insert(state.trial, (*clock, state));
        if map.len() > self.capacity {
            // Drop the older half at once, so that eviction's scan is paid once per half a
            // capacity of writes rather than at each.
            let mut stamps: Vec<u64> = map.values().map(|(t, _)| *t).collect();
            let (_, &mut median, _) = stamps.select_nth_unstable(map.len() / 2);
            map.retain(|_, (t, _)| *t >= median);
        }
    }

    /// The state kept for `trial`, if it was kept after exactly `observations` observations
    /// and with `status`.
    pub(crate) fn get(
        &self,
        trial: i64,
        observations: usize,
        status: TrialStatus,
    ) -> Option<Arc<TrialState>> {
        let kept = self.lock();
        kept.1
            .get(&trial)
            .filter(|(_, s)| s.searched.len() == observations && s.status == status)
            .map(|(_, s)| s.clone())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn state(trial: i64, searched: usize, status: TrialStatus) -> Arc<TrialState> {
        Arc::new(TrialState {
            trial,
            deployment: 1,
            k: trial,
            scene: "s".into(),
            target: "Mug".into(),
            targets: vec!["Mug".into()],
            goal: crate::api::GoalName::All,
            destination: None,
            found_in: Default::default(),
            strategy: "model/uniform".into(),
            status,
            searched: vec!["c".into(); searched],
            cost_m: 0.0,
            travelled_m: None,
            next: None,
            replays_m: None,
            robots: None,
            robot: None,
            language: Vec::new(),
        })
    }

    #[test]
    fn a_state_is_given_only_for_the_trial_as_it_was_kept() {
        let recent = RecentStates::new(8);
        recent.keep(state(1, 2, TrialStatus::Searching));
        assert!(recent.get(1, 2, TrialStatus::Searching).is_some());
        assert!(
            recent.get(1, 3, TrialStatus::Searching).is_none(),
            "observed since"
        );
        assert!(
            recent.get(1, 2, TrialStatus::Abandoned).is_none(),
            "abandoned since"
        );
        assert!(recent.get(2, 2, TrialStatus::Searching).is_none());
        recent.keep(state(1, 3, TrialStatus::Done));
        assert!(
            recent.get(1, 3, TrialStatus::Done).is_some(),
            "the newer replaces it"
        );
        assert!(
            RecentStates::new(0)
                .get(1, 2, TrialStatus::Searching)
                .is_none()
        );
    }

    #[test]
    fn at_most_the_capacity_is_kept_and_the_newest_stay() {
        let recent = RecentStates::new(10);
        for t in 0..1000 {
            recent.keep(state(t, 0, TrialStatus::Searching));
            assert!(recent.lock().1.len() <= 10);
        }
        assert!(recent.get(999, 0, TrialStatus::Searching).is_some());
        assert!(recent.get(0, 0, TrialStatus::Searching).is_none());
    }
}
