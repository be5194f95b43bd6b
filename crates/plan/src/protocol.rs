//! The experimental protocol: the choices that make ferret's experiment (the default) or the
//! paper's reference code's (`--protocol paper`). See `docs/protocol.md`.

use serde::{Deserialize, Serialize};

use ferret_world::two_way_option as two_way;
pub use ferret_world::{AccessRule, ContainerSet, TravelCost};

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
        /// The reference code: between half and all but one of all the containers, drawn at
        /// random, plus every goal container, stay unsearched; the rest start out searched.
        Paper = "paper",
    }
);

two_way!(
    /// Which object types may be targets.
    TargetSet {
        /// Every small-object type inside a container (ferret).
        Pickupable = "pickupable",
        /// The reference code: uniform over the distinct types of the containers' objects, in
        /// the house's order, leaving out types that are also a top-level object of the house.
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

two_way!(
    /// Where the random draws of trials (target, initial belief) come from.
    TrialRng {
        /// ferret's own seeded streams, one per house and purpose.
        Ferret = "ferret",
        /// The reference code's: CPython's `random` seeded with the house's index, so houses
        /// at the reference's line indices get the reference's very trials.
        Python = "python",
    }
);

two_way!(
    /// The UCB score of a strategy never deployed.
    UntriedScore {
        /// −∞: every strategy is deployed once before any twice (the paper's text, ferret).
        First = "first",
        /// The reference code: 0 (its NaN and ∞ scores become 0), below every tried strategy
        /// whose lower bound is positive, above those whose bound is negative.
        Zero = "zero",
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
    /// The reported travel cost.
    #[serde(default)]
    pub travel_cost: TravelCost,
    /// The access point of a container.
    #[serde(default)]
    pub access: AccessRule,
    /// The trials' random draws.
    #[serde(default)]
    pub rng: TrialRng,
    /// UCB's score of an untried strategy.
    #[serde(default)]
    pub untried: UntriedScore,
}

impl Protocol {
    /// ferret's protocol (every default).
    pub const FERRET: Protocol = Protocol {
        initial_belief: InitialBelief::Empty,
        containers: ContainerSet::Receptacles,
        targets: TargetSet::Pickupable,
        replay: ReplayMode::Pessimistic,
        draw: DrawMode::Distinct,
        travel_cost: TravelCost::Plain,
        access: AccessRule::Footprint,
        rng: TrialRng::Ferret,
        untried: UntriedScore::First,
    };

    /// The paper's reference code's protocol.
    pub const PAPER: Protocol = Protocol {
        initial_belief: InitialBelief::Paper,
        containers: ContainerSet::Furniture,
        targets: TargetSet::Paper,
        replay: ReplayMode::Counterfactual,
        draw: DrawMode::Replacement,
        travel_cost: TravelCost::Soft,
        access: AccessRule::NearestFree,
        rng: TrialRng::Python,
        untried: UntriedScore::Zero,
    };

    /// The protocol of a name.
    pub fn named(name: ProtocolName) -> Protocol {
        match name {
            ProtocolName::Ferret => Self::FERRET,
            ProtocolName::Paper => Self::PAPER,
        }
    }

    /// The settings that decide which trials an eval run holds and what they cost (the others
    /// act at selection): runs differing in these cannot be compared or selected over together.
    pub fn trial_settings(&self) -> TrialSettings {
        TrialSettings {
            initial_belief: self.initial_belief,
            containers: self.containers,
            targets: self.targets,
            travel_cost: self.travel_cost,
            access: self.access,
            rng: self.rng,
        }
    }
}

/// The part of a [`Protocol`] fixed by an eval run (see [`Protocol::trial_settings`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TrialSettings {
    /// The initial belief.
    pub initial_belief: InitialBelief,
    /// The container set.
    pub containers: ContainerSet,
    /// The target set.
    pub targets: TargetSet,
    /// The reported travel cost.
    pub travel_cost: TravelCost,
    /// The access point rule.
    pub access: AccessRule,
    /// The trials' random draws.
    pub rng: TrialRng,
}

impl std::fmt::Display for TrialSettings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "initial belief {}, containers {}, targets {}, travel cost {}, access {}, rng {}",
            self.initial_belief,
            self.containers,
            self.targets,
            self.travel_cost,
            self.access,
            self.rng
        )
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
        assert_ne!(f.travel_cost, p.travel_cost);
        assert_ne!(f.access, p.access);
        assert_ne!(f.rng, p.rng);
        assert_ne!(f.untried, p.untried);
        assert_eq!(Protocol::named(ProtocolName::Paper), p);
        assert_eq!(
            serde_json::to_string(&p.replay).unwrap(),
            "\"counterfactual\""
        );
        // run.json files written before the newer settings existed still read.
        let old = r#"{"initial_belief":"paper","containers":"receptacles","targets":"paper","replay":"counterfactual","draw":"replacement"}"#;
        let p: Protocol = serde_json::from_str(old).unwrap();
        assert_eq!(p.travel_cost, TravelCost::Plain);
        assert_eq!(p.rng, TrialRng::Ferret);
    }
}
