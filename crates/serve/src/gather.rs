//! Requests that must take the same lock one after another, gathered so that one holder does
//! the work of all who are waiting. A trial's start holds its deployment's lock from the
//! statement that takes it until the commit: a round trip to the database at least, during
//! which every other start and end of the deployment waits. When many robots share a
//! deployment, starts queue behind each other and each adds its round trip to the wait of
//! all behind it. Gathered, the starts waiting on one replica are made in one transaction
//! (one lock, one read, one commit), so the wait grows with the number of batches, not of
//! starts.
//!
//! Written by hand since what is gathered is a blocking database transaction run on the
//! caller's own thread (flat combining): the first caller leads; the ones that arrive while
//! it works wait and are taken, all at once, by the next leader, which is one of them.

use std::collections::{HashMap, VecDeque};
use std::hash::Hash;
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};

/// One caller's place in a queue: its job until a leader takes it, then its result.
struct Slot<J, R> {
    job: Mutex<Option<J>>,
    state: Mutex<SlotState<R>>,
    ready: Condvar,
}

enum SlotState<R> {
    Waiting,
    /// This caller leads next: it takes the queue, its own job first.
    Lead,
    /// The leader's result.
    Done(R),
}

/// The callers waiting on one key, in the order they came.
type Queue<J, R> = VecDeque<Arc<Slot<J, R>>>;

/// Queues of jobs by key (a deployment); jobs of different keys never wait for each other.
pub(crate) struct Gather<K, J, R> {
    /// The callers waiting, by key; a key is here while a caller leads its queue, and a
    /// caller that finds none leads.
    queues: Mutex<HashMap<K, Queue<J, R>>>,
    /// The largest number of jobs a leader takes at once.
    max_batch: usize,
    /// Jobs worked on in a batch of more than one.
    together: std::sync::atomic::AtomicU64,
}

impl<K: Eq + Hash + Clone, J, R> Gather<K, J, R> {
    pub(crate) fn new(max_batch: usize) -> Self {
        Self {
            queues: Mutex::new(HashMap::new()),
            max_batch: max_batch.max(1),
            together: Default::default(),
        }
    }

    /// How many jobs were worked on together with others so far.
    pub(crate) fn together(&self) -> u64 {
        self.together.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Runs `job` under `key`: at once when no other job of the key is being worked on, else
    /// together with the others waiting then, by whichever caller leads next. `work` gets the
    /// jobs of one batch in the order they came and returns one result per job, in that order
    /// (a missing result is filled in by `lost()`, so that no caller waits forever).
    pub(crate) fn run(
        &self,
        key: &K,
        job: J,
        work: impl Fn(Vec<J>) -> Vec<R>,
        lost: impl Fn() -> R,
    ) -> R {
        let slot = Arc::new(Slot {
            job: Mutex::new(Some(job)),
            state: Mutex::new(SlotState::Waiting),
            ready: Condvar::new(),
        });
        let leads = {
            let mut queues = lock(&self.queues);
            match queues.get_mut(key) {
                Some(queue) => {
                    queue.push_back(Arc::clone(&slot));
                    false
                }
                None => {
                    queues.insert(key.clone(), VecDeque::from([Arc::clone(&slot)]));
                    true
                }
            }
        };
        if !leads {
            let mut state = lock(&slot.state);
            loop {
                match std::mem::replace(&mut *state, SlotState::Waiting) {
                    SlotState::Done(result) => return result,
                    SlotState::Lead => break,
                    SlotState::Waiting => {
                        state = slot
                            .ready
                            .wait(state)
                            .unwrap_or_else(PoisonError::into_inner);
                    }
                }
            }
        }
        self.lead(key, &slot, work, lost)
    }

    /// Takes the waiting jobs, this caller's first (a leader is always at the front of its
    /// queue: the first to come, or the first still waiting when the lead was handed on),
    /// works on them, hands the results out and the lead on to the first caller still waiting.
    fn lead(
        &self,
        key: &K,
        own: &Arc<Slot<J, R>>,
        work: impl Fn(Vec<J>) -> Vec<R>,
        lost: impl Fn() -> R,
    ) -> R {
        let taken: Vec<Arc<Slot<J, R>>> = {
            let mut queues = lock(&self.queues);
            match queues.get_mut(key) {
                Some(queue) => {
                    let n = queue.len().min(self.max_batch);
                    queue.drain(..n).collect()
                }
                None => Vec::new(),
            }
        };
        let jobs: Vec<J> = taken.iter().filter_map(|s| lock(&s.job).take()).collect();
        if jobs.len() > 1 {
            self.together
                .fetch_add(jobs.len() as u64, std::sync::atomic::Ordering::Relaxed);
        }
        // A panic in `work` must not leave the callers it took waiting (nor the queue led by
        // no one): they get `lost()`.
        let results = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work(jobs)))
            .unwrap_or_default();
        let mut results = results.into_iter();
        let mut own_result = None;
        for s in &taken {
            let result = results.next().unwrap_or_else(&lost);
            if Arc::ptr_eq(s, own) {
                own_result = Some(result);
            } else {
                *lock(&s.state) = SlotState::Done(result);
                s.ready.notify_one();
            }
        }
        // The lead is handed on under the queues' lock, so that no newcomer leads beside the
        // caller handed it.
        {
            let mut queues = lock(&self.queues);
            let next = queues.get(key).and_then(|q| q.front().cloned());
            match next {
                Some(next) => {
                    *lock(&next.state) = SlotState::Lead;
                    next.ready.notify_one();
                }
                None => {
                    queues.remove(key);
                }
            }
        }
        own_result.unwrap_or_else(lost)
    }
}

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    /// Each caller's (key, job, result), and each batch's key and jobs.
    type Run = (Vec<(u8, usize, Option<(u8, usize)>)>, Vec<(u8, Vec<usize>)>);

    /// Callers of a few keys, each with a job of its own; `work` sleeps so that callers pile
    /// up behind it. Returns each caller's (key, job, result) and the batches worked on.
    fn run_callers(callers: usize, keys: u8, max_batch: usize) -> Run {
        let gather = Gather::<u8, usize, Option<(u8, usize)>>::new(max_batch);
        let batches = Mutex::new(Vec::new());
        let busy = (0..keys).map(|_| AtomicUsize::new(0)).collect::<Vec<_>>();
        let results = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..callers)
                .map(|i| {
                    let (gather, batches, busy) = (&gather, &batches, &busy);
                    scope.spawn(move || {
                        let key = (i % keys as usize) as u8;
                        let result = gather.run(
                            &key,
                            i,
                            |jobs: Vec<usize>| {
                                // One leader per key at a time.
                                assert_eq!(busy[key as usize].fetch_add(1, Ordering::SeqCst), 0);
                                std::thread::sleep(Duration::from_millis(5));
                                lock(batches).push((key, jobs.clone()));
                                busy[key as usize].fetch_sub(1, Ordering::SeqCst);
                                jobs.into_iter().map(|j| Some((key, j))).collect()
                            },
                            || None,
                        );
                        (key, i, result)
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().expect("a caller panicked"))
                .collect::<Vec<_>>()
        });
        (results, batches.into_inner().expect("batches"))
    }

    #[test]
    fn every_caller_gets_the_result_of_its_own_job_once() {
        let (results, batches) = run_callers(48, 3, 64);
        for (key, job, result) in &results {
            assert_eq!(
                *result,
                Some((*key, *job)),
                "caller {job} got another's result"
            );
        }
        let mut worked: Vec<usize> = batches.iter().flat_map(|(_, b)| b.clone()).collect();
        worked.sort_unstable();
        assert_eq!(
            worked,
            (0..48).collect::<Vec<_>>(),
            "a job worked twice or never"
        );
        for (key, batch) in &batches {
            assert!(
                batch.iter().all(|j| j % 3 == *key as usize),
                "keys mixed: {batch:?}"
            );
        }
        // Callers that came while a batch was worked on waited and went together.
        assert!(
            batches.len() < 48,
            "no two jobs went together: {} batches",
            batches.len()
        );
    }

    #[test]
    fn a_batch_takes_at_most_max_batch_jobs() {
        let (results, batches) = run_callers(40, 1, 3);
        assert!(results.iter().all(|(k, j, r)| *r == Some((*k, *j))));
        assert!(batches.iter().all(|(_, b)| (1..=3).contains(&b.len())));
        assert_eq!(batches.iter().map(|(_, b)| b.len()).sum::<usize>(), 40);
    }

    #[test]
    fn callers_whose_work_panicked_or_returned_too_little_get_lost_and_the_queue_goes_on() {
        let gather = Gather::<u8, usize, Option<usize>>::new(64);
        let calls = AtomicUsize::new(0);
        let results: Vec<(usize, Option<usize>)> = std::thread::scope(|scope| {
            let handles: Vec<_> = (0..16)
                .map(|i| {
                    let (gather, calls) = (&gather, &calls);
                    scope.spawn(move || {
                        let r = gather.run(
                            &0,
                            i,
                            |jobs: Vec<usize>| {
                                std::thread::sleep(Duration::from_millis(3));
                                match calls.fetch_add(1, Ordering::SeqCst) % 3 {
                                    0 => panic!("work failed"),
                                    1 => {
                                        let n = jobs.len() - 1;
                                        jobs.into_iter().take(n).map(Some).collect()
                                    }
                                    _ => jobs.into_iter().map(Some).collect(),
                                }
                            },
                            || None,
                        );
                        (i, r)
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| h.join().expect("a caller panicked"))
                .collect()
        });
        // Every caller came back, with its own job's result or none.
        assert_eq!(results.len(), 16);
        for (i, r) in &results {
            assert!(r.is_none() || *r == Some(*i), "caller {i} got {r:?}");
        }
        assert!(results.iter().any(|(_, r)| r.is_none()), "no loss was seen");
        assert!(
            gather.queues.lock().expect("queues").is_empty(),
            "a queue was left led"
        );
    }
}
