//! Sharded evaluation: which houses a shard runs, what it records, and the merge of shards'
//! runs into the run one machine would have written.
//!
//! **The rule.** Shard `i` of `n` runs the houses whose index in their file satisfies
//! `index mod n = i` ([`Shard::contains`]). The index is the house's line in its file (or its
//! place among generated houses), so the rule needs nothing but the house itself: no count of
//! the file's houses, no hash whose value could change between machines or language versions,
//! and a house keeps its shard when `--range` or invalid houses change which others are
//! loaded. Striding rather than contiguous blocks also spreads houses of every kind over all
//! shards, so one shard does not draw all the large houses of a file sorted by size.
//!
//! **Why the shards' trials are the one-machine trials.** Every draw of a trial (target,
//! revealed containers, the paper's initial belief, under both `--rng ferret` and
//! `--rng python`) is seeded from the trial seed and the house's index alone
//! ([`ferret_plan::draw_trials_with`]); no stream runs across houses. A shard therefore draws
//! exactly the trials one machine draws for its houses, and nothing about the shard enters them.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

/// One shard of an evaluation: `index` of `count` (0-based).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Shard {
    /// This shard, `0..count`.
    pub index: usize,
    /// How many shards the houses are split into.
    pub count: usize,
}

/// The rule's name as run.json records it.
pub const SHARD_RULE: &str = "house_index mod count";

impl Shard {
    /// Shard `index` of `count`; an error unless `index < count`.
    pub fn new(index: usize, count: usize) -> Result<Self, ShardError> {
        if count == 0 || index >= count {
            return Err(ShardError::OutOfRange { index, count });
        }
        Ok(Self { index, count })
    }

    /// Whether the house with file index `house_index` belongs to this shard.
    pub fn contains(&self, house_index: usize) -> bool {
        house_index % self.count == self.index
    }

    /// The shard of `count` that runs the house with file index `house_index`.
    pub fn of_house(house_index: usize, count: usize) -> usize {
        house_index % count.max(1)
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl std::str::FromStr for Shard {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || ShardError::Syntax(s.to_string());
        let (i, n) = s.trim().split_once('/').ok_or_else(bad)?;
        let i = digits(i).ok_or_else(bad)?;
        let n = digits(n).ok_or_else(bad)?;
        Self::new(i, n)
    }
}

/// A number written as decimal digits only: `+1`, ` 1` and `1 ` (which `usize`'s own parsing or
/// a trim would take) are refused, since a batch system never writes them and a mistyped
/// variable should not run a shard.
fn digits(s: &str) -> Option<usize> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

/// `--shard` as given: a fixed shard, or `auto` (from the batch system's environment).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShardSpec {
    /// `i/n`.
    Fixed(Shard),
    /// From `SLURM_ARRAY_TASK_ID`/`SLURM_ARRAY_TASK_COUNT` or `JOB_COMPLETION_INDEX` with
    /// [`SHARD_COUNT_VAR`]; see [`ShardSpec::resolve`].
    Auto,
}

/// The variable that gives the shard count beside a Kubernetes Indexed Job's
/// `JOB_COMPLETION_INDEX` (Kubernetes passes the index only; the manifest's `completions` is
/// the count, set here too).
pub const SHARD_COUNT_VAR: &str = "FERRET_SHARD_COUNT";

impl std::str::FromStr for ShardSpec {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.trim() == "auto" {
            Ok(Self::Auto)
        } else {
            s.parse().map(Self::Fixed)
        }
    }
}

impl ShardSpec {
    /// The shard, reading the environment through `var` for `auto`: a Slurm array task
    /// (`SLURM_ARRAY_TASK_ID` − `SLURM_ARRAY_TASK_MIN`, of `SLURM_ARRAY_TASK_COUNT`, so that
    /// `--array=1-3` works as `--array=0-2` does), else a Kubernetes Indexed Job
    /// (`JOB_COMPLETION_INDEX` of [`SHARD_COUNT_VAR`]).
    pub fn resolve(&self, var: impl Fn(&str) -> Option<String>) -> Result<Shard, ShardError> {
        if let Self::Fixed(s) = self {
            return Ok(*s);
        }
        let num = |name: &str| -> Result<Option<usize>, ShardError> {
            match var(name) {
                None => Ok(None),
                Some(v) => digits(&v).map(Some).ok_or_else(|| {
                    ShardError::Env(format!("{name}={v:?} is not a number (digits only)"))
                }),
            }
        };
        if var("SLURM_ARRAY_TASK_ID").is_some() && var("JOB_COMPLETION_INDEX").is_some() {
            return Err(ShardError::Env(
                "--shard auto: both a Slurm array task (SLURM_ARRAY_TASK_ID) and a Kubernetes \
                 Indexed Job (JOB_COMPLETION_INDEX) are in the environment, so the shard is \
                 ambiguous: unset one, or give --shard i/n"
                    .into(),
            ));
        }
        if let Some(id) = num("SLURM_ARRAY_TASK_ID")? {
            let count = num("SLURM_ARRAY_TASK_COUNT")?.ok_or_else(|| {
                ShardError::Env(
                    "SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not".into(),
                )
            })?;
            let min = num("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let index = id.checked_sub(min).ok_or_else(|| {
                ShardError::Env(format!(
                    "SLURM_ARRAY_TASK_ID {id} is below SLURM_ARRAY_TASK_MIN {min}"
                ))
            })?;
            // An array with a step (--array=0-10:2) or a list has ids that are not 0..count.
            return Shard::new(index, count).map_err(|_| {
                ShardError::Env(format!(
                    "array task {id} (min {min}) of {count} is not one of 0..{count} after the \
                     minimum is taken off: submit a contiguous array such as --array=0-{}",
                    count.saturating_sub(1)
                ))
            });
        }
        if let Some(index) = num("JOB_COMPLETION_INDEX")? {
            let count = num(SHARD_COUNT_VAR)?.ok_or_else(|| {
                ShardError::Env(format!(
                    "JOB_COMPLETION_INDEX is set but {SHARD_COUNT_VAR} is not: set it to the \
                     Job's completions"
                ))
            })?;
            return Shard::new(index, count);
        }
        Err(ShardError::Env(format!(
            "--shard auto: neither a Slurm array task (SLURM_ARRAY_TASK_ID and \
             SLURM_ARRAY_TASK_COUNT) nor a Kubernetes Indexed Job (JOB_COMPLETION_INDEX and \
             {SHARD_COUNT_VAR}) is in the environment; give --shard i/n"
        )))
    }
}

/// A `--shard` that cannot be used.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ShardError {
    /// Not `i/n` nor `auto`.
    #[error("--shard {0:?}: expected i/n (e.g. 0/3) or `auto`")]
    Syntax(String),
    /// `i` not below `n`.
    #[error(
        "--shard {index}/{count}: the shard must be one of 0..{count} (and the count at least 1)"
    )]
    OutOfRange {
        /// The index given.
        index: usize,
        /// The count given.
        count: usize,
    },
    /// `auto` found no usable environment.
    #[error("{0}")]
    Env(String),
}

/// What a shard's run.json records besides the run's settings: enough for [`merge_runs`](crate::merge::merge_runs) to
/// check the shards and to write the report one machine writes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShardRecord {
    /// This shard.
    pub index: usize,
    /// Of how many.
    pub count: usize,
    /// The rule, [`SHARD_RULE`].
    pub rule: String,
    /// File indices of the houses this shard loaded (valid houses of the run's source in it).
    pub houses: Vec<usize>,
    /// Houses with at least one trial.
    pub houses_run: usize,
    /// Trials (house and target) drawn.
    pub trials_run: usize,
    /// House or trial failures (their messages went to the shard's log).
    #[serde(default)]
    pub failures: usize,
    /// The report's extra references (`--paired-against`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub paired_against: Vec<String>,
    /// Whether costs in grid cells were asked for (`--cells`).
    #[serde(default)]
    pub cells: bool,
    /// The house whose trajectories the merged run shows (`--show-house`): shards draw no
    /// pictures, the merge draws them once.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub show_house: Option<usize>,
}

/// One shard of a merged run, as the merged run.json lists it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MergedShard {
    /// The shard's run directory, as given to the merge.
    pub dir: PathBuf,
    /// Its index.
    pub index: usize,
    /// Its houses.
    pub houses: usize,
    /// Its trials.csv's rows.
    pub rows: usize,
    /// Its trials.csv's SHA-256.
    pub trials_sha256: String,
}

/// Why shards cannot be merged. Every message names the directories concerned.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// Nothing to merge.
    #[error("no run directories to merge")]
    Empty,
    /// A run directory that is not a shard.
    #[error("{}: not a shard's run (its run.json has no `shard`); run `ferret eval --shard i/n` into it", dir.display())]
    NotShard {
        /// The directory.
        dir: PathBuf,
    },
    /// Two shards ran with different settings.
    #[error("{} and {} ran with different settings ({fields}); shards of one run must share every option but --shard and --out", first.display(), other.display())]
    Settings {
        /// The first shard given.
        first: PathBuf,
        /// The one that differs.
        other: PathBuf,
        /// The settings that differ.
        fields: String,
    },
    /// Two directories hold the same shard, or share a house.
    #[error("{} and {} overlap: {what}", first.display(), other.display())]
    Overlap {
        /// One directory.
        first: PathBuf,
        /// The other.
        other: PathBuf,
        /// What they share.
        what: String,
    },
    /// Shards missing.
    #[error("shards missing: {missing} of {count} (given: {given})")]
    Gap {
        /// The missing shard indices.
        missing: String,
        /// The count.
        count: usize,
        /// The directories given, with their shards.
        given: String,
    },
    /// A shard holds a house or trial that its rule does not give it.
    #[error("{}: {message}", dir.display())]
    Inconsistent {
        /// The directory.
        dir: PathBuf,
        /// What is wrong.
        message: String,
    },
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rule_is_pinned() {
        // Fixed house → fixed shard: a change here reassigns houses between existing shards.
        let of = |h| Shard::of_house(h, 3);
        assert_eq!(
            (0..10).map(of).collect::<Vec<_>>(),
            [0, 1, 2, 0, 1, 2, 0, 1, 2, 0]
        );
        assert_eq!(Shard::of_house(149, 3), 2);
        assert_eq!(Shard::of_house(9_999, 16), 15);
        assert_eq!(Shard::of_house(9_999, 128), 15);
        let s: Shard = "1/3".parse().unwrap();
        assert!(s.contains(4) && !s.contains(5));
        assert_eq!(s.to_string(), "1/3");
    }

    #[test]
    fn shards_partition_the_houses() {
        for n in 1..8 {
            for h in 0..100 {
                let owners = (0..n).filter(|&i| Shard { index: i, count: n }.contains(h));
                assert_eq!(owners.count(), 1);
            }
        }
    }

    #[test]
    fn bad_shards_are_refused() {
        assert!(matches!(
            "3/3".parse::<Shard>(),
            Err(ShardError::OutOfRange { .. })
        ));
        assert!(matches!(
            "0/0".parse::<Shard>(),
            Err(ShardError::OutOfRange { .. })
        ));
        assert!(matches!("x".parse::<Shard>(), Err(ShardError::Syntax(_))));
        assert_eq!("auto".parse::<ShardSpec>().unwrap(), ShardSpec::Auto);
    }

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| {
            vars.iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn auto_reads_slurm_then_kubernetes() {
        let slurm = [
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
        ];
        assert_eq!(
            ShardSpec::Auto.resolve(env(&slurm)),
            Ok(Shard { index: 2, count: 3 })
        );
        let one_based = [
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
        ];
        assert_eq!(
            ShardSpec::Auto.resolve(env(&one_based)),
            Ok(Shard { index: 2, count: 3 })
        );
        let k8s = [("JOB_COMPLETION_INDEX", "4"), (SHARD_COUNT_VAR, "5")];
        assert_eq!(
            ShardSpec::Auto.resolve(env(&k8s)),
            Ok(Shard { index: 4, count: 5 })
        );
        let e = ShardSpec::Auto.resolve(env(&[])).unwrap_err().to_string();
        assert!(
            e.contains("SLURM_ARRAY_TASK_ID") && e.contains("JOB_COMPLETION_INDEX"),
            "{e}"
        );
        let e = ShardSpec::Auto
            .resolve(env(&[("JOB_COMPLETION_INDEX", "1")]))
            .unwrap_err()
            .to_string();
        assert!(e.contains(SHARD_COUNT_VAR), "{e}");
    }

    #[test]
    fn auto_refuses_two_batch_systems_and_numbers_that_are_not_plain_digits() {
        let both = [
            ("SLURM_ARRAY_TASK_ID", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
            ("JOB_COMPLETION_INDEX", "1"),
            (SHARD_COUNT_VAR, "3"),
        ];
        let e = ShardSpec::Auto.resolve(env(&both)).unwrap_err().to_string();
        assert!(e.contains("ambiguous"), "{e}");
        for bad in [" 1", "+1", "1 ", "", "-1", "1_0"] {
            let vars = [
                ("SLURM_ARRAY_TASK_ID", bad),
                ("SLURM_ARRAY_TASK_COUNT", "3"),
            ];
            let e = ShardSpec::Auto.resolve(env(&vars)).unwrap_err().to_string();
            assert!(e.contains("not a number"), "{bad:?}: {e}");
            let vars = [("JOB_COMPLETION_INDEX", "0"), (SHARD_COUNT_VAR, bad)];
            assert!(ShardSpec::Auto.resolve(env(&vars)).is_err(), "{bad:?}");
        }
        for bad in ["+1/3", "1/+3", "1 / 3", "0x1/3"] {
            assert!(
                matches!(bad.parse::<Shard>(), Err(ShardError::Syntax(_))),
                "{bad}"
            );
        }
        assert_eq!(" 1/3 ".parse::<Shard>(), Ok(Shard { index: 1, count: 3 }));
    }
}
