//! The object-search problem a strategy solves: what the robot knows (the house and its travel
//! distances) and what it is asked (the target, the containers searched before). Every
//! consumer — the simulator, a robot's step-by-step search, offline replay, the services —
//! plans on this one type.

use ferret_world::{Distances, House, ObjectType};
use serde::{Deserialize, Serialize};

use std::sync::Arc;

use crate::plan_memo::PlanMemo;
use crate::replay_memo::ReplayMemo;

/// One house, one target, one start pose (the house's), and containers revealed beforehand.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrialSpec {
    /// The object type to find.
    pub target: ObjectType,
    /// Containers known to be searched before the trial starts (usually none).
    pub revealed: Vec<usize>,
}

/// One object-search problem: the map the robot knows, travel distances on it, and the trial
/// (what to find, what was searched before it began). The ground truth is not part of it: a
/// robot never knows it, so simulations and replays pass it beside the problem.
#[derive(Clone, Copy, Debug)]
pub struct SearchProblem<'a> {
    /// The known map: rooms, containers, the start pose.
    pub house: &'a House,
    /// Travel distances between the start and the containers' access points.
    pub distances: &'a Distances,
    /// The target and the containers searched beforehand.
    pub trial: &'a TrialSpec,
    /// Replays already computed in this house from this start, when the caller keeps them.
    memo: Option<&'a ReplayMemo>,
    /// First steps of plans solved in this house, when the caller keeps them.
    plans: Option<&'a Arc<PlanMemo>>,
}

impl<'a> SearchProblem<'a> {
    /// The problem of `trial` in `house`.
    pub fn new(house: &'a House, distances: &'a Distances, trial: &'a TrialSpec) -> Self {
        Self {
            house,
            distances,
            trial,
            memo: None,
            plans: None,
        }
    }

    /// The same problem, its replays looked up in and added to `memo`. The memo must belong to
    /// this house seen from this start (these distances); see [`ReplayMemo`].
    pub fn with_replay_memo(self, memo: &'a ReplayMemo) -> Self {
        Self {
            memo: Some(memo),
            ..self
        }
    }

    /// The same problem, its model strategies taking first decisions over candidate sets
    /// solved before from `memo` (the same decisions, without solving). The memo must belong
    /// to this house on this grid (any start); see [`PlanMemo`].
    pub fn with_plan_memo(self, memo: &'a Arc<PlanMemo>) -> Self {
        Self {
            plans: Some(memo),
            ..self
        }
    }

    /// The plan memo given with [`with_plan_memo`](Self::with_plan_memo).
    pub fn plan_memo(&self) -> Option<&'a Arc<PlanMemo>> {
        self.plans
    }

    /// The replay memo given with [`with_replay_memo`](Self::with_replay_memo).
    pub fn replay_memo(&self) -> Option<&'a ReplayMemo> {
        self.memo
    }

    /// The object type searched for.
    pub fn target(&self) -> &'a ObjectType {
        &self.trial.target
    }
}
