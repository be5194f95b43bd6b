//! Held-out target types: the object types split into folds by a stable rule, so that a prior can
//! be asked about types its training houses never showed it (what a likelihood source knows
//! beyond the prior is measured there).

use std::fmt;
use std::str::FromStr;

use ferret_world::ObjectType;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

/// Which target types a prior must not have seen: the types of one fold of `folds`, or, with
/// `fold` `None`, for every target the types of that target's own fold (every trial then has a
/// target its prior never saw, and the trials are those of a run without hold-out).
///
/// Written `K/N` (fold K of N, counted from 1) or `N` (every fold of N).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(try_from = "String", into = "String")]
pub struct HoldOut {
    /// Number of folds (≥ 2).
    folds: usize,
    /// The held-out fold, from 0; `None` for every fold in turn.
    fold: Option<usize>,
}

/// The most folds a hold-out may have: ProcTHOR's houses hold about a hundred target types, so
/// more folds than this leave nearly every fold empty (and each fold is a prior to build).
pub const MAX_FOLDS: usize = 1_000;

impl HoldOut {
    /// Every fold of `folds` in turn; `None` for fewer than 2 folds or more than [`MAX_FOLDS`].
    pub fn every_fold(folds: usize) -> Option<Self> {
        (2..=MAX_FOLDS)
            .contains(&folds)
            .then_some(Self { folds, fold: None })
    }

    /// Fold `fold` (from 0) of `folds`; `None` when out of range or more than [`MAX_FOLDS`].
    pub fn one_fold(fold: usize, folds: usize) -> Option<Self> {
        ((2..=MAX_FOLDS).contains(&folds) && fold < folds).then_some(Self {
            folds,
            fold: Some(fold),
        })
    }

    /// Number of folds.
    pub fn folds(&self) -> usize {
        self.folds
    }

    /// The held-out fold (from 0), or `None` for every fold in turn.
    pub fn fold(&self) -> Option<usize> {
        self.fold
    }

    /// The fold of `t` among `folds`: the first eight bytes of the SHA-256 of its name, modulo
    /// `folds`. The same on every machine and in every version, and independent of the houses.
    pub fn fold_of(t: &ObjectType, folds: usize) -> usize {
        let digest = Sha256::digest(t.as_str().as_bytes());
        let mut first = [0u8; 8];
        first.copy_from_slice(&digest[..8]);
        (u64::from_le_bytes(first) % folds.max(1) as u64) as usize
    }

    /// The fold whose types the prior asked about `t` has never seen.
    pub fn prior_fold(&self, t: &ObjectType) -> usize {
        self.fold.unwrap_or_else(|| Self::fold_of(t, self.folds))
    }

    /// Whether a trial with target `t` belongs to the run: with one fold, only its types; with
    /// every fold, every type.
    pub fn includes_target(&self, t: &ObjectType) -> bool {
        self.fold.is_none_or(|k| Self::fold_of(t, self.folds) == k)
    }
}

impl fmt::Display for HoldOut {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.fold {
            Some(k) => write!(f, "{}/{}", k + 1, self.folds),
            None => write!(f, "{}", self.folds),
        }
    }
}

impl FromStr for HoldOut {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        let number = |v: &str| {
            v.trim()
                .parse::<usize>()
                .map_err(|_| format!("`{s}`: expected N (every fold of N) or K/N (fold K of N)"))
        };
        let count = |n: usize| {
            if n < 2 {
                Err(format!("`{s}`: at least 2 folds"))
            } else if n > MAX_FOLDS {
                Err(format!(
                    "`{s}`: at most {MAX_FOLDS} folds (the houses hold about a hundred target types; more folds leave them empty)"
                ))
            } else {
                Ok(n)
            }
        };
        match s.split_once('/') {
            None => {
                let n = count(number(s)?)?;
                Self::every_fold(n).ok_or_else(|| format!("`{s}`: no such hold-out"))
            }
            Some((k, n)) => {
                let (k, n) = (number(k)?, count(number(n)?)?);
                if k == 0 || k > n {
                    return Err(format!("`{s}`: the fold is counted from 1 to {n}"));
                }
                Self::one_fold(k - 1, n).ok_or_else(|| format!("`{s}`: no such fold"))
            }
        }
    }
}

impl TryFrom<String> for HoldOut {
    type Error = String;
    fn try_from(s: String) -> Result<Self, String> {
        s.parse()
    }
}

impl From<HoldOut> for String {
    fn from(h: HoldOut) -> String {
        h.to_string()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn folds_are_read_and_written_as_users_write_them() {
        let one: HoldOut = "2/5".parse().unwrap();
        assert_eq!(one, HoldOut::one_fold(1, 5).unwrap());
        assert_eq!(one.to_string(), "2/5");
        let every: HoldOut = "5".parse().unwrap();
        assert_eq!(every.to_string(), "5");
        for bad in ["0/5", "6/5", "1", "x/5", "1/1", "", "1001", "1/100000"] {
            assert!(bad.parse::<HoldOut>().is_err(), "{bad}");
        }
        // Numbers past usize are refused as numbers, not counted into a capacity.
        for bad in [
            "18446744073709551615",
            "18446744073709551616",
            "1/18446744073709551615",
        ] {
            assert!(bad.parse::<HoldOut>().is_err(), "{bad}");
        }
        assert_eq!("1000".parse::<HoldOut>().unwrap().folds(), MAX_FOLDS);
        assert!(HoldOut::every_fold(MAX_FOLDS + 1).is_none());
        let json = serde_json::to_string(&one).unwrap();
        assert_eq!(json, "\"2/5\"");
        assert_eq!(serde_json::from_str::<HoldOut>(&json).unwrap(), one);
    }

    #[test]
    fn a_type_has_a_fixed_fold() {
        // Pinned (SHA-256 of the name, first 8 bytes little-endian, mod 5): a change of the
        // rule would change every published hold-out figure.
        let folds: Vec<usize> = ["Apple", "RemoteControl", "Book", "CellPhone", "Mug"]
            .iter()
            .map(|t| HoldOut::fold_of(&ObjectType::new(*t), 5))
            .collect();
        assert_eq!(folds, [4, 1, 0, 4, 0]);
    }

    proptest! {
        /// Every type falls in exactly one fold, and a one-fold run takes just its types.
        #[test]
        fn every_type_is_in_one_fold(name in "[A-Za-z]{1,20}", n in 2usize..12) {
            let t = ObjectType::new(name);
            let f = HoldOut::fold_of(&t, n);
            prop_assert!(f < n);
            let members = (0..n)
                .filter(|&k| HoldOut::one_fold(k, n).unwrap().includes_target(&t))
                .count();
            prop_assert_eq!(members, 1);
            prop_assert_eq!(HoldOut::every_fold(n).unwrap().prior_fold(&t), f);
            prop_assert!(HoldOut::every_fold(n).unwrap().includes_target(&t));
        }
    }
}
