//! A target's name as a person or a robot's operator types it, checked against the object types
//! a scene lists. A name the scene does not list can only end "not found" after every container
//! was searched, so it is refused at once; a name that differs from a listed one only in case,
//! spaces or punctuation (`wallet`, `remote control`), or by a typo (`Walet`), is suggested. A
//! scene that lists no objects (a real home, where nobody wrote down what is where) has no
//! vocabulary to check against, and any name passes.

use std::collections::BTreeSet;

use crate::house::ObjectType;

/// Least similarity (normalised Levenshtein, case folded) of a typo to the name meant: one
/// letter off in a long name (`Walet`, `AlarmClok`), not merely a similar word (`Toaster` is
/// not `Tomato`).
const SIMILAR: f64 = 0.8;

/// A target name the scene does not list.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("{}", self.describe())]
pub struct UnknownTarget {
    /// The name given.
    pub name: String,
    /// The listed type it most likely means, if one is close.
    pub suggestion: Option<ObjectType>,
    /// Every type the scene lists, sorted.
    pub known: Vec<ObjectType>,
}

impl UnknownTarget {
    fn describe(&self) -> String {
        match &self.suggestion {
            Some(s) => format!(
                "unknown target {:?}: did you mean {:?}?",
                self.name,
                s.as_str()
            ),
            None => format!(
                "unknown target {:?}: the scene holds {} object types: {}",
                self.name,
                self.known.len(),
                self.known
                    .iter()
                    .map(ObjectType::as_str)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
        }
    }
}

/// `name` as one of `known` (the object types a scene lists); any name when `known` is empty.
///
/// # Errors
/// [`UnknownTarget`] for a name not listed, with the listed type it most likely means.
pub fn check_target(name: &str, known: &BTreeSet<ObjectType>) -> Result<ObjectType, UnknownTarget> {
    let given = ObjectType::new(name);
    if known.is_empty() || known.contains(&given) {
        return Ok(given);
    }
    let squashed = |s: &str| -> String {
        s.chars()
            .filter(|c| c.is_alphanumeric())
            .flat_map(char::to_lowercase)
            .collect()
    };
    let wanted = squashed(name);
    let suggestion = known
        .iter()
        .find(|k| squashed(k.as_str()) == wanted)
        .or_else(|| {
            known
                .iter()
                .map(|k| {
                    (
                        k,
                        strsim::normalized_levenshtein(&squashed(k.as_str()), &wanted),
                    )
                })
                .filter(|(_, s)| *s >= SIMILAR)
                .max_by(|a, b| a.1.total_cmp(&b.1))
                .map(|(k, _)| k)
        })
        .cloned();
    Err(UnknownTarget {
        name: name.to_string(),
        suggestion,
        known: known.iter().cloned().collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn known(names: &[&str]) -> BTreeSet<ObjectType> {
        names.iter().map(|n| ObjectType::new(*n)).collect()
    }

    #[test]
    fn a_listed_name_passes_and_a_near_one_is_suggested() {
        let k = known(&["Wallet", "RemoteControl", "Tomato", "AlarmClock"]);
        assert_eq!(check_target("Wallet", &k), Ok(ObjectType::new("Wallet")));
        let suggested = |n: &str| check_target(n, &k).unwrap_err().suggestion;
        assert_eq!(suggested("wallet"), Some(ObjectType::new("Wallet")));
        assert_eq!(
            suggested("remote control"),
            Some(ObjectType::new("RemoteControl"))
        );
        assert_eq!(suggested("Walet"), Some(ObjectType::new("Wallet")));
        assert_eq!(suggested("AlarmClok"), Some(ObjectType::new("AlarmClock")));
        assert_eq!(suggested("Toaster"), None);
        let message = check_target("wallet", &k).unwrap_err().to_string();
        assert_eq!(
            message,
            r#"unknown target "wallet": did you mean "Wallet"?"#
        );
        let listed = check_target("Toaster", &k).unwrap_err().to_string();
        assert!(listed.contains("4 object types: AlarmClock, RemoteControl, Tomato, Wallet"));
    }

    #[test]
    fn a_scene_that_lists_nothing_takes_any_name() {
        assert_eq!(
            check_target("Anything", &BTreeSet::new()),
            Ok(ObjectType::new("Anything"))
        );
    }

    proptest! {
        /// Exactly the listed names pass; a refused one's suggestion is always a listed name.
        #[test]
        fn only_listed_names_pass(names in prop::collection::btree_set("[A-Za-z]{1,8}", 1..6), given in "[A-Za-z ]{1,9}") {
            let k: BTreeSet<ObjectType> = names.iter().map(|n| ObjectType::new(n.as_str())).collect();
            match check_target(&given, &k) {
                Ok(t) => prop_assert!(k.contains(&t) && t.as_str() == given),
                Err(e) => {
                    prop_assert!(!names.contains(&given));
                    prop_assert!(e.suggestion.is_none_or(|s| k.contains(&s)));
                    prop_assert_eq!(e.known.len(), k.len());
                }
            }
        }
    }
}
