//! The rows of a run and their unit, below everything else of a run: one [`TrialRow`] per trial
//! and strategy (a line of `trials.csv`), and the paper's cost unit [`CELL_M`]. Summaries, run
//! files, shards and their merge all read these and nothing here reads them.

use serde::{Deserialize, Serialize};

/// One row of `trials.csv`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrialRow {
    /// House label.
    pub house: String,
    /// House index in its file.
    pub house_index: usize,
    /// Target object type.
    pub target: String,
    /// Strategy spec.
    pub strategy: String,
    /// Distance travelled, metres.
    pub cost_m: f64,
    /// Containers searched.
    pub searches: usize,
    /// Whether the target was found.
    pub found: bool,
    /// Id of the container where it was found.
    pub found_container: String,
    /// Ids of the containers searched, in order, space separated.
    pub searched: String,
    /// Number of containers holding the target.
    pub goal_containers: usize,
    /// Distance travelled in the paper's 0.05 m grid cells, when asked for (absent otherwise,
    /// so that the default file has the columns above only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost_cells: Option<f64>,
    /// The task's goal, `all` or `any`, in a run of household tasks (these last four columns
    /// are absent otherwise; `target` is then the targets joined by `+` for all and `|` for
    /// any, `found` whether the goal held, `found_container` where it came to hold and
    /// `goal_containers` the containers holding any target).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub goal: Option<String>,
    /// Where the robot brought what it found (`start`, `container:<id>`, `room:<id>`,
    /// `<x>,<z>`), empty for nowhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub destination: Option<String>,
    /// Where each target (in the task's order) was first seen, space separated, `-` for not
    /// found.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub found_each: Option<String>,
    /// The last leg, to the destination, metres (part of `cost_m`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub delivery_m: Option<f64>,
    /// Robots of the team, in a run of teams (these last three columns are absent otherwise;
    /// `cost_m` is then the makespan: metres until the goal held, and with a destination the
    /// last robot carrying a target stood there).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robots: Option<usize>,
    /// Metres driven by the whole team.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub total_travel_m: Option<f64>,
    /// Which robot (0 first) searched each container of `searched`, space separated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub searched_by: Option<String>,
}

/// The paper's unit of cost: a grid cell of 0.05 m (its table I is in these cells).
pub const CELL_M: f64 = 0.05;
