//! Deployments' selectors kept between requests. A deployment's selector is derived from its
//! stored history and could be replayed from the first trial on every start, but that costs in
//! proportion to the history (a long-lived deployment would start its trials ever slower, and
//! 50 robots sharing one would replay it 50 times over). A deployment's history only grows at
//! its end (trials are numbered in the order they start, ends in the order they end), so the
//! selector is kept after the events it has seen and goes on from them with the trials that
//! started or ended since, read in one statement. Another replica's trials are read like this
//! replica's own; a replica that restarts or drops a selector replays the whole history once.
//!
//! No lock is held while the database is read: on SQLite the one connection may be held by a
//! write transaction that itself waits for a selector here.

use std::collections::HashMap;
use std::sync::{Mutex, MutexGuard, PoisonError};

use ferret_select::{DeploymentEvent, FinishedTrial, LiveDeployment, TrialEnd};

use crate::error::ApiError;
use crate::model::{DeploymentSpec, StoredTrial, TrialStatus};
use crate::store::TrialCounts;

/// Where a deployment's history stood when a selector was brought up to date.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct HistoryMark {
    /// Trials started (numbered `1..=started`).
    pub(crate) started: usize,
    /// Trials ended (numbered `1..=ended` in the order they ended).
    pub(crate) ended: usize,
    /// The `started_after` of the last start: later starts saw at least as many ends.
    last_after: i64,
}

impl HistoryMark {
    /// The counts a new trial's choice depends on.
    pub(crate) fn counts(&self) -> TrialCounts {
        TrialCounts {
            started: self.started,
            ended: self.ended,
            open: self.started.saturating_sub(self.ended),
        }
    }
}

/// A deployment's history after `mark` as the selector saw it, from `rows`: every trial that
/// started or ended after the mark (and possibly others, which are skipped), in order of start.
/// Each start comes after the ends it was chosen from. Returns the events and the mark after
/// them.
///
/// # Errors
/// Rows whose numbering has gaps or whose starts and ends contradict each other (a database
/// edited by hand, or a bug).
pub(crate) fn events_since(
    mark: HistoryMark,
    rows: &[StoredTrial],
) -> Result<(Vec<DeploymentEvent>, HistoryMark), ApiError> {
    let corrupt = |t: &StoredTrial, what: String| {
        ApiError::internal(format!(
            "deployment {}: trial {} {what}; the stored order of starts and ends is inconsistent",
            t.deployment, t.id
        ))
    };
    let starts: Vec<&StoredTrial> = rows.iter().filter(|t| t.k > mark.started as i64).collect();
    for (j, t) in starts.iter().enumerate() {
        let expected = (mark.started + j + 1) as i64;
        if t.k != expected {
            return Err(corrupt(
                t,
                format!("is numbered {} where {expected} was next", t.k),
            ));
        }
    }
    let mut ends: Vec<&StoredTrial> = rows
        .iter()
        .filter(|t| t.end_seq.is_some_and(|e| e > mark.ended as i64))
        .collect();
    ends.sort_by_key(|t| t.end_seq);
    for (i, t) in ends.iter().enumerate() {
        let before = (mark.ended + i) as i64;
        if t.end_seq != Some(before + 1) {
            return Err(corrupt(t, "ended out of sequence".into()));
        }
        if t.started_after > before {
            return Err(corrupt(t, "ended before it started".into()));
        }
    }
    let mut events = Vec::with_capacity(starts.len() + ends.len());
    let started = mark.started + starts.len();
    let mut starts = starts.into_iter().peekable();
    let mut last_after = mark.last_after;
    let mut start = |t: &StoredTrial, events: &mut Vec<DeploymentEvent>| {
        if t.started_after < last_after {
            return Err(corrupt(t, "started before an earlier trial".into()));
        }
        last_after = t.started_after;
        events.push(DeploymentEvent::Started { chosen: t.chosen });
        Ok(())
    };
    for (i, end) in ends.iter().enumerate() {
        // The starts that saw only the ends before this one.
        let before = (mark.ended + i) as i64;
        while let Some(t) = starts.next_if(|t| t.started_after <= before) {
            start(t, &mut events)?;
        }
        events.push(DeploymentEvent::Ended(match end.status {
            TrialStatus::Done => TrialEnd::Finished(FinishedTrial {
                chosen: end.chosen,
                cost: end.cost.unwrap_or(f64::NAN),
                replays: end.replays.clone().unwrap_or_default(),
            }),
            _ => TrialEnd::Abandoned { chosen: end.chosen },
        }));
    }
    for t in starts {
        start(t, &mut events)?;
    }
    let next = HistoryMark {
        started,
        ended: mark.ended + ends.len(),
        last_after,
    };
    Ok((events, next))
}

/// A deployment's selector after the events up to `mark`.
struct Kept {
    mark: HistoryMark,
    live: LiveDeployment,
    used: u64,
}

/// The kept selectors, at most `capacity` (the least recently used are dropped).
pub(crate) struct Selectors {
    capacity: usize,
    kept: Mutex<(u64, HashMap<i64, Kept>)>,
}

impl Selectors {
    pub(crate) fn new(capacity: usize) -> Self {
        Self {
            capacity,
            kept: Mutex::new((0, HashMap::new())),
        }
    }

    fn lock(&self) -> MutexGuard<'_, (u64, HashMap<i64, Kept>)> {
        self.kept.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// Where deployment `id`'s kept selector stands (the start of its history when none is
    /// kept).
    pub(crate) fn mark(&self, id: i64) -> HistoryMark {
        self.lock().1.get(&id).map(|k| k.mark).unwrap_or_default()
    }

    /// The choices for `n` new trials of deployment `id`, started one after another, and the
    /// counts each was made from, after bringing its selector up to date with
    /// `since(started, ended)`: the trials that started or ended after the first `started`
    /// starts and `ended` ends (read in one statement). When another request brought the
    /// selector further meanwhile, its state is used (it is as fresh as this read or fresher).
    ///
    /// Each choice after the first is made after the starts before it in the batch, as if
    /// those had been stored and read back: the kept selector goes on past them, so the batch
    /// must be stored, or the selector [forgotten](Self::forget).
    pub(crate) fn choose(
        &self,
        id: i64,
        spec: &DeploymentSpec,
        n: usize,
        since: impl Fn(usize, usize) -> Result<Vec<StoredTrial>, ApiError>,
    ) -> Result<Vec<(usize, TrialCounts)>, ApiError> {
        let from = self.mark(id);
        let mut rows = since(from.started, from.ended)?;
        let mut kept = self.lock();
        // A selector dropped or behind this read's start is rebuilt from this read when it
        // covers the whole history, else from a fresh one.
        let usable = match kept.1.get(&id) {
            Some(k) => k.mark.started >= from.started && k.mark.ended >= from.ended,
            None => from == HistoryMark::default(),
        };
        if !usable {
            drop(kept);
            rows = since(0, 0)?;
            let (live, mark) = replayed(id, spec, &rows)?;
            kept = self.lock();
            let fresher = kept
                .1
                .get(&id)
                .is_some_and(|k| k.mark.started >= mark.started && k.mark.ended >= mark.ended);
            if !fresher {
                kept.1.insert(
                    id,
                    Kept {
                        mark,
                        live,
                        used: 0,
                    },
                );
            }
        }
        let (clock, map) = &mut *kept;
        *clock += 1;
        let now = *clock;
        let k = match map.entry(id) {
            std::collections::hash_map::Entry::Occupied(e) => e.into_mut(),
            std::collections::hash_map::Entry::Vacant(e) => e.insert(Kept {
                mark: HistoryMark::default(),
                live: new_live(spec)?,
                used: now,
            }),
        };
        let (events, mark) = events_since(k.mark, &rows)?;
        let mut answers = Vec::with_capacity(n);
        let mut extended = || {
            k.live.extend_events(&events)?;
            let mut mark = mark;
            for i in 0..n {
                let chosen = k.live.peek();
                answers.push((chosen, mark.counts()));
                if i + 1 < n {
                    k.live
                        .extend_events(&[DeploymentEvent::Started { chosen }])?;
                    mark = HistoryMark {
                        started: mark.started + 1,
                        ended: mark.ended,
                        last_after: mark.ended as i64,
                    };
                }
            }
            Ok::<_, ferret_select::SelectError>(mark)
        };
        let extended = extended();
        match extended {
            Ok(mark) => {
                k.mark = mark;
                k.used = now;
                self.trim(map);
                Ok(answers)
            }
            Err(e) => {
                map.remove(&id);
                Err(ApiError::internal(format!("deployment {id}: {e}")))
            }
        }
    }

    /// Drops deployment `id`'s selector (rebuilt from the database when next needed): after a
    /// batch of choices that was not stored.
    pub(crate) fn forget(&self, id: i64) {
        self.lock().1.remove(&id);
    }

    fn trim(&self, map: &mut HashMap<i64, Kept>) {
        while map.len() > self.capacity {
            let Some(oldest) = map.iter().min_by_key(|(_, k)| k.used).map(|(id, _)| *id) else {
                break;
            };
            map.remove(&oldest);
        }
    }
}

/// Deployment `id`'s selector replayed from all its trials `rows`, and where that leaves its
/// history.
pub(crate) fn replayed(
    id: i64,
    spec: &DeploymentSpec,
    rows: &[StoredTrial],
) -> Result<(LiveDeployment, HistoryMark), ApiError> {
    let (events, mark) = events_since(HistoryMark::default(), rows)?;
    let live = LiveDeployment::replay_events(
        spec.selector,
        spec.strategies.len(),
        spec.c,
        spec.seed,
        &events,
    )
    .map_err(|e| ApiError::internal(format!("deployment {id}: {e}")))?;
    Ok((live, mark))
}

/// A deployment's selector before its first trial.
fn new_live(spec: &DeploymentSpec) -> Result<LiveDeployment, ApiError> {
    LiveDeployment::new(spec.selector, spec.strategies.len(), spec.c, spec.seed)
        .map_err(|e| ApiError::internal(e.to_string()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A deployment's rows as the store holds them after `script` (start a trial, or end the
    /// open one at a position), each row as it stood after step `j` of the script: what a read
    /// at that moment returns.
    fn history(script: &[Option<usize>]) -> Vec<Vec<StoredTrial>> {
        let (mut rows, mut open, mut ended, mut snapshots) =
            (Vec::<StoredTrial>::new(), Vec::new(), 0, Vec::new());
        for (j, step) in script.iter().enumerate() {
            match step {
                Some(p) if !open.is_empty() => {
                    let i: usize = open.remove(p % open.len());
                    ended += 1;
                    let t = &mut rows[i];
                    t.end_seq = Some(ended);
                    if j % 3 == 0 {
                        t.status = TrialStatus::Abandoned;
                        t.cost = Some(1.0);
                    } else {
                        t.status = TrialStatus::Done;
                        t.cost = Some((j % 5) as f64);
                        t.replays = Some(vec![(j % 5) as f64, (j % 7) as f64, 2.0]);
                    }
                }
                _ => {
                    open.push(rows.len());
                    rows.push(StoredTrial {
                        id: rows.len() as i64 + 100,
                        deployment: 1,
                        k: rows.len() as i64 + 1,
                        scene: "flat".into(),
                        target: "Wallet".into(),
                        pose: None,
                        chosen: 0,
                        status: TrialStatus::Searching,
                        cost: None,
                        replays: None,
                        started_after: ended,
                        end_seq: None,
                        task: None,
                        robots: None,
                        robot: None,
                        heard_ms: None,
                    });
                }
            }
            snapshots.push(rows.clone());
        }
        snapshots
    }

    /// What `trials_since` returns from `rows`.
    fn since(rows: &[StoredTrial], mark: HistoryMark) -> Vec<StoredTrial> {
        rows.iter()
            .filter(|t| {
                t.k > mark.started as i64 || t.end_seq.is_some_and(|e| e > mark.ended as i64)
            })
            .cloned()
            .collect()
    }

    proptest! {
        #[test]
        fn a_history_read_in_pieces_is_the_history_read_at_once(
            script in prop::collection::vec(prop::option::of(0usize..4), 1..40),
            cuts in prop::collection::vec(0usize..40, 0..5),
        ) {
            let snapshots = history(&script);
            let last = snapshots.len() - 1;
            let (whole, end) = events_since(HistoryMark::default(), &snapshots[last]).unwrap();
            let mut cuts: Vec<usize> = cuts.into_iter().map(|c| c % snapshots.len()).collect();
            cuts.push(last);
            cuts.sort_unstable();
            let (mut pieces, mut mark) = (Vec::new(), HistoryMark::default());
            for cut in cuts {
                let (events, next) = events_since(mark, &since(&snapshots[cut], mark)).unwrap();
                pieces.extend(events);
                mark = next;
            }
            prop_assert_eq!(mark, end);
            prop_assert_eq!(pieces, whole);
        }
    }

    #[test]
    fn gaps_and_contradictions_in_the_rows_are_refused() {
        let rows = history(&[None, None, Some(0), None, Some(0)])
            .pop()
            .unwrap();
        let mut gap = rows.clone();
        gap[2].k = 4;
        let e = events_since(HistoryMark::default(), &gap).unwrap_err();
        assert!(
            e.message.contains("numbered 4 where 3 was next"),
            "{}",
            e.message
        );
        let mut early = rows.clone();
        let ended = early.iter_mut().find(|t| t.end_seq == Some(1)).unwrap();
        ended.end_seq = Some(2);
        let e = events_since(HistoryMark::default(), &early).unwrap_err();
        assert!(e.message.contains("out of sequence"), "{}", e.message);
    }
}
