//! What the service's parts share: the reply of a request, where a trial stands, and the rows
//! the store keeps. The wire types of the HTTP API live in [`api`](crate::api), the storage in
//! [`store`](crate::store); both, and the service's resources, read their data from here, so no
//! two of them import each other.

use ferret_select::Method;
use serde::{Deserialize, Serialize};

/// What a request did: read or changed something, or created it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Read, or done to something that exists (also: the same upload again).
    Done,
    /// Created a scene, a deployment or a trial.
    Created,
}

/// A reply: what the request did and the JSON text of its result. Kept as text so that a
/// retried request gets the very bytes of the first reply (a float parsed back from JSON may
/// differ in its last digit).
#[derive(Clone, Debug, PartialEq)]
pub struct ApiReply {
    /// What the request did.
    pub outcome: Outcome,
    /// The result as JSON.
    pub body: String,
}

/// How a deployment was created.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DeploymentSpec {
    /// Candidate strategies, by name.
    pub strategies: Vec<String>,
    /// Selection method.
    pub selector: Method,
    /// Exploration constant, metres.
    pub c: f64,
    /// Seed of the selector's tie breaks.
    pub seed: u64,
    /// One trial at a time (the paper's setting): a second open trial is refused. Otherwise
    /// several robots may run trials of the deployment at once.
    #[serde(default)]
    pub sequential: bool,
}

/// A stored deployment.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredDeployment {
    /// Its id.
    pub id: i64,
    /// How it was created.
    pub spec: DeploymentSpec,
}

/// Where a trial stands.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum TrialStatus {
    /// The robot is searching.
    Searching,
    /// The target was found; the trial counts for selection.
    Done,
    /// Every container was searched without finding the target; the trial does not count.
    Exhausted,
    /// The robot gave the search up; the trial does not count.
    Abandoned,
}

impl TrialStatus {
    pub(crate) fn as_str(self) -> &'static str {
        match self {
            TrialStatus::Searching => "searching",
            TrialStatus::Done => "done",
            TrialStatus::Exhausted => "exhausted",
            TrialStatus::Abandoned => "abandoned",
        }
    }

    pub(crate) fn parse(s: &str) -> Option<Self> {
        match s {
            "searching" => Some(TrialStatus::Searching),
            "done" => Some(TrialStatus::Done),
            "exhausted" => Some(TrialStatus::Exhausted),
            "abandoned" => Some(TrialStatus::Abandoned),
            _ => None,
        }
    }
}

/// A stored trial.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredTrial {
    /// Its id.
    pub id: i64,
    /// Its deployment.
    pub deployment: i64,
    /// 1-based position in the deployment.
    pub k: i64,
    /// The scene's name.
    pub scene: String,
    /// The target type; for a household task, its targets joined by `+` (all) or `|` (any).
    pub target: String,
    /// The robot's pose at the start, when given (else the scene's start).
    pub pose: Option<[f64; 3]>,
    /// Index of the chosen strategy in the deployment's list.
    pub chosen: usize,
    /// Where it stands.
    pub status: TrialStatus,
    /// Map-distance cost, metres, once ended.
    pub cost: Option<f64>,
    /// Every candidate's replay cost (entry `chosen` = `cost`), once done.
    pub replays: Option<Vec<f64>>,
    /// How many trials of the deployment had ended when it started (its choice was made from
    /// those).
    pub started_after: i64,
    /// Its place (1-based) among the deployment's trials in the order they ended, once ended.
    pub end_seq: Option<i64>,
    /// Its household task (targets, goal, destination); `None` for one target.
    pub task: Option<TaskBody>,
    /// The robots of a team that searches it together; `None` for one robot.
    pub robots: Option<Vec<TeamRobot>>,
    /// The robot that started it alone and named itself, if it did.
    pub robot: Option<String>,
    /// When a robot last reported on it (start, observation, end; Unix milliseconds); `None`
    /// for trials stored before this was kept.
    pub heard_ms: Option<i64>,
}

/// Whose a trial is, as lists and events name it: the robot that started it alone and named
/// itself, else its team's robots joined by `,` (`None` for a robot that gave no name).
pub(crate) fn whose<'a>(
    robot: Option<&str>,
    team: impl Iterator<Item = &'a str>,
) -> Option<String> {
    if let Some(r) = robot {
        return Some(r.to_string());
    }
    let ids: Vec<&str> = team.collect();
    (!ids.is_empty()).then(|| ids.join(","))
}

/// One search reported by the robot.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredObservation {
    /// The container's id.
    pub container: String,
    /// Whether the target was there.
    pub found: bool,
    /// Other object types seen in it.
    pub objects: Vec<String>,
    /// The robot's own odometry for the leg, when reported.
    pub travelled: Option<f64>,
    /// The leg's map distance, metres.
    pub leg: f64,
    /// The robot of a team that searched it.
    pub robot: Option<String>,
}

/// A stored reply to a request with a `request_id`.
#[derive(Clone, Debug, PartialEq)]
pub struct StoredReply {
    /// SHA-256 of route and body, to tell a retry from a reuse of the id.
    pub fingerprint: String,
    /// What the request did.
    pub outcome: Outcome,
    /// JSON body.
    pub body: String,
}

/// What one uploaded scene and the store may hold. Planning a scene costs memory in proportion
/// to its grid cells and time in proportion to cells × containers, so both are bounded before a
/// grid is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SceneLimits {
    /// Uploaded scenes the store may hold (413 past it).
    pub max_scenes: usize,
    /// Grid cells of an uploaded scene at the server's resolution (422 past it).
    pub max_cells: u64,
    /// Containers of an uploaded scene, and obstacles likewise (422 past it).
    pub max_containers: usize,
    /// Vertices of all room polygons of an uploaded scene together (422 past it).
    pub max_vertices: usize,
}

impl Default for SceneLimits {
    fn default() -> Self {
        Self {
            max_scenes: 1000,
            max_cells: 4_000_000,
            max_containers: 200,
            max_vertices: 1000,
        }
    }
}

/// Whether a task wants every target or any one.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "lowercase")]
pub enum GoalName {
    /// Every target.
    #[default]
    All,
    /// Any one of them.
    Any,
}

impl From<GoalName> for ferret_plan::Goal {
    fn from(g: GoalName) -> Self {
        match g {
            GoalName::All => ferret_plan::Goal::All,
            GoalName::Any => ferret_plan::Goal::Any,
        }
    }
}

/// Where a task brings what it found, in the scene's names and map frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(tag = "kind", rename_all = "lowercase", deny_unknown_fields)]
pub enum DestinationBody {
    /// Back where the trial started ("bring it to me").
    Start,
    /// At a container, where the robot stands to search it.
    Container {
        /// The container's id.
        #[schema(min_length = 1)]
        id: String,
    },
    /// In a room, at the reachable point nearest its centre.
    Room {
        /// The room's name.
        #[schema(min_length = 1)]
        name: String,
    },
    /// At a point of the floor (the reachable point nearest it, within 0.5 m).
    Point {
        /// x, metres.
        #[schema(minimum = -100000.0, maximum = 100000.0)]
        x: f64,
        /// y, metres.
        #[schema(minimum = -100000.0, maximum = 100000.0)]
        y: f64,
    },
}

/// A trial's household task as stored: its targets, goal and destination.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskBody {
    /// The targets, in order.
    pub targets: Vec<String>,
    /// All or any.
    pub goal: GoalName,
    /// Where to bring them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub destination: Option<DestinationBody>,
}

/// A robot of a team trial: its id and where it starts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TeamRobot {
    /// How the robot names itself in every request of the trial: 1 to 64 letters, digits,
    /// `_`, `-`, `.` or `/` (a ROS namespace serves).
    #[schema(pattern = r"^[A-Za-z0-9_./-]{1,64}$")]
    pub id: String,
    /// Its pose `[x, y, yaw°]` in the map frame; default: the trial's start.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Vec<f64>>, min_items = 3, max_items = 3)]
    pub pose: Option<[f64; 3]>,
}

/// A team robot's row: its claim and when it was last heard from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StoredRobot {
    /// Its id.
    pub robot: String,
    /// The container it claimed, if any, and when the claim lapses (ms since the Unix epoch).
    pub claim: Option<(String, i64)>,
    /// When it last called, ms since the Unix epoch.
    pub heard_ms: i64,
}
