//! Household tasks in the service: what a trial's start asks for (one target, or several with
//! a goal and a destination), checked against its scene and kept with the trial; the trial's
//! task again for planning; and where its destination is for the trial's state.

use std::collections::BTreeMap;

use ferret_plan::{Destination, DestinationLegs, Task, TrialSpec};
use ferret_world::ObjectType;
use ferret_world::distance::Place;

use crate::api::{DestinationBody, DestinationState, GoalName, StartTrial, TaskBody, is_type_name};
use crate::error::{ApiError, ErrorKind};
use crate::grids::Placed;
use crate::model::{StoredObservation, StoredTrial};

fn invalid(field: impl Into<String>, message: impl Into<String>) -> ApiError {
    ApiError::new(ErrorKind::Invalid, field, message)
}

/// What a start asks for, checked against `placed`: the name a trial's row keeps as its
/// target (the target, or a task's targets joined), and the task to keep with it (none for
/// one target with no goal or destination: the paper's trial, stored as before tasks).
///
/// # Errors
/// 400 for no target or both `target` and `targets`; 422 naming the field for a name that is
/// no object type or one the scene does not hold, too many or repeated targets, a destination
/// the scene does not have or the robot cannot reach.
pub(crate) fn requested_task(
    req: &StartTrial,
    placed: &Placed,
) -> Result<(String, Option<TaskBody>), ApiError> {
    let (names, field): (Vec<String>, &str) = match (&req.target, &req.targets) {
        (Some(_), Some(_)) => {
            return Err(ApiError::new(
                ErrorKind::Malformed,
                "targets",
                "give one object type as `target` or a task's `targets`, not both",
            ));
        }
        (None, None) => {
            return Err(ApiError::new(
                ErrorKind::Malformed,
                "target",
                "missing field `target`: give the object type to find, or a task's `targets`",
            ));
        }
        (Some(t), None) => (vec![t.clone()], "target"),
        (None, Some(ts)) => (ts.clone(), "targets"),
    };
    let mut targets = Vec::with_capacity(names.len());
    for (i, name) in names.iter().enumerate() {
        let at = if field == "target" {
            field.to_string()
        } else {
            format!("targets[{i}]")
        };
        if !is_type_name(name) {
            return Err(invalid(
                at,
                format!(
                    "{name:?} is not a CamelCase object type of ASCII letters and digits such as CellPhone"
                ),
            ));
        }
        // A target the scene does not list could only end "not found" after every container.
        let t = ferret_world::check_target(name, &placed.targets)
            .map_err(|e| invalid(at, e.to_string()))?;
        targets.push(t);
    }
    let goal = req.goal.unwrap_or_default();
    let destination = req
        .destination
        .as_ref()
        .map(|d| destination_of(d, placed))
        .transpose()?;
    let task = Task::new(targets, goal.into(), destination)
        .map_err(|e| invalid(field_of(field, e.field), e.message))?;
    if let Some(d) = task.destination() {
        d.legs(&placed.house, &placed.distances)
            .map_err(|e| invalid("destination", e.message))?;
    }
    let label = task.targets_label();
    if task.is_single() && req.goal.is_none() {
        return Ok((label, None));
    }
    let body = TaskBody {
        targets: task.targets().iter().map(ToString::to_string).collect(),
        goal,
        destination: req.destination.clone(),
    };
    Ok((label, Some(body)))
}

/// The request field a task's field is: `targets` is the request's target field.
fn field_of(target_field: &str, task_field: &str) -> String {
    if task_field == "targets" {
        target_field.to_string()
    } else {
        task_field.to_string()
    }
}

/// A destination named in the scene's terms, on its house.
fn destination_of(d: &DestinationBody, placed: &Placed) -> Result<Destination, ApiError> {
    let house = &placed.house;
    match d {
        DestinationBody::Start => Ok(Destination::Start),
        DestinationBody::Container { id } => house
            .container_index(id)
            .map(|index| Destination::Container { index })
            .ok_or_else(|| {
                invalid(
                    "destination.id",
                    format!("{id:?} is not a container of the scene"),
                )
            }),
        DestinationBody::Room { name } => house
            .rooms
            .iter()
            .position(|r| &r.id == name)
            .map(|index| Destination::Room { index })
            .ok_or_else(|| {
                invalid(
                    "destination.name",
                    format!("{name:?} is not a room of the scene"),
                )
            }),
        DestinationBody::Point { x, y } if x.is_finite() && y.is_finite() => {
            Ok(Destination::Point { x: *x, z: *y })
        }
        DestinationBody::Point { .. } => Err(invalid(
            "destination",
            "a point's x and y must be finite numbers",
        )),
    }
}

/// The trial a stored row asks for in `placed`: its task, or its one target.
pub(crate) fn trial_spec(row: &StoredTrial, placed: &Placed) -> Result<TrialSpec, ApiError> {
    let Some(task) = &row.task else {
        return Ok(TrialSpec::single(ObjectType::new(row.target.clone())));
    };
    let corrupt = |e: String| ApiError::internal(format!("trial {}: stored task: {e}", row.id));
    let destination = task
        .destination
        .as_ref()
        .map(|d| destination_of(d, placed))
        .transpose()
        .map_err(|e| corrupt(e.message))?;
    Task::new(
        task.targets.iter().map(ObjectType::new).collect(),
        task.goal.into(),
        destination,
    )
    .map(TrialSpec::of)
    .map_err(|e| corrupt(e.to_string()))
}

/// The object types an observation says were seen: what it lists, and the target of a
/// one-target trial when it was found.
pub(crate) fn seen(o: &StoredObservation, targets: &[String]) -> Vec<ObjectType> {
    let mut seen: Vec<ObjectType> = o.objects.iter().map(ObjectType::new).collect();
    if let [one] = targets
        && o.found
        && !o.objects.contains(one)
    {
        seen.push(ObjectType::new(one));
    }
    seen
}

/// Each target found, with the container it was first seen in.
pub(crate) fn found_in(
    observations: &[StoredObservation],
    targets: &[String],
) -> BTreeMap<String, String> {
    let mut found = BTreeMap::new();
    for o in observations {
        let seen = seen(o, targets);
        for t in targets {
            if seen.iter().any(|s| s.as_str() == t) {
                found
                    .entry(t.clone())
                    .or_insert_with(|| o.container.clone());
            }
        }
    }
    found
}

/// Where a trial's destination is (`legs`, its travel on the trial's map) and, once the search
/// ended at `ended_at`, the way there from that place.
pub(crate) fn destination_state(
    task: Option<&TaskBody>,
    placed: &Placed,
    legs: Option<&DestinationLegs>,
    ended_at: Option<Place>,
) -> Option<DestinationState> {
    let named = task?.destination.clone()?;
    let legs = legs?;
    let at = legs.point(&placed.distances)?;
    let (path, distance_m) = match ended_at {
        Some(from) => {
            let path = legs
                .path(&placed.distances, from)
                .unwrap_or_default()
                .into_iter()
                .map(|p| [p.x, p.z])
                .collect();
            (Some(path), Some(legs.from(from)))
        }
        None => (None, None),
    };
    Some(DestinationState {
        named,
        at: [at.x, at.z],
        path,
        distance_m,
    })
}

/// The goal a stored row asks for.
pub(crate) fn goal_of(row: &StoredTrial) -> GoalName {
    row.task.as_ref().map_or(GoalName::All, |t| t.goal)
}

/// The targets a stored row asks for, in order.
pub(crate) fn targets_of(row: &StoredTrial) -> Vec<String> {
    match &row.task {
        Some(t) => t.targets.clone(),
        None => vec![row.target.clone()],
    }
}
