//! The object-search problem a strategy solves: what the robot knows (the house and its travel
//! distances) and what it is asked (the target, the containers searched before). Every
//! consumer — the simulator, a robot's step-by-step search, offline replay, the services —
//! plans on this one type.

use ferret_world::{Distances, House, ObjectType};

use crate::trial::TrialSpec;

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
}

impl<'a> SearchProblem<'a> {
    /// The problem of `trial` in `house`.
    pub fn new(house: &'a House, distances: &'a Distances, trial: &'a TrialSpec) -> Self {
        Self {
            house,
            distances,
            trial,
        }
    }

    /// The object type searched for.
    pub fn target(&self) -> &'a ObjectType {
        &self.trial.target
    }
}
