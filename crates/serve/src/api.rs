//! The JSON bodies of the HTTP API, with their OpenAPI schemas.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::store::TrialStatus;

/// `POST /scenes`.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct UploadScene {
    /// Makes a retried request harmless.
    #[serde(default)]
    pub request_id: Option<String>,
    /// The scene, as in a scene file (version 1, without `map`).
    #[schema(value_type = Object)]
    pub scene: serde_json::Value,
}

/// `POST /deployments`.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateDeployment {
    /// Makes a retried request harmless.
    #[serde(default)]
    pub request_id: Option<String>,
    /// Candidate strategies (names the server was started with); default: all of them.
    #[serde(default)]
    pub strategies: Option<Vec<String>>,
    /// `replay` (default) or `ucb`.
    #[serde(default)]
    #[schema(value_type = Option<String>, example = "replay")]
    pub selector: Option<ferret_select::Method>,
    /// Exploration constant, metres (default 5).
    #[serde(default)]
    pub c: Option<f64>,
    /// Seed of the selector's tie breaks (default 0).
    #[serde(default)]
    pub seed: Option<u64>,
}

/// `POST /deployments/{id}/trials`.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct StartTrial {
    /// Makes a retried request harmless.
    #[serde(default)]
    pub request_id: Option<String>,
    /// The scene's name.
    pub scene: String,
    /// The object type to find, CamelCase (`CellPhone`).
    pub target: String,
    /// The robot's pose `[x, y, yaw°]` in the map frame; default: the scene's start.
    #[serde(default)]
    pub pose: Option<[f64; 3]>,
}

/// `POST /trials/{id}/observations`.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Observe {
    /// Makes a retried request harmless.
    #[serde(default)]
    pub request_id: Option<String>,
    /// The id of the container searched.
    pub container: String,
    /// Whether the target was in it.
    pub found: bool,
    /// Other object types seen in it (CamelCase).
    #[serde(default)]
    pub objects: Vec<String>,
    /// The robot's own odometry for this leg, metres.
    #[serde(default)]
    pub travelled_m: Option<f64>,
}

/// A scene in the list.
#[derive(Debug, Serialize, ToSchema)]
pub struct SceneSummary {
    /// Its name.
    pub name: String,
    /// Number of rooms.
    pub rooms: usize,
    /// Number of containers.
    pub containers: usize,
    /// Whether it navigates on a robot's map.
    pub has_map: bool,
}

/// A room of a scene.
#[derive(Debug, Serialize, ToSchema)]
pub struct RoomInfo {
    /// Its name.
    pub name: String,
    /// Its type.
    #[serde(rename = "type")]
    pub room_type: String,
    /// Floor outline `[[x, y], ...]`.
    pub polygon: Vec<[f64; 2]>,
}

/// A container of a scene.
#[derive(Debug, Serialize, ToSchema)]
pub struct ContainerInfo {
    /// Its id.
    pub id: String,
    /// Its type.
    #[serde(rename = "type")]
    pub object_type: String,
    /// Its room's name.
    pub room: Option<String>,
    /// Centre x, metres.
    pub x: f64,
    /// Centre y, metres.
    pub y: f64,
    /// Where the robot stands to search it (the access cell's centre).
    pub access: Option<[f64; 2]>,
    /// What the scene file says it holds (for simulated robots; planners never see it).
    pub contents: Vec<String>,
}

/// `GET /scenes/{name}`.
#[derive(Debug, Serialize, ToSchema)]
pub struct SceneDetail {
    /// Its name.
    pub name: String,
    /// Rooms.
    pub rooms: Vec<RoomInfo>,
    /// Containers.
    pub containers: Vec<ContainerInfo>,
    /// The start pose `[x, y, yaw°]`.
    pub start: [f64; 3],
    /// Travel distances, metres: from `start` and from every container id to every container id.
    pub distances_m: BTreeMap<String, BTreeMap<String, f64>>,
}

/// Where to search next.
#[derive(Clone, Debug, Serialize, Deserialize, ToSchema)]
pub struct NextContainer {
    /// The container's id.
    pub container: String,
    /// Its type.
    #[serde(rename = "type")]
    pub object_type: String,
    /// Its room's name.
    pub room: Option<String>,
    /// Its centre x, metres.
    pub x: f64,
    /// Its centre y, metres.
    pub y: f64,
    /// Length of `path`, metres.
    pub distance_m: f64,
    /// Cell centres from where the robot is to the container's access point.
    pub path: Vec<[f64; 2]>,
}

/// A trial.
#[derive(Clone, Debug, Serialize, Deserialize, ToSchema)]
pub struct TrialState {
    /// Its id.
    pub trial: i64,
    /// Its deployment.
    pub deployment: i64,
    /// 1-based position in the deployment.
    pub k: i64,
    /// The scene's name.
    pub scene: String,
    /// The target.
    pub target: String,
    /// The strategy selection chose for it.
    pub strategy: String,
    /// Where it stands.
    pub status: TrialStatus,
    /// Containers searched so far, in order.
    pub searched: Vec<String>,
    /// Map distance travelled so far, metres (the cost selection learns from).
    pub cost_m: f64,
    /// Sum of the robot's reported odometry, when it reported any.
    pub travelled_m: Option<f64>,
    /// Where to search next (while searching).
    pub next: Option<NextContainer>,
    /// Every candidate's replay cost (done trials).
    pub replays_m: Option<BTreeMap<String, f64>>,
}

/// A strategy's row in a deployment.
#[derive(Debug, Serialize, ToSchema)]
pub struct StrategyRow {
    /// The strategy.
    pub strategy: String,
    /// Trials in which it was deployed.
    pub deployed: usize,
    /// Its mean cost where deployed, metres.
    pub mean_cost_m: Option<f64>,
    /// Mean over all done trials of its real or replayed cost, metres.
    pub replay_mean_m: Option<f64>,
    /// Its selection score for the next trial (lower wins); null means "must be tried".
    pub score: Option<f64>,
}

/// A trial in a deployment's list.
#[derive(Debug, Serialize, ToSchema)]
pub struct TrialSummary {
    /// Its id.
    pub trial: i64,
    /// 1-based position.
    pub k: i64,
    /// The target.
    pub target: String,
    /// The strategy.
    pub strategy: String,
    /// Where it stands.
    pub status: TrialStatus,
    /// Its cost, once ended.
    pub cost_m: Option<f64>,
}

/// The next choice.
#[derive(Debug, Serialize, ToSchema)]
pub struct NextChoice {
    /// The strategy the next trial will deploy.
    pub strategy: String,
    /// Why, in one sentence.
    pub why: String,
}

/// `GET /deployments/{id}`.
#[derive(Debug, Serialize, ToSchema)]
pub struct DeploymentState {
    /// Its id.
    pub id: i64,
    /// `replay` or `ucb`.
    pub selector: String,
    /// Exploration constant, metres.
    pub c: f64,
    /// Seed of the tie breaks.
    pub seed: u64,
    /// Candidates, in order.
    pub strategies: Vec<String>,
    /// Its trials.
    pub trials: Vec<TrialSummary>,
    /// Per-strategy statistics.
    pub per_strategy: Vec<StrategyRow>,
    /// The trial in progress.
    pub open_trial: Option<i64>,
    /// What the next trial will deploy.
    pub next: NextChoice,
}

/// Error body.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct ErrorBody {
    /// The error.
    pub error: ErrorDetail,
}

/// What went wrong.
#[derive(Debug, Serialize, Deserialize, ToSchema)]
pub struct ErrorDetail {
    /// HTTP status.
    pub status: u16,
    /// The request field at fault (empty when the request as a whole is).
    pub field: String,
    /// What is wrong.
    pub message: String,
}
