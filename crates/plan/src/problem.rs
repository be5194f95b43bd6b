//! The object-search problem a strategy solves: what the robot knows (the house and its travel
//! distances) and what it is asked (the task, the containers searched before). Every
//! consumer — the simulator, a robot's step-by-step search, offline replay, the services —
//! plans on this one type.

use ferret_world::{Distances, House, ObjectType};

use crate::task::{DestinationLegs, Task, TaskError};
use serde::{Deserialize, Serialize};

use std::sync::Arc;

use crate::plan_memo::PlanMemo;
use crate::replay_memo::ReplayMemo;

/// One house, one task (a target, or several with a goal and a destination), one start pose
/// (the house's), and containers revealed beforehand.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrialSpec {
    /// What the robot is asked.
    pub task: Task,
    /// Containers known to be searched before the trial starts (usually none).
    pub revealed: Vec<usize>,
}

impl TrialSpec {
    /// A trial of one target, nothing revealed.
    pub fn single(target: ObjectType) -> Self {
        Self {
            task: Task::single(target),
            revealed: Vec::new(),
        }
    }

    /// A trial of `task`, nothing revealed.
    pub fn of(task: Task) -> Self {
        Self {
            task,
            revealed: Vec::new(),
        }
    }
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
    /// The task's destination on this map, when the caller resolved it.
    destination: Option<&'a DestinationLegs>,
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
            destination: None,
        }
    }

    /// The same problem with its task's destination already resolved on this map (see
    /// [`Destination::legs`](crate::Destination::legs)): searches of it then need not resolve it
    /// themselves, which costs a search over the grid for a room or a point.
    pub fn with_destination(self, legs: &'a DestinationLegs) -> Self {
        Self {
            destination: Some(legs),
            ..self
        }
    }

    /// The task's destination on this map: the legs given with
    /// [`with_destination`](Self::with_destination), else resolved now; `None` for a task
    /// without one.
    ///
    /// # Errors
    /// What [`Destination::legs`](crate::Destination::legs) refuses.
    pub fn destination_legs(
        &self,
    ) -> Result<Option<std::borrow::Cow<'a, DestinationLegs>>, TaskError> {
        if let Some(l) = self.destination {
            return Ok(Some(std::borrow::Cow::Borrowed(l)));
        }
        self.trial
            .task
            .destination()
            .map(|d| {
                d.legs(self.house, self.distances)
                    .map(std::borrow::Cow::Owned)
            })
            .transpose()
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

    /// What the robot is asked.
    pub fn task(&self) -> &'a Task {
        &self.trial.task
    }
}
