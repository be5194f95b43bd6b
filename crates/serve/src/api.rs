//! The JSON bodies of the HTTP API, with their OpenAPI schemas. The schemas state what the
//! service enforces (lengths, patterns, bounds, enums); what JSON Schema cannot express (a
//! container in no room, a pose in a wall) is a 422 naming the field.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};
use utoipa::ToSchema;

use crate::model::TrialStatus;
pub use crate::model::{DestinationBody, GoalName, TaskBody, TeamRobot};

/// Longest accepted request id, characters.
pub const MAX_REQUEST_ID: usize = 200;

/// Largest exploration constant `c`, metres (the default is 5; costs are tens of metres).
pub const MAX_C: f64 = 1000.0;

/// Largest seed: 2^53 − 1, the largest integer every JSON client reads exactly.
pub const MAX_SEED: u64 = (1 << 53) - 1;

/// Largest odometry one observation may report, metres (100 km: no leg inside a home is longer,
/// and sums of such numbers stay exact).
pub const MAX_TRAVELLED_M: f64 = 100_000.0;

/// Longest object type name, characters.
pub const MAX_TYPE_NAME: usize = 100;

/// Most object types one observation may list.
pub const MAX_OBJECTS: usize = 1000;

/// An object or room type as the API takes it: ASCII letters and digits.
pub const TYPE_NAME_PATTERN: &str = "^[A-Za-z0-9]{1,100}$";

/// An object type as the API takes it ([`TYPE_NAME_PATTERN`]): ASCII letters and digits, as in
/// `CellPhone`.
pub(crate) fn is_type_name(s: &str) -> bool {
    !s.is_empty() && s.len() <= MAX_TYPE_NAME && s.chars().all(|c| c.is_ascii_alphanumeric())
}

/// A name or id in an uploaded scene: printable ASCII, at least one character not a space.
pub const UPLOAD_NAME_PATTERN: &str = "^[ -~]{0,99}[!-~][ -~]{0,99}$";

/// The JSON schema of an uploaded scene (the scene file format without `map`), with a server's
/// limits. What it cannot say is refused with 422 naming the field: a container in no room,
/// overlapping rooms, more grid cells or polygon vertices in all than the limits, an
/// unreachable container.
pub fn scene_schema(limits: &crate::model::SceneLimits) -> serde_json::Value {
    use serde_json::json;
    let max = ferret_world::procthor::MAX_COORDINATE;
    let coordinate = json!({"type": "number", "minimum": -max, "maximum": max});
    let point = json!({"type": "array", "items": coordinate, "minItems": 2, "maxItems": 2});
    let pose = json!({
        "type": "array", "items": coordinate, "minItems": 3, "maxItems": 3,
        "description": "[x, y, yaw°], metres and degrees counter-clockwise"
    });
    let size = json!({
        "type": "array", "minItems": 2, "maxItems": 2,
        "items": {"type": "number", "exclusiveMinimum": 0, "maximum": max}
    });
    let name =
        json!({"type": "string", "pattern": UPLOAD_NAME_PATTERN, "maxLength": MAX_TYPE_NAME});
    let type_name = json!({"type": "string", "pattern": TYPE_NAME_PATTERN});
    json!({
        "type": "object",
        "description": "A home: rooms, containers, the robot's start (see docs/serve.md).",
        "additionalProperties": false,
        "required": ["ferret_scene", "name", "rooms", "containers", "start"],
        "properties": {
            "ferret_scene": {"type": "integer", "enum": [ferret_world::scene::SCENE_VERSION]},
            "name": name,
            "rooms": {
                "type": "array", "minItems": 1, "maxItems": 254,
                "items": {
                    "type": "object", "additionalProperties": false,
                    "required": ["name", "type", "polygon"],
                    "properties": {
                        "name": name,
                        "type": type_name,
                        "polygon": {
                            "type": "array", "items": point, "minItems": 3,
                            "maxItems": limits.max_vertices
                        }
                    }
                }
            },
            "doors": {
                "type": "array",
                "items": {
                    "type": "object", "additionalProperties": false,
                    "required": ["from", "to"],
                    "properties": {"from": point, "to": point}
                }
            },
            "containers": {
                "type": "array", "minItems": 1, "maxItems": limits.max_containers,
                "items": {
                    "type": "object", "additionalProperties": false,
                    "required": ["id", "type", "pose"],
                    "properties": {
                        "id": name,
                        "type": type_name,
                        "room": name,
                        "pose": pose,
                        "size": size,
                        "access": point,
                        "contents": {"type": "array", "items": type_name}
                    }
                }
            },
            "obstacles": {
                "type": "array", "maxItems": limits.max_containers,
                "items": {
                    "type": "object", "additionalProperties": false,
                    "required": ["id", "type", "pose"],
                    "properties": {"id": name, "type": type_name, "pose": pose, "size": size}
                }
            },
            "start": pose
        }
    })
}

/// A write request that may carry a request id, in its `request_id` field or (as the IETF
/// Idempotency-Key draft has it) in an `Idempotency-Key` header, with the same meaning.
pub trait WithRequestId {
    /// The request's id.
    fn request_id_mut(&mut self) -> &mut Option<String>;
}

/// `POST /scenes`.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct UploadScene {
    /// Makes a retried request harmless.
    #[serde(default)]
    #[schema(min_length = 1, max_length = 200)]
    pub request_id: Option<String>,
    /// The scene, as in a scene file (version 1, without `map`); its schema, with this
    /// server's limits, is `Scene`.
    #[schema(value_type = Object)]
    pub scene: serde_json::Value,
}

/// How a deployment selects strategies: the name of a selection method (`replay`, the default,
/// or `ucb`). Its schema lists every method the select crate registers, so a new selector is
/// offered here without a change to the API code.
#[derive(Clone, Copy, Debug)]
pub struct Selector(pub ferret_select::Method);

impl<'de> Deserialize<'de> for Selector {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let name = std::borrow::Cow::<'de, str>::deserialize(d)?;
        ferret_select::Method::from_name(&name)
            .map(Selector)
            .ok_or_else(|| {
                let names = ferret_select::Method::ALL.map(|m| format!("`{}`", m.name()));
                serde::de::Error::custom(format!(
                    "unknown selector `{name}`, expected one of {}",
                    names.join(", ")
                ))
            })
    }
}

impl utoipa::PartialSchema for Selector {
    fn schema() -> utoipa::openapi::RefOr<utoipa::openapi::schema::Schema> {
        utoipa::openapi::ObjectBuilder::new()
            .schema_type(utoipa::openapi::schema::Type::String)
            .enum_values(Some(
                ferret_select::Method::ALL.map(ferret_select::Method::name),
            ))
            .description(Some(
                "How a deployment selects strategies: the name of a selection method \
                 (default `replay`, UCB constrained from below by offline replay costs).",
            ))
            .into()
    }
}

impl ToSchema for Selector {}

/// `POST /deployments`.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CreateDeployment {
    /// Makes a retried request harmless.
    #[serde(default)]
    #[schema(min_length = 1, max_length = 200)]
    pub request_id: Option<String>,
    /// Candidate strategies, each once (names of strategies the server was started with);
    /// default: all of them.
    #[serde(default)]
    #[schema(min_items = 1)]
    pub strategies: Option<Vec<String>>,
    /// `replay` (default) or `ucb`.
    #[serde(default)]
    pub selector: Option<Selector>,
    /// Exploration constant, metres (default 5).
    #[serde(default)]
    #[schema(minimum = 0.0, maximum = 1000.0)]
    pub c: Option<f64>,
    /// Seed of the selector's tie breaks (default 0).
    #[serde(default, deserialize_with = "integer_valued")]
    #[schema(minimum = 0, maximum = 9007199254740991_i64)]
    pub seed: Option<u64>,
    /// One trial at a time, as in the paper (default false: several robots may run trials of
    /// the deployment at once, each chosen from the trials ended before it started).
    #[serde(default)]
    pub sequential: Option<bool>,
}

/// A non-negative integer as JSON Schema counts one: `2232.0` is the integer 2232, as many JSON
/// encoders write it. An integral number too large for `u64` becomes `u64::MAX`, so that the
/// bound check names the field (422) as for any other seed too large.
fn integer_valued<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Option<u64>, D::Error> {
    use serde::de::Error;
    let Some(n) = Option::<serde_json::Number>::deserialize(d)? else {
        return Ok(None);
    };
    if let Some(v) = n.as_u64() {
        return Ok(Some(v));
    }
    match n.as_f64() {
        Some(f) if f >= 0.0 && f.fract() == 0.0 => {
            // Exact below 2^64; the bound check refuses everything from 2^53 on anyway.
            #[allow(clippy::cast_possible_truncation, clippy::cast_sign_loss)]
            let v = if f < 18_446_744_073_709_551_616.0 {
                f as u64
            } else {
                u64::MAX
            };
            Ok(Some(v))
        }
        _ => Err(D::Error::custom(format!(
            "invalid value: {n}, expected a non-negative integer"
        ))),
    }
}

/// `POST /deployments/{id}/trials`: one target (`target`), or a household task (`targets`, a
/// `goal` and a `destination`).
#[derive(Clone, Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct StartTrial {
    /// Makes a retried request harmless.
    #[serde(default)]
    #[schema(min_length = 1, max_length = 200)]
    pub request_id: Option<String>,
    /// The scene's name.
    #[schema(min_length = 1)]
    pub scene: String,
    /// The object type to find, CamelCase (`CellPhone`); give this or `targets`.
    #[serde(default)]
    #[schema(pattern = r"^[A-Za-z0-9]{1,100}$")]
    pub target: Option<String>,
    /// The object types of a household task, 1 to 4 distinct, CamelCase; give this or
    /// `target`. A target seen while looking for another is found.
    #[serde(default)]
    #[schema(min_items = 1, max_items = 4)]
    pub targets: Option<Vec<String>>,
    /// `all` (default): every target; `any`: any one of them.
    #[serde(default)]
    pub goal: Option<GoalName>,
    /// Where the robot brings what it found; the trial's cost includes the way there.
    #[serde(default)]
    pub destination: Option<DestinationBody>,
    /// The robot's pose `[x, y, yaw°]` in the map frame; default: the scene's start.
    #[serde(default)]
    #[schema(value_type = Option<Vec<f64>>, min_items = 3, max_items = 3)]
    pub pose: Option<[f64; 3]>,
    /// A team of 1 to 4 robots that search together, each by its own id: each asks for its
    /// next container (`POST /trials/{id}/claims`) and reports what it saw with its id; no two
    /// robots are given the same container. Default: one robot, as the trial's own replies
    /// steer.
    #[serde(default)]
    #[schema(min_items = 1, max_items = 4)]
    pub robots: Option<Vec<TeamRobot>>,
    /// The id of the robot that searches alone (1 to 64 letters, digits, `_`, `-`, `.` or `/`;
    /// a team's robots are named in `robots` instead). The deployment's trial list then says
    /// whose each trial is, so that a robot that restarts finds its own open trial and leaves
    /// other robots' alone, and the live view shows the robot and how long since it was last
    /// heard from.
    #[serde(default)]
    #[schema(pattern = r"^[A-Za-z0-9_./-]{1,64}$")]
    pub robot: Option<String>,
}

/// The destination of a trial's task, where it is.
#[derive(Clone, Debug, Serialize, Deserialize, ToSchema)]
pub struct DestinationState {
    /// As the task named it.
    #[serde(flatten)]
    pub named: DestinationBody,
    /// Where the robot stands there, map frame, metres.
    pub at: [f64; 2],
    /// Once the trial has ended: the way from the last container searched to the destination
    /// (cell centres, map frame), which the robot drives with what it found.
    pub path: Option<Vec<[f64; 2]>>,
    /// The length of `path`, metres (part of `cost_m`).
    pub distance_m: Option<f64>,
}

/// `POST /trials/{id}/observations`.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Observe {
    /// Makes a retried request harmless.
    #[serde(default)]
    #[schema(min_length = 1, max_length = 200)]
    pub request_id: Option<String>,
    /// The id of the container searched.
    #[schema(min_length = 1)]
    pub container: String,
    /// Whether the target was in it. For a household task, whether one of its targets was,
    /// named in `found_targets` or `objects`.
    pub found: bool,
    /// The task's targets seen in it (CamelCase); a target listed in `objects` counts too.
    #[serde(default)]
    #[schema(max_items = 4)]
    pub found_targets: Vec<String>,
    /// Other object types seen in it (CamelCase).
    #[serde(default)]
    #[schema(max_items = 1000)]
    pub objects: Vec<String>,
    /// The robot's own odometry for this leg, metres.
    #[serde(default)]
    #[schema(minimum = 0.0, maximum = 100000.0)]
    pub travelled_m: Option<f64>,
    /// The robot that searched it: required in a team's trial (one of its `robots`).
    #[serde(default)]
    #[schema(pattern = r"^[A-Za-z0-9_./-]{1,64}$")]
    pub robot: Option<String>,
}

/// `POST /trials/{id}/claims`: a robot of a team asks for its next container.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ClaimNext {
    /// Makes a retried request harmless.
    #[serde(default)]
    #[schema(min_length = 1, max_length = 200)]
    pub request_id: Option<String>,
    /// The robot asking: one of the trial's `robots`.
    #[schema(pattern = r"^[A-Za-z0-9_./-]{1,64}$")]
    pub robot: String,
}

/// A robot of a team's trial as it stands.
#[derive(Clone, Debug, Serialize, Deserialize, ToSchema)]
pub struct RobotState {
    /// Its id.
    pub id: String,
    /// Where it is: where it started, or the access point of the last container it searched
    /// (map frame, metres).
    pub at: [f64; 2],
    /// The container it claimed, if any: it is the only robot sent there.
    pub claim: Option<String>,
    /// Seconds until the claim lapses unless the robot is heard from.
    pub claim_expires_in_s: Option<f64>,
    /// The containers it searched, in order.
    pub searched: Vec<String>,
    /// Map distance it drove so far, metres.
    pub cost_m: f64,
    /// Seconds since it last called; `None` before its first call.
    pub heard_s_ago: Option<f64>,
}

/// `POST /trials/{id}/abandon`: the robot gives the search up (it failed, or was called away).
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AbandonTrial {
    /// Makes a retried request harmless.
    #[serde(default)]
    #[schema(min_length = 1, max_length = 200)]
    pub request_id: Option<String>,
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

/// `GET /scenes/{name}/map`: the occupancy grid the planner measures the scene's distances on
/// (walls, doors left open, furniture, free floor), for drawing under the plan.
#[derive(Debug, Serialize, ToSchema)]
pub struct SceneMap {
    /// Cell size, metres.
    pub resolution_m: f64,
    /// The map-frame corner of cell (0, 0): its lowest x and y, metres.
    pub origin: [f64; 2],
    /// Columns, along x.
    pub width: u32,
    /// Rows, along y.
    pub height: u32,
    /// Every cell's kind as runs of `[kind, count]`, row by row from row 0 (lowest y) and in
    /// each row from column 0 (lowest x), the runs crossing from one row to the next. Kinds:
    /// 0 outside every room, 1 wall, 2 furniture, 3 floor closer to an obstacle than the robot's
    /// radius, 4 free floor. The counts add up to `width × height`.
    pub runs: Vec<[u32; 2]>,
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
    /// The target; for a household task, its targets joined by `+` (all) or `|` (any).
    pub target: String,
    /// The targets, in order (one for a single target).
    pub targets: Vec<String>,
    /// `all` or `any`.
    pub goal: GoalName,
    /// Where the robot brings what it found, if anywhere.
    pub destination: Option<DestinationState>,
    /// Each target found so far, with the container it was found in.
    pub found_in: BTreeMap<String, String>,
    /// The strategy selection chose for it.
    pub strategy: String,
    /// Where it stands.
    pub status: TrialStatus,
    /// Containers searched so far, in order.
    pub searched: Vec<String>,
    /// Map distance travelled so far, metres (the cost selection learns from); once a trial
    /// with a destination has ended, with the way there.
    pub cost_m: f64,
    /// Sum of the robot's reported odometry, when it reported any.
    pub travelled_m: Option<f64>,
    /// Where to search next (while searching). In a team's trial: the container claimed for
    /// the robot that asked (none when everything left is claimed by its teammates: ask again).
    pub next: Option<NextContainer>,
    /// A team's robots, in the order the trial named them; `cost_m` is then the makespan
    /// (the longest way any robot drove).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub robots: Option<Vec<RobotState>>,
    /// The robot that searches it alone, when it named itself at the start.
    pub robot: Option<String>,
    /// What the deployment's strategies said of the scene's names when they were checked:
    /// one line per word read otherwise than spelt (its base form, a WordNet hypernym, a word
    /// left out), so that a misspelt furniture or room name shows where the robot is watched.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub language: Vec<String>,
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
    /// The target; for a household task, its targets joined by `+` (all) or `|` (any).
    pub target: String,
    /// The strategy.
    pub strategy: String,
    /// Where it stands.
    pub status: TrialStatus,
    /// Its cost, once ended.
    pub cost_m: Option<f64>,
    /// Whose it is: the robot that started it alone and named itself, or a team's robots
    /// joined by `,`.
    pub robot: Option<String>,
    /// Seconds since a robot last reported on it (its start, an observation, its end); `None` for a trial stored by a server older than this field.
    pub heard_s_ago: Option<f64>,
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
    /// One trial at a time.
    pub sequential: bool,
    /// Candidates, in order.
    pub strategies: Vec<String>,
    /// Its trials.
    pub trials: Vec<TrialSummary>,
    /// Per-strategy statistics.
    pub per_strategy: Vec<StrategyRow>,
    /// The first trial in progress (see `open_trials`).
    pub open_trial: Option<i64>,
    /// Every trial in progress, in the order they started.
    pub open_trials: Vec<i64>,
    /// What the next trial will deploy.
    pub next: NextChoice,
}

/// A deployment in the list (`GET /deployments`).
#[derive(Debug, Serialize, ToSchema)]
pub struct DeploymentSummary {
    /// Its id.
    pub id: i64,
    /// `replay` or `ucb`.
    pub selector: String,
    /// One trial at a time.
    pub sequential: bool,
    /// Candidates, in order.
    pub strategies: Vec<String>,
    /// Trials started so far.
    pub trials: usize,
    /// Trials in progress, in the order they started.
    pub open_trials: Vec<i64>,
}

/// The newest deployments `GET /deployments` lists, at most.
pub const MAX_LISTED_DEPLOYMENTS: usize = 1000;

/// One container searched, as the robot reported it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, ToSchema)]
pub struct ObservationInfo {
    /// The container's id.
    pub container: String,
    /// Whether the target was in it.
    pub found: bool,
    /// Other object types seen in it.
    pub objects: Vec<String>,
}

/// `GET /trials/{id}/view`: a trial with what a picture of it needs.
#[derive(Debug, Serialize, ToSchema)]
pub struct TrialView {
    /// The trial, as `GET /trials/{id}` gives it.
    pub trial: TrialState,
    /// Where it started `[x, y, yaw°]`.
    pub start: [f64; 3],
    /// The way travelled so far: cell centres from the start through each searched container's
    /// access point, in order.
    pub route: Vec<[f64; 2]>,
    /// What each searched container held, in the order searched.
    pub observations: Vec<ObservationInfo>,
    /// The probability that the target is in each container now, by container id: the
    /// strategy's likelihood for containers not yet searched, 0 for searched ones without the
    /// target, 1 where it was found. For a household task, the chance that a container holds a
    /// target still wanted (0 once the goal holds). Null for a strategy that plans without a
    /// likelihood.
    pub likelihoods: Option<BTreeMap<String, f64>>,
    /// For a household task of several targets, each target's likelihoods as `likelihoods`
    /// has them for one; null otherwise.
    pub target_likelihoods: Option<BTreeMap<String, BTreeMap<String, f64>>>,
    /// A team's robots, in the trial's order, each with its own way (`route` is then empty);
    /// null for one robot.
    pub robot_routes: Option<Vec<RobotRoute>>,
}

/// One robot of a team's trial as its picture needs it.
#[derive(Debug, Serialize, ToSchema)]
pub struct RobotRoute {
    /// Its id.
    pub id: String,
    /// Its way so far: cell centres from its start through each container it searched.
    pub route: Vec<[f64; 2]>,
    /// The way from where it is to the container it claimed, while it holds one.
    pub claim_path: Option<Vec<[f64; 2]>>,
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

impl WithRequestId for UploadScene {
    fn request_id_mut(&mut self) -> &mut Option<String> {
        &mut self.request_id
    }
}

impl WithRequestId for CreateDeployment {
    fn request_id_mut(&mut self) -> &mut Option<String> {
        &mut self.request_id
    }
}

impl WithRequestId for StartTrial {
    fn request_id_mut(&mut self) -> &mut Option<String> {
        &mut self.request_id
    }
}

impl WithRequestId for AbandonTrial {
    fn request_id_mut(&mut self) -> &mut Option<String> {
        &mut self.request_id
    }
}

impl WithRequestId for Observe {
    fn request_id_mut(&mut self) -> &mut Option<String> {
        &mut self.request_id
    }
}

impl WithRequestId for ClaimNext {
    fn request_id_mut(&mut self) -> &mut Option<String> {
        &mut self.request_id
    }
}
