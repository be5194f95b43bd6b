//! The experimental protocol: the choices that make ferret's experiment (the default) or the
//! paper's reference code's (`--protocol paper`). See `docs/protocol.md`.

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Serialize};

macro_rules! two_way {
    ($(#[$doc:meta])* $name:ident { $(#[$da:meta])* $a:ident = $sa:literal, $(#[$db:meta])* $b:ident = $sb:literal $(,)? }) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
        #[serde(rename_all = "lowercase")]
        pub enum $name {
            $(#[$da])*
            #[default]
            $a,
            $(#[$db])*
            $b,
        }

        impl $name {
            /// The option's values, default first.
            pub const VALUES: [&'static str; 2] = [$sa, $sb];
        }

        impl FromStr for $name {
            type Err = String;

            fn from_str(s: &str) -> Result<Self, Self::Err> {
                match s {
                    $sa => Ok(Self::$a),
                    $sb => Ok(Self::$b),
                    _ => Err(format!("`{s}`: expected `{}` or `{}`", $sa, $sb)),
                }
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(match self {
                    Self::$a => $sa,
                    Self::$b => $sb,
                })
            }
        }
    };
}

two_way!(
    /// A whole protocol at once; single switches override its parts.
    ProtocolName {
        /// ferret's defaults.
        Ferret = "ferret",
        /// The paper's reference code.
        Paper = "paper",
    }
);

two_way!(
    /// What the robot knows before a trial.
    InitialBelief {
        /// Nothing searched (the paper's text, ferret).
        Empty = "empty",
        /// The reference code: every goal container plus a random number, between half and all
        /// but one, of the other containers stay unsearched; the rest start out searched.
        Paper = "paper",
    }
);

two_way!(
    /// Which top-level objects are containers.
    ContainerSet {
        /// Receptacles of the asset database (ferret).
        Receptacles = "receptacles",
        /// The reference code: every top-level object except an ignore list.
        Furniture = "furniture",
    }
);

two_way!(
    /// Which object types may be targets.
    TargetSet {
        /// Every small-object type inside a container (ferret).
        Pickupable = "pickupable",
        /// The reference code: child object types that never appear as a top-level object of
        /// the house.
        Paper = "paper",
    }
);

two_way!(
    /// What a replay assumes about the target (paper section V-C).
    ReplayMode {
        /// Only in the container where it was found (the paper's text, ferret).
        Pessimistic = "pessimistic",
        /// The reference code: wherever it truly is; the replay stops at any goal container.
        Counterfactual = "counterfactual",
    }
);

two_way!(
    /// How a deployment draws its houses.
    DrawMode {
        /// Distinct houses (the paper's text, ferret).
        Distinct = "distinct",
        /// The reference code: with replacement.
        Replacement = "replacement",
    }
);

/// Every protocol setting, resolved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Protocol {
    /// The initial belief.
    pub initial_belief: InitialBelief,
    /// The container set.
    pub containers: ContainerSet,
    /// The target set.
    pub targets: TargetSet,
    /// The replay's assumption.
    pub replay: ReplayMode,
    /// The deployment draw.
    pub draw: DrawMode,
}

impl Protocol {
    /// ferret's protocol (every default).
    pub const FERRET: Protocol = Protocol {
        initial_belief: InitialBelief::Empty,
        containers: ContainerSet::Receptacles,
        targets: TargetSet::Pickupable,
        replay: ReplayMode::Pessimistic,
        draw: DrawMode::Distinct,
    };

    /// The paper's reference code's protocol.
    pub const PAPER: Protocol = Protocol {
        initial_belief: InitialBelief::Paper,
        containers: ContainerSet::Furniture,
        targets: TargetSet::Paper,
        replay: ReplayMode::Counterfactual,
        draw: DrawMode::Replacement,
    };

    /// The protocol of a name.
    pub fn named(name: ProtocolName) -> Protocol {
        match name {
            ProtocolName::Ferret => Self::FERRET,
            ProtocolName::Paper => Self::PAPER,
        }
    }

    /// The settings that decide which trials an eval run holds (the others act at selection):
    /// runs differing in these cannot be compared or selected over together.
    pub fn trial_settings(&self) -> (InitialBelief, ContainerSet, TargetSet) {
        (self.initial_belief, self.containers, self.targets)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_protocols_differ_in_every_setting() {
        for v in ReplayMode::VALUES {
            assert_eq!(v.parse::<ReplayMode>().unwrap().to_string(), v);
        }
        assert!("optimistic".parse::<ReplayMode>().is_err());
        assert_eq!(Protocol::default(), Protocol::FERRET);
        let (f, p) = (Protocol::FERRET, Protocol::PAPER);
        assert_ne!(f.initial_belief, p.initial_belief);
        assert_ne!(f.containers, p.containers);
        assert_ne!(f.targets, p.targets);
        assert_ne!(f.replay, p.replay);
        assert_ne!(f.draw, p.draw);
        assert_eq!(Protocol::named(ProtocolName::Paper), p);
        assert_eq!(
            serde_json::to_string(&p.replay).unwrap(),
            "\"counterfactual\""
        );
    }
}
