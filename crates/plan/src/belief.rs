//! The robot's belief during a trial (paper appendix B).

use ferret_world::{Distances, House, ObjectType, Place};

use crate::task::Task;

/// What the robot knows during a trial: the map (house and distances), what it is asked, where
/// it is, which containers it has searched, what they held and so which targets it has found.
/// It holds no ground truth.
#[derive(Clone, Debug)]
pub struct Belief<'a> {
    /// The known map.
    pub house: &'a House,
    /// Travel distances between places of the map.
    pub distances: &'a Distances,
    /// What the robot is asked.
    pub task: &'a Task,
    position: Place,
    searched: Vec<bool>,
    order: Vec<usize>,
    observed: Vec<Vec<ObjectType>>,
    /// The container each target (task order) was first seen in.
    found: Vec<Option<usize>>,
    travelled: f64,
}

impl<'a> Belief<'a> {
    /// The belief at the start of a trial: at the start pose, nothing searched.
    pub fn new(house: &'a House, distances: &'a Distances, task: &'a Task) -> Self {
        let n = house.containers.len();
        Self {
            house,
            distances,
            task,
            position: Place::Start,
            searched: vec![false; n],
            order: Vec::new(),
            observed: vec![Vec::new(); n],
            found: vec![None; task.targets().len()],
            travelled: 0.0,
        }
    }

    /// The container where target `t` (an index into the task's targets) was first seen.
    pub fn found(&self, t: usize) -> Option<usize> {
        self.found.get(t).copied().flatten()
    }

    /// Where each target (task order) was first seen.
    pub fn found_each(&self) -> &[Option<usize>] {
        &self.found
    }

    /// True once the task's goal holds: every target found (`all`) or one (`any`).
    pub fn goal_holds(&self) -> bool {
        self.task.holds(self.found.iter().map(Option::is_some))
    }

    /// The first target of the task not yet found (the first one when all are): what a policy
    /// that looks for one thing at a time looks for.
    pub fn sought(&self) -> &'a ObjectType {
        let t = self.found.iter().position(Option::is_none).unwrap_or(0);
        &self.task.targets()[t]
    }

    /// Where the robot is.
    pub fn position(&self) -> Place {
        self.position
    }

    /// True when container `c` was searched.
    pub fn is_searched(&self, c: usize) -> bool {
        self.searched.get(c).copied().unwrap_or(false)
    }

    /// Containers not yet searched, in index order.
    pub fn unsearched(&self) -> impl Iterator<Item = usize> + '_ {
        (0..self.searched.len()).filter(|&c| !self.searched[c])
    }

    /// Number of unsearched containers.
    pub fn unsearched_count(&self) -> usize {
        self.searched.iter().filter(|s| !**s).count()
    }

    /// The searched containers in the order they were searched.
    pub fn searched_in_order(&self) -> &[usize] {
        &self.order
    }

    /// What a searched container held (empty if unsearched).
    pub fn observed(&self, c: usize) -> &[ObjectType] {
        self.observed.get(c).map_or(&[], Vec::as_slice)
    }

    /// Distance travelled so far, metres.
    pub fn travelled(&self) -> f64 {
        self.travelled
    }

    /// Distance from the robot's position to container `c`, metres.
    pub fn distance_to(&self, c: usize) -> f64 {
        self.distances.between(self.position, Place::Container(c))
    }

    /// The belief update of paper appendix B: the robot travels to `c`, searches it and sees what
    /// it holds; `c` is marked searched and its contents are added to the map. Returns the distance
    /// travelled for this leg.
    pub fn search(&mut self, c: usize, contents: Vec<ObjectType>) -> f64 {
        let leg = self.distance_to(c);
        self.travelled += leg;
        self.position = Place::Container(c);
        if let Some(s) = self.searched.get_mut(c) {
            *s = true;
        }
        self.note_found(c, &contents);
        if let Some(o) = self.observed.get_mut(c) {
            *o = contents;
        }
        self.order.push(c);
        leg
    }

    /// The robot travels to `c` without learning anything (a container a teammate searched
    /// while it was on its way); returns the leg, metres.
    pub fn visit(&mut self, c: usize) -> f64 {
        let leg = self.distance_to(c);
        self.travelled += leg;
        self.position = Place::Container(c);
        leg
    }

    /// Marks as found in `c` every target of the task among `contents` not found before.
    fn note_found(&mut self, c: usize, contents: &[ObjectType]) {
        for (t, found) in self.task.targets().iter().zip(&mut self.found) {
            if found.is_none() && contents.contains(t) {
                *found = Some(c);
            }
        }
    }

    /// Adds the last leg to the destination (metres) to the distance travelled.
    pub(crate) fn arrive(&mut self, leg: f64) {
        self.travelled += leg;
    }

    /// Marks `c` as searched, holding `contents`, without moving (containers revealed before
    /// the trial).
    pub fn reveal(&mut self, c: usize, contents: Vec<ObjectType>) {
        if let Some(s) = self.searched.get_mut(c) {
            *s = true;
        }
        self.note_found(c, &contents);
        if let Some(o) = self.observed.get_mut(c) {
            *o = contents;
        }
    }
}
