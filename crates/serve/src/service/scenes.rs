//! Scenes: the ones given on the command line and the ones robots upload (checked against the
//! server's limits before any grid is built), listed, described and placed at a robot's pose.

use std::sync::{Arc, PoisonError};

use ferret_world::distance::Place;
use ferret_world::{House, OccupancyGrid, Scene, SceneFile};

use super::replies::Begun;
use super::{Scenes, Service, json};
use crate::api::{
    ContainerInfo, MAX_TYPE_NAME, RoomInfo, SceneDetail, SceneMap, SceneSummary, UploadScene,
    is_type_name,
};
use crate::error::{ApiError, ErrorKind};
use crate::grids::Placed;
use crate::model::{ApiReply, DeploymentSpec, Outcome};

/// A name or id in an uploaded scene: printable ASCII, not only spaces, at most 100 characters
/// (they appear in URLs and replies; the scene file format itself is more lenient).
fn is_upload_name(s: &str) -> bool {
    s.len() <= MAX_TYPE_NAME
        && s.chars().all(|c| matches!(c, ' '..='~'))
        && s.chars().any(|c| matches!(c, '!'..='~'))
}

fn summary(name: &str, scene: &Scene) -> SceneSummary {
    SceneSummary {
        name: name.to_string(),
        rooms: scene.house.rooms.len(),
        containers: scene.house.containers.len(),
        has_map: scene.house.map.is_some(),
    }
}

pub(super) fn start_pose(house: &House) -> [f64; 3] {
    let start = &house.start;
    [
        start.position.x,
        start.position.z,
        ferret_world::scene::heading_to_ros(start.yaw_deg),
    ]
}

/// What the candidates said of a scene's names: (strategy, line) pairs.
pub(crate) type SceneLanguage = Vec<(String, String)>;

impl Service {
    /// Asks every candidate's likelihood source whether it can answer the names of `scene`
    /// (its furniture, rooms and targets): a learned prior needs a vector for each, from its
    /// file or its embeddings. The notes (words read otherwise than spelt) are logged as
    /// warnings and kept for the scene's trial states.
    ///
    /// # Errors
    /// 422 on `field` naming the first name a candidate cannot answer and what to give.
    pub(crate) fn check_language(
        &self,
        name: &str,
        scene: &Scene,
        field: &str,
    ) -> Result<Arc<SceneLanguage>, ApiError> {
        let targets: Vec<_> = scene.truth.target_types().into_iter().collect();
        let mut said = Vec::new();
        for s in &self.candidates {
            let Some(source) = s.likelihood_source() else {
                continue;
            };
            let notes = source.check_names(&scene.house, &targets).map_err(|m| {
                ApiError::new(
                    ErrorKind::Invalid,
                    field,
                    format!("{} cannot plan here: {m}", s.name()),
                )
            })?;
            for n in notes {
                tracing::info!(scene = name, strategy = s.name(), "{n}");
                said.push((s.name().to_string(), n));
            }
        }
        let said = Arc::new(said);
        self.language
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .insert(name.to_string(), said.clone());
        Ok(said)
    }

    /// What the strategies of a deployment said of scene `name`'s names (checked when the
    /// scene was added; a scene another replica uploaded is checked at its first trial here).
    pub(crate) fn language(&self, name: &str, spec: &DeploymentSpec) -> Vec<String> {
        let known = self
            .language
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .get(name)
            .cloned();
        let said = match known {
            Some(said) => said,
            None => match self
                .scene(name)
                .and_then(|scene| self.check_language(name, &scene, "scene"))
            {
                Ok(said) => said,
                // A trial's start answers that error itself; a state only lacks the notes.
                Err(_) => return Vec::new(),
            },
        };
        said.iter()
            .filter(|(strategy, _)| spec.strategies.contains(strategy))
            .map(|(_, line)| line.clone())
            .collect()
    }

    /// Offers `scene` under `name` (scene files and houses named on the command line; no limits
    /// apply, the operator chose them). Its grid is built now, to check it.
    ///
    /// # Errors
    /// 422 when a container cannot be reached from the scene's start; 409 when the name is
    /// taken.
    pub fn add_scene(&self, name: &str, scene: Scene) -> Result<(), ApiError> {
        if self.knows(name)? {
            return Err(ApiError::new(
                ErrorKind::Conflict,
                "scene",
                format!("a scene named {name:?} exists already"),
            ));
        }
        self.check_language(name, &scene, "scene")?;
        let targets = Arc::new(scene.truth.target_types());
        let placed = self.grids.build(&scene.house, targets, None, "scene")?;
        let s = summary(name, &scene);
        self.write_scenes()
            .fixed
            .insert(name.to_string(), (Arc::new(scene), s));
        self.grids.keep(name, placed);
        Ok(())
    }

    /// The scene `name` with the robot at `pose` (its own start when `None`), from the grid
    /// cache or built.
    pub(crate) fn placed(
        &self,
        name: &str,
        pose: Option<[f64; 3]>,
    ) -> Result<Arc<Placed>, ApiError> {
        self.grids.placed(name, pose, || self.scene(name))
    }

    fn read_scenes(&self) -> std::sync::RwLockReadGuard<'_, Scenes> {
        self.scenes.read().unwrap_or_else(PoisonError::into_inner)
    }

    fn write_scenes(&self) -> std::sync::RwLockWriteGuard<'_, Scenes> {
        self.scenes.write().unwrap_or_else(PoisonError::into_inner)
    }

    /// True when a scene is offered under `name` (also one another process uploaded to the
    /// same store).
    fn knows(&self, name: &str) -> Result<bool, ApiError> {
        {
            let scenes = self.read_scenes();
            if scenes.fixed.contains_key(name) || scenes.uploaded.contains_key(name) {
                return Ok(true);
            }
        }
        Ok(self.store.read(|r| r.scene(name))?.is_some())
    }

    /// The scene called `name`: a fixed one, or an uploaded one read from the store.
    pub(crate) fn scene(&self, name: &str) -> Result<Arc<Scene>, ApiError> {
        if let Some((scene, _)) = self.read_scenes().fixed.get(name) {
            return Ok(scene.clone());
        }
        let Some(text) = self.store.read(|r| r.scene(name))? else {
            return Err(ApiError::new(
                ErrorKind::NotFound,
                "scene",
                format!("no scene named {name:?}"),
            ));
        };
        let (_, scene) = parse_uploaded(&text).map_err(|e| {
            ApiError::internal(format!(
                "stored scene {name:?} no longer loads: {}",
                e.message
            ))
        })?;
        self.write_scenes()
            .uploaded
            .entry(name.to_string())
            .or_insert_with(|| summary(name, &scene));
        Ok(Arc::new(scene))
    }

    /// `GET /scenes`.
    pub fn list_scenes(&self) -> Result<ApiReply, ApiError> {
        let scenes = self.read_scenes();
        let mut list: Vec<&SceneSummary> = scenes
            .fixed
            .values()
            .map(|(_, s)| s)
            .chain(scenes.uploaded.values())
            .collect();
        list.sort_by(|a, b| a.name.cmp(&b.name));
        json(Outcome::Done, &list)
    }

    /// `GET /scenes/{name}`.
    pub fn get_scene(&self, name: &str) -> Result<ApiReply, ApiError> {
        let scene = self.scene(name)?;
        let placed = self.placed(name, None)?;
        scene_detail(name, &scene, &placed).and_then(|d| json(Outcome::Done, &d))
    }

    /// `GET /scenes/{name}/map`: the grid of the scene placed at its start, run-length coded.
    pub fn scene_map(&self, name: &str) -> Result<ApiReply, ApiError> {
        self.scene(name)?;
        let placed = self.placed(name, None)?;
        let grid = placed.distances.grid().ok_or_else(|| {
            ApiError::new(
                ErrorKind::NotFound,
                "name",
                format!("scene {name:?} has no occupancy grid"),
            )
        })?;
        json(Outcome::Done, &scene_map(grid))
    }

    /// `POST /scenes`.
    pub fn upload_scene(&self, req: UploadScene, body: &[u8]) -> Result<ApiReply, ApiError> {
        const ROUTE: &str = "POST /scenes";
        let request_id = req.request_id.as_deref();
        let claim = match self.begin(request_id, ROUTE, body)? {
            Begun::Replied(reply) => return Ok(reply),
            Begun::Fresh(claim) => claim,
        };
        let text = req.scene.to_string();
        let file = parse_file(&text)?;
        // Counts first: checking the rooms for overlaps takes time in their vertices squared.
        self.check_upload(&file)?;
        let scene = to_scene(&file)?;
        self.check_cells(&scene)?;
        let name = file.name;
        if self.read_scenes().fixed.contains_key(&name) {
            return Err(taken(&name));
        }
        // The same scene again: nothing to build.
        match self.store.read(|r| r.scene(&name))? {
            Some(stored) if stored == text => {
                let reply = self.get_scene(&name)?;
                return claim.complete(ROUTE, body, |_| Ok(reply));
            }
            Some(_) => return Err(taken(&name)),
            None => {}
        }
        self.check_language(&name, &scene, "scene.containers")?;
        let targets = Arc::new(scene.truth.target_types());
        let placed = self
            .grids
            .build(&scene.house, targets, None, "scene.containers")?;
        let detail = json(Outcome::Created, &scene_detail(&name, &scene, &placed)?)?;
        let max = self.options.limits.max_scenes;
        let reply = claim.complete(ROUTE, body, |w| {
            match w.reader().scene(&name)? {
                Some(stored) if stored == text => {
                    return Ok(ApiReply {
                        outcome: Outcome::Done,
                        body: detail.body.clone(),
                    });
                }
                Some(_) => return Err(taken(&name)),
                None => {}
            }
            if w.reader().scene_count()? >= max {
                return Err(ApiError::new(
                    ErrorKind::TooLarge,
                    "scene",
                    format!("the server holds {max} uploaded scenes, its limit (--max-scenes)"),
                ));
            }
            w.insert_scene(&name, &text)?;
            Ok(detail.clone())
        })?;
        self.grids.keep(&name, placed);
        self.write_scenes()
            .uploaded
            .insert(name.clone(), summary(&name, &scene));
        Ok(reply)
    }

    /// The limits of uploaded scenes, and names the API can carry; checked before any grid is
    /// built.
    fn check_upload(&self, file: &SceneFile) -> Result<(), ApiError> {
        let limits = &self.options.limits;
        let bad =
            |field: String, message: String| Err(ApiError::new(ErrorKind::Invalid, field, message));
        let names = std::iter::once(("scene.name".to_string(), file.name.as_str()))
            .chain(
                file.rooms
                    .iter()
                    .enumerate()
                    .map(|(i, r)| (format!("scene.rooms[{i}].name"), r.name.as_str())),
            )
            .chain(file.containers.iter().enumerate().flat_map(|(i, c)| {
                std::iter::once((format!("scene.containers[{i}].id"), c.id.as_str())).chain(
                    c.room
                        .as_deref()
                        .map(|r| (format!("scene.containers[{i}].room"), r)),
                )
            }))
            .chain(
                file.obstacles
                    .iter()
                    .enumerate()
                    .map(|(i, o)| (format!("scene.obstacles[{i}].id"), o.id.as_str())),
            );
        for (field, name) in names {
            if !is_upload_name(name) {
                return bad(
                    field,
                    format!(
                        "{name:?}: names and ids of uploaded scenes are printable ASCII, 1 to {MAX_TYPE_NAME} characters, not only spaces"
                    ),
                );
            }
        }
        let types =
            file.rooms
                .iter()
                .enumerate()
                .map(|(i, r)| (format!("scene.rooms[{i}].type"), r.room_type.as_str()))
                .chain(file.containers.iter().enumerate().flat_map(|(i, c)| {
                    std::iter::once((
                        format!("scene.containers[{i}].type"),
                        c.object_type.as_str(),
                    ))
                    .chain(c.contents.iter().enumerate().map(
                        move |(k, t)| (format!("scene.containers[{i}].contents[{k}]"), t.as_str()),
                    ))
                }))
                .chain(
                    file.obstacles.iter().enumerate().map(|(i, o)| {
                        (format!("scene.obstacles[{i}].type"), o.object_type.as_str())
                    }),
                );
        for (field, t) in types {
            if !is_type_name(t) {
                return bad(
                    field,
                    format!("{t:?} is not a CamelCase type of ASCII letters and digits"),
                );
            }
        }
        if file.containers.len() > limits.max_containers {
            return bad(
                "scene.containers".into(),
                format!(
                    "{} containers; this server takes at most {} per uploaded scene (--max-scene-containers)",
                    file.containers.len(),
                    limits.max_containers
                ),
            );
        }
        if file.obstacles.len() > limits.max_containers {
            return bad(
                "scene.obstacles".into(),
                format!(
                    "{} obstacles; this server takes at most {} per uploaded scene (--max-scene-containers)",
                    file.obstacles.len(),
                    limits.max_containers
                ),
            );
        }
        let vertices: usize = file.rooms.iter().map(|r| r.polygon.len()).sum();
        if vertices > limits.max_vertices {
            return bad(
                "scene.rooms".into(),
                format!(
                    "{vertices} polygon vertices in all; this server takes at most {} per uploaded scene (--max-scene-vertices)",
                    limits.max_vertices
                ),
            );
        }
        Ok(())
    }

    /// The grid cells limit of uploaded scenes.
    fn check_cells(&self, scene: &Scene) -> Result<(), ApiError> {
        let limits = &self.options.limits;
        let cells = OccupancyGrid::planned_cells(&scene.house, self.grids.params()).unwrap_or(0.0);
        if cells > limits.max_cells as f64 {
            return Err(ApiError::new(
                ErrorKind::Invalid,
                "scene.rooms",
                format!(
                    "the rooms span {cells:.0} grid cells at {} m; this server takes at most {} per uploaded scene (--max-scene-cells)",
                    self.grids.params().resolution,
                    limits.max_cells
                ),
            ));
        }
        Ok(())
    }
}
/// Parses an uploaded scene's text (a scene file without a map).
fn parse_file(text: &str) -> Result<SceneFile, ApiError> {
    let parsed =
        SceneFile::parse(text, std::path::Path::new("<uploaded>")).map_err(|e| scene_error(&e))?;
    if parsed.map.is_some() {
        return Err(ApiError::new(
            ErrorKind::Invalid,
            "scene.map",
            "a scene with a map is loaded by the server (--scene), not uploaded",
        ));
    }
    Ok(parsed)
}

fn to_scene(file: &SceneFile) -> Result<Scene, ApiError> {
    file.to_scene(std::path::Path::new("<uploaded>"), None)
        .map_err(|e| scene_error(&e))
}

/// Parses a stored uploaded scene.
fn parse_uploaded(text: &str) -> Result<(SceneFile, Scene), ApiError> {
    let file = parse_file(text)?;
    let scene = to_scene(&file)?;
    Ok((file, scene))
}

fn taken(name: &str) -> ApiError {
    ApiError::new(
        ErrorKind::Conflict,
        "scene.name",
        format!("a different scene named {name:?} exists already"),
    )
}

/// What `GET /scenes/{name}` says about a scene placed at its start.
fn scene_detail(name: &str, scene: &Scene, placed: &Placed) -> Result<SceneDetail, ApiError> {
    let (house, truth) = (&scene.house, &scene.truth);
    let grid = placed.distances.grid();
    let containers = house
        .containers
        .iter()
        .enumerate()
        .map(|(i, c)| ContainerInfo {
            id: c.id.clone(),
            object_type: c.object_type.to_string(),
            room: house.container_room(i).map(|r| r.id.clone()),
            x: c.position.x,
            y: c.position.z,
            access: grid
                .and_then(|g| g.access_cell(i).map(|cell| g.center(cell)))
                .map(|p| [p.x, p.z]),
            contents: truth
                .contents(i)
                .iter()
                .map(|o| o.object_type.to_string())
                .collect(),
        })
        .collect();
    let places: Vec<(String, Place)> = std::iter::once(("start".to_string(), Place::Start))
        .chain(
            house
                .containers
                .iter()
                .enumerate()
                .map(|(i, c)| (c.id.clone(), Place::Container(i))),
        )
        .collect();
    let distances_m = places
        .iter()
        .map(|(a, pa)| {
            let row = places[1..]
                .iter()
                .map(|(b, pb)| (b.clone(), placed.distances.between(*pa, *pb)))
                .collect();
            (a.clone(), row)
        })
        .collect();
    Ok(SceneDetail {
        name: name.to_string(),
        rooms: house
            .rooms
            .iter()
            .map(|r| RoomInfo {
                name: r.id.clone(),
                room_type: r.room_type.to_string(),
                polygon: r.floor.vertices.iter().map(|p| [p.x, p.z]).collect(),
            })
            .collect(),
        containers,
        start: start_pose(house),
        distances_m,
    })
}

fn scene_error(e: &ferret_world::WorldError) -> ApiError {
    match e {
        ferret_world::WorldError::Scene { field, message, .. } => ApiError::new(
            ErrorKind::Invalid,
            if field.is_empty() {
                "scene".to_string()
            } else {
                format!("scene.{field}")
            },
            message.clone(),
        ),
        other => ApiError::new(ErrorKind::Invalid, "scene", other.to_string()),
    }
}

/// A grid as runs of equal cells in the order [`OccupancyGrid::cells`] gives them (row by row):
/// a house of 400 × 300 cells is a few thousand runs, where one value per cell would be 120 000.
fn scene_map(grid: &OccupancyGrid) -> SceneMap {
    let mut runs: Vec<[u32; 2]> = Vec::new();
    for (_, kind) in grid.cells() {
        let k = kind as u32;
        match runs.last_mut() {
            Some(run) if run[0] == k => run[1] += 1,
            _ => runs.push([k, 1]),
        }
    }
    let origin = grid.origin();
    SceneMap {
        resolution_m: grid.resolution(),
        origin: [origin.x, origin.z],
        width: grid.width(),
        height: grid.height(),
        runs,
    }
}
