//! Household tasks from Python's arguments: a search's targets, goal and destination
//! (`ferret.Search`), and an evaluation's drawn or listed tasks (`ferret.evaluate`'s `task`,
//! `deliver` and `tasks`), checked with the rules of the command line and named, when refused,
//! by the keyword and the task's field.

use std::path::PathBuf;

use ferret_lab::{Deliver, TaskLine, TaskText, Tasks};
use ferret_plan::{Destination, Goal, Task, TaskError, TaskShape};
use ferret_world::ObjectType;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};

use crate::errors;
use crate::houses::{House, PyContainer};

/// A task's error as a `ConfigError` naming the keyword that set the field (`at`) and the
/// field itself, unless the keyword is the field.
pub fn task_error(at: &str, e: &TaskError) -> PyErr {
    if at == e.field {
        errors::config(format!("{at}: {}", e.message))
    } else {
        errors::config(format!("{at}: {e}"))
    }
}

/// The target names of a search: one object type (a `str`), or a list of 1 to 4 of them.
/// Returns the names and whether they came as a list. Names are trimmed; an empty one is
/// refused, naming its place (`target` or `target[i]`).
pub fn target_names(arg: &Bound<'_, PyAny>) -> PyResult<(Vec<String>, bool)> {
    if let Ok(s) = arg.downcast::<PyString>() {
        let name = s.extract::<String>()?.trim().to_string();
        if name.is_empty() {
            return Err(errors::config("target: an empty object type"));
        }
        return Ok((vec![name], false));
    }
    let Ok(names) = arg.extract::<Vec<String>>() else {
        return Err(errors::config(
            "target: expected an object type (str) or a list of 1 to 4 of them",
        ));
    };
    let names: Vec<String> = names.into_iter().map(|n| n.trim().to_string()).collect();
    if let Some(i) = names.iter().position(String::is_empty) {
        return Err(errors::config(format!("target[{i}]: an empty object type")));
    }
    Ok((names, true))
}

/// A goal by name, `"all"` or `"any"`, refused naming the keyword.
pub fn goal(name: &str) -> PyResult<Goal> {
    name.parse::<Goal>()
        .map_err(|e| errors::config(format!("goal={name:?}: {}", e.message)))
}

/// A search's destination in `house`: `None`, `"start"`, `"container:<id>"`, `"room:<id>"`,
/// a point `(x, y)` in metres (or written `"<x>,<y>"`), or one of the house's `Container`s.
pub fn destination(house: &House, arg: Option<&Bound<'_, PyAny>>) -> PyResult<Option<Destination>> {
    let Some(arg) = arg.filter(|a| !a.is_none()) else {
        return Ok(None);
    };
    let h = &house.scene.house;
    if let Ok(text) = arg.downcast::<PyString>() {
        return Destination::parse_in(&text.extract::<String>()?, h)
            .map(Some)
            .map_err(|e| task_error("destination", &e));
    }
    if arg.downcast::<PyContainer>().is_ok() {
        // The house's own container only (ids repeat across houses): its check says so.
        let index = house
            .container_index(arg)
            .map_err(|e| errors::config(format!("destination: {}", e.value(arg.py()))))?;
        return Ok(Some(Destination::Container { index }));
    }
    match arg.extract::<(f64, f64)>() {
        Ok((x, y)) if x.is_finite() && y.is_finite() => Ok(Some(Destination::Point { x, z: y })),
        Ok((x, y)) => Err(errors::config(format!(
            "destination: ({x}, {y}) is not a point: x and y must be finite numbers (metres)"
        ))),
        Err(_) => Err(errors::config(
            "destination: expected None, \"start\", \"container:<id>\", \"room:<id>\", an (x, y) point in metres or a Container",
        )),
    }
}

/// `ferret.evaluate`'s tasks: `task` (a shape, `"all:3"`) drawn per house and brought as
/// `deliver` says, or `tasks` listed (a tasks file's path, or a list of dicts); at most one of
/// `task` and `tasks`, and `deliver` only with `task`, as `ferret eval --task/--deliver/--tasks`.
pub fn eval_tasks(
    task: Option<&str>,
    deliver: Option<&str>,
    tasks: Option<&Bound<'_, PyAny>>,
) -> PyResult<Option<Tasks>> {
    let tasks = tasks.filter(|t| !t.is_none());
    if task.is_some() && tasks.is_some() {
        return Err(errors::config(
            "task, tasks: give one of them (task= draws tasks per house, tasks= lists them)",
        ));
    }
    if let (Some(d), None) = (deliver, task) {
        return Err(errors::config(format!(
            "deliver={d:?}: only with task= (listed tasks name their own destinations)"
        )));
    }
    if let Some(t) = task {
        let shape: TaskShape = t
            .parse()
            .map_err(|e: TaskError| task_error(&format!("task={t:?}"), &e))?;
        let deliver = deliver
            .map(|d| {
                d.parse::<Deliver>()
                    .map_err(|e| errors::config(format!("deliver={d:?}: {}", e.message)))
            })
            .transpose()?;
        return Ok(Some(Tasks::Drawn { shape, deliver }));
    }
    let Some(tasks) = tasks else {
        return Ok(None);
    };
    let lines = if let Ok(list) = tasks.downcast::<PyList>() {
        listed(list)?
    } else if let Ok(path) = tasks.extract::<PathBuf>() {
        // The file's own errors name the file, the line and the field.
        ferret_lab::read_task_file(&path)
            .map_err(|e| errors::config(format!("tasks: {}", ferret_world::error_chain(&e))))?
    } else {
        return Err(errors::config(
            "tasks: expected the path of a tasks file or a list of dicts with house, targets, goal and destination",
        ));
    };
    Ok(Some(Tasks::Listed { lines }))
}

/// The keys a listed task's dict may have.
const TASK_KEYS: [&str; 4] = ["house", "targets", "goal", "destination"];

/// Listed tasks, one dict per trial: `house` (index), `targets` (a list of types, or one string
/// of them separated by spaces or `+`, as a tasks file's column), `goal` (`all` when absent)
/// and `destination` (a string as a tasks file writes it, an `(x, y)` point, or absent). The
/// checks that need no house are made here; those that do, against the houses, later.
fn listed(list: &Bound<'_, PyList>) -> PyResult<Vec<TaskLine>> {
    if list.is_empty() {
        return Err(errors::config("tasks: no task in the list"));
    }
    list.iter()
        .enumerate()
        .map(|(i, item)| {
            let at = |field: &str| format!("tasks[{i}].{field}");
            let d = item.downcast::<PyDict>().map_err(|_| {
                errors::config(format!(
                    "tasks[{i}]: expected a dict with the keys house, targets, goal and destination"
                ))
            })?;
            for key in d.keys() {
                let key: String = key.extract().unwrap_or_else(|_| key.to_string());
                if !TASK_KEYS.contains(&key.as_str()) {
                    return Err(errors::config(format!(
                        "tasks[{i}]: unknown key {key:?} (expected {})",
                        TASK_KEYS.join(", ")
                    )));
                }
            }
            let house = d
                .get_item("house")?
                .ok_or_else(|| errors::config(format!("{}: missing", at("house"))))?
                .extract::<usize>()
                .map_err(|_| {
                    errors::config(format!(
                        "{}: expected the house's index in its file (an int ≥ 0)",
                        at("house")
                    ))
                })?;
            let targets = match d.get_item("targets")? {
                None => return Err(errors::config(format!("{}: missing", at("targets")))),
                Some(t) => {
                    if let Ok(s) = t.downcast::<PyString>() {
                        s.extract::<String>()?
                            .split(|c: char| c.is_whitespace() || c == '+')
                            .filter(|t| !t.is_empty())
                            .map(str::to_string)
                            .collect()
                    } else {
                        t.extract::<Vec<String>>()
                            .map_err(|_| {
                                errors::config(format!(
                                    "{}: expected a list of object types",
                                    at("targets")
                                ))
                            })?
                            .into_iter()
                            .map(|t| t.trim().to_string())
                            .collect::<Vec<_>>()
                    }
                }
            };
            let goal = match d.get_item("goal")?.filter(|g| !g.is_none()) {
                None => Goal::All,
                Some(g) => {
                    let g: String = g.extract().map_err(|_| {
                        errors::config(format!("{}: expected \"all\" or \"any\"", at("goal")))
                    })?;
                    g.parse::<Goal>()
                        .map_err(|e| errors::config(format!("{}: {}", at("goal"), e.message)))?
                }
            };
            let destination = match d.get_item("destination")?.filter(|x| !x.is_none()) {
                None => None,
                Some(x) => Some(
                    destination_text(&x)
                        .map_err(|why| errors::config(format!("{}: {why}", at("destination"))))?,
                ),
            };
            // The checks a task makes of itself (count, repeats, empty names), now rather than
            // at its house.
            Task::new(
                targets
                    .iter()
                    .map(|t| ObjectType::new(t.as_str()))
                    .collect(),
                goal,
                None,
            )
            .map_err(|e| errors::config(format!("{}: {}", at(e.field), e.message)))?;
            Ok(TaskLine {
                house,
                task: TaskText {
                    targets,
                    goal,
                    destination,
                },
            })
        })
        .collect()
}

/// A listed task's destination as a tasks file writes it: the text itself, or an `(x, y)` point
/// written `<x>,<y>` (Rust's shortest form of each number, which reads back to the same one).
fn destination_text(x: &Bound<'_, PyAny>) -> Result<String, String> {
    if let Ok(s) = x.downcast::<PyString>() {
        let s = s
            .extract::<String>()
            .map_err(|e| e.to_string())?
            .trim()
            .to_string();
        return if s.is_empty() {
            Err("an empty destination (leave it out for none)".into())
        } else {
            Ok(s)
        };
    }
    match x.extract::<(f64, f64)>() {
        Ok((a, b)) if a.is_finite() && b.is_finite() => Ok(format!("{a},{b}")),
        _ => Err(
            "expected \"start\", \"container:<id>\", \"room:<id>\" or an (x, y) point in metres"
                .into(),
        ),
    }
}
