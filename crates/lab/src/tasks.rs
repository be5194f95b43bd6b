//! Household tasks in an experiment: how a run's tasks are given — drawn per house in a shape
//! (`all:3`) and brought to a place named the same way in every house ([`Deliver`]), or listed
//! one per trial in a tasks file ([`TaskLine`]) — and the trials they make on each house.
//!
//! A tasks file is CSV with a header: `house` (the house's index in its file), `targets` (1 to
//! 4 object types, separated by spaces or `+`), `goal` (`all` or `any`, `all` when empty) and
//! `destination` (`start`, `container:<id>`, `room:<id>`, a point `<x>,<z>` in metres, or
//! empty for none):
//!
//! ```text
//! house,targets,goal,destination
//! 0,Mug Apple,all,start
//! 3,Mug Cup,any,room:room|4
//! ```

use std::path::Path;

use ferret_plan::{
    Destination, Goal, PlanError, Protocol, Task, TaskError, TaskShape, TrialSpec, TrialsPerHouse,
    draw_tasks,
};
use ferret_world::{ObjectType, Scene};
use serde::{Deserialize, Serialize};

use crate::error::{LabError, Result};

/// Where drawn tasks bring what was found, named the same way for every house.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Deliver {
    /// Back to the robot's start: "bring it to me".
    Start,
    /// To the centre of the house's first room of this type (`room:Kitchen`).
    RoomType(String),
    /// To the house's first container of this type (`container:Sofa`).
    ContainerType(String),
}

impl std::str::FromStr for Deliver {
    type Err = TaskError;

    fn from_str(s: &str) -> std::result::Result<Self, TaskError> {
        let s = s.trim();
        let err = || {
            TaskError::new(
                "destination",
                format!(
                    "`{s}`: expected `start`, `room:<RoomType>` (e.g. room:Kitchen) or `container:<ObjectType>` (e.g. container:Sofa)"
                ),
            )
        };
        if s == "start" {
            return Ok(Deliver::Start);
        }
        match s.split_once(':') {
            Some(("room", t)) if !t.trim().is_empty() => Ok(Deliver::RoomType(t.trim().into())),
            Some(("container", t)) if !t.trim().is_empty() => {
                Ok(Deliver::ContainerType(t.trim().into()))
            }
            _ => Err(err()),
        }
    }
}

impl std::fmt::Display for Deliver {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Deliver::Start => f.write_str("start"),
            Deliver::RoomType(t) => write!(f, "room:{t}"),
            Deliver::ContainerType(t) => write!(f, "container:{t}"),
        }
    }
}

impl Serialize for Deliver {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for Deliver {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        String::deserialize(d)?
            .parse()
            .map_err(serde::de::Error::custom)
    }
}

impl Deliver {
    /// The destination this names in `house`.
    ///
    /// # Errors
    /// [`TaskError`] on field `destination` when the house has no room or container of the
    /// type.
    pub fn destination(&self, scene: &Scene) -> std::result::Result<Destination, TaskError> {
        let house = &scene.house;
        match self {
            Deliver::Start => Ok(Destination::Start),
            Deliver::RoomType(t) => house
                .rooms
                .iter()
                .position(|r| r.room_type.as_str() == t)
                .map(|index| Destination::Room { index })
                .ok_or_else(|| {
                    TaskError::new(
                        "destination",
                        format!("{}: no room of type {t}", house.name),
                    )
                }),
            Deliver::ContainerType(t) => house
                .containers
                .iter()
                .position(|c| c.object_type.as_str() == t)
                .map(|index| Destination::Container { index })
                .ok_or_else(|| {
                    TaskError::new(
                        "destination",
                        format!("{}: no container of type {t}", house.name),
                    )
                }),
        }
    }
}

/// A task named without a house: its targets, goal and destination as the house will name it.
/// Written `Mug` (one target), `Mug+Apple` (all of them), `Mug|Cup` (any one), followed by
/// `@<destination>` as a tasks file names it (`Mug+Apple@start`, `Mug@room:room|4`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskText {
    /// The target types, in order.
    pub targets: Vec<String>,
    /// All of them or any one.
    pub goal: Goal,
    /// Where to bring them, as the house names it; none when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub destination: Option<String>,
}

impl std::str::FromStr for TaskText {
    type Err = TaskError;

    fn from_str(s: &str) -> std::result::Result<Self, TaskError> {
        let (body, destination) = match s.trim().split_once('@') {
            Some((b, d)) => (b, Some(d.trim().to_string())),
            None => (s.trim(), None),
        };
        let (goal, sep) = if body.contains('|') {
            (Goal::Any, '|')
        } else {
            (Goal::All, '+')
        };
        let targets: Vec<String> = body.split(sep).map(|t| t.trim().to_string()).collect();
        let text = TaskText {
            targets,
            goal,
            destination,
        };
        text.check()?;
        Ok(text)
    }
}

impl std::fmt::Display for TaskText {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let sep = match self.goal {
            Goal::All => "+",
            Goal::Any => "|",
        };
        f.write_str(&self.targets.join(sep))?;
        match &self.destination {
            Some(d) => write!(f, "@{d}"),
            None => Ok(()),
        }
    }
}

impl TaskText {
    fn types(&self) -> Vec<ObjectType> {
        self.targets
            .iter()
            .map(|t| ObjectType::new(t.as_str()))
            .collect()
    }

    /// The checks a task makes of itself, which need no house.
    fn check(&self) -> std::result::Result<(), TaskError> {
        Task::new(self.types(), self.goal, None).map(|_| ())
    }

    /// The task in `scene`: its destination looked up in the house.
    ///
    /// # Errors
    /// [`TaskError`] for a target of `all` no container of the house holds, a task of `any`
    /// none of whose targets is there, or a destination the house does not have.
    pub fn task(&self, scene: &Scene) -> std::result::Result<Task, TaskError> {
        let targets = self.types();
        let present: Vec<bool> = targets
            .iter()
            .map(|t| !scene.truth.goal_containers(t).is_empty())
            .collect();
        let name = &scene.house.name;
        match self.goal {
            Goal::All => {
                if let Some(i) = present.iter().position(|p| !p) {
                    return Err(TaskError::new(
                        "targets",
                        format!(
                            "{name}: no container holds {}, so the task cannot be done",
                            targets[i]
                        ),
                    ));
                }
            }
            Goal::Any => {
                if !present.iter().any(|p| *p) {
                    return Err(TaskError::new(
                        "targets",
                        format!("{name}: no container holds any of the targets"),
                    ));
                }
            }
        }
        let destination = self
            .destination
            .as_deref()
            .map(|d| Destination::parse_in(d, &scene.house))
            .transpose()?;
        Task::new(targets, self.goal, destination)
    }
}

/// One line of a tasks file: one trial.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskLine {
    /// The house's index in its file.
    pub house: usize,
    /// The task.
    #[serde(flatten)]
    pub task: TaskText,
}

/// A line as the CSV has it.
#[derive(Deserialize)]
struct RawLine {
    house: String,
    targets: String,
    #[serde(default)]
    goal: String,
    #[serde(default)]
    destination: String,
}

/// Most lines a tasks file may hold.
pub const MAX_TASK_LINES: usize = 1_000_000;

/// Reads a tasks file (see the [module documentation](self)), checking every line's fields
/// that need no house: each error names the file, the line and the field.
///
/// # Errors
/// [`LabError::Task`] for an unreadable file, a missing column or a bad line.
pub fn read_task_file(path: &Path) -> Result<Vec<TaskLine>> {
    let at = |line: u64, e: TaskError| LabError::Task {
        place: format!("{}: line {line}", path.display()),
        error: e,
    };
    let mut reader = csv::ReaderBuilder::new()
        .trim(csv::Trim::All)
        .from_path(path)
        .map_err(|e| LabError::Task {
            place: path.display().to_string(),
            error: TaskError::new("file", e.to_string()),
        })?;
    let mut lines = Vec::new();
    for record in reader.deserialize::<RawLine>() {
        let record = record.map_err(|e| {
            let line = e.position().map_or(0, |p| p.line());
            at(
                line,
                TaskError::new(
                    "columns",
                    format!("{e} (expected the columns house,targets,goal,destination)"),
                ),
            )
        })?;
        let line = lines.len() as u64 + 2;
        if lines.len() >= MAX_TASK_LINES {
            return Err(at(
                line,
                TaskError::new("file", format!("more than {MAX_TASK_LINES} tasks")),
            ));
        }
        let house = record.house.parse::<usize>().map_err(|_| {
            at(
                line,
                TaskError::new("house", format!("`{}` is not a house index", record.house)),
            )
        })?;
        let targets: Vec<String> = record
            .targets
            .split(|c: char| c.is_whitespace() || c == '+')
            .filter(|t| !t.is_empty())
            .map(str::to_string)
            .collect();
        let goal = if record.goal.is_empty() {
            Goal::All
        } else {
            record.goal.parse().map_err(|e| at(line, e))?
        };
        let task = TaskText {
            targets,
            goal,
            destination: (!record.destination.is_empty()).then_some(record.destination),
        };
        // The checks a task makes of itself, now rather than at the line's house.
        task.check().map_err(|e| at(line, e))?;
        lines.push(TaskLine { house, task });
    }
    if lines.is_empty() {
        return Err(LabError::Task {
            place: path.display().to_string(),
            error: TaskError::new("file", "no task in it"),
        });
    }
    Ok(lines)
}

/// How an experiment's trials are household tasks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Tasks {
    /// Drawn per house: `shape`'s number of distinct types present, brought by `deliver`.
    Drawn {
        /// Goal and number of targets.
        shape: TaskShape,
        /// Where every task brings what it found.
        #[serde(default, skip_serializing_if = "Option::is_none")]
        deliver: Option<Deliver>,
    },
    /// Listed one per trial.
    Listed {
        /// The tasks, in the file's order.
        lines: Vec<TaskLine>,
    },
}

impl Tasks {
    /// The trials of `scene`: its drawn tasks (`per_house` of them, targets from the house under
    /// `protocol`), or its lines in the list in their order (none when it has none).
    ///
    /// # Errors
    /// What [`draw_tasks`] refuses; a destination the house does not have; for listed tasks
    /// ([`LabError::Task`], naming the line and field): a target of `all` no container holds,
    /// a task of `any` none of whose targets is there, an unknown destination, the same task
    /// twice.
    pub fn trials(
        &self,
        scene: &Scene,
        (seed, reveal_fraction): (u64, f64),
        per_house: TrialsPerHouse,
        protocol: &Protocol,
    ) -> Result<Vec<TrialSpec>> {
        match self {
            Tasks::Drawn { shape, deliver } => {
                let mut trials = draw_tasks(
                    (&scene.house, &scene.truth),
                    seed,
                    reveal_fraction,
                    per_house,
                    protocol,
                    *shape,
                )?;
                if let Some(d) = deliver {
                    let dest = d.destination(scene).map_err(PlanError::Task)?;
                    for t in &mut trials {
                        t.task = t.task.clone().with_destination(Some(dest.clone()));
                    }
                }
                Ok(trials)
            }
            Tasks::Listed { lines } => {
                let mut trials: Vec<TrialSpec> = Vec::new();
                for (k, line) in lines.iter().enumerate() {
                    if line.house != scene.house.index {
                        continue;
                    }
                    let at = |e: TaskError| LabError::Task {
                        place: format!("task {} (house {})", k + 1, line.house),
                        error: e,
                    };
                    let task = line.task.task(scene).map_err(at)?;
                    if let Some(same) = trials.iter().position(|t| t.task == task) {
                        return Err(at(TaskError::new(
                            "targets",
                            format!("the same task as task {} of this house", same + 1),
                        )));
                    }
                    trials.push(TrialSpec::of(task));
                }
                Ok(trials)
            }
        }
    }

    /// The house indices a list names, in order of first mention; none for drawn tasks.
    pub fn listed_houses(&self) -> Vec<usize> {
        match self {
            Tasks::Drawn { .. } => Vec::new(),
            Tasks::Listed { lines } => {
                let mut houses = Vec::new();
                for l in lines {
                    if !houses.contains(&l.house) {
                        houses.push(l.house);
                    }
                }
                houses
            }
        }
    }

    /// How the run's tasks read in a report: `all:3, delivered to start`, `12 listed tasks`.
    pub fn describe(&self) -> String {
        match self {
            Tasks::Drawn { shape, deliver } => match deliver {
                Some(d) => format!("tasks {shape}, brought to {d}"),
                None => format!("tasks {shape}"),
            },
            Tasks::Listed { lines } => format!("{} listed tasks", lines.len()),
        }
    }
}

/// The task a row of `trials.csv` ran in `house`: its target for a run of single targets, else
/// the targets, goal and destination of its task's columns.
///
/// # Errors
/// [`TaskError`] for columns no task has (a goal other than `all`/`any`, a destination the
/// house does not have).
pub fn task_of_row(
    row: &crate::rows::TrialRow,
    house: &ferret_world::House,
) -> std::result::Result<Task, TaskError> {
    let Some(goal) = &row.goal else {
        return Ok(Task::single(ObjectType::new(row.target.as_str())));
    };
    let goal: Goal = goal.parse()?;
    let sep = match goal {
        Goal::All => '+',
        Goal::Any => '|',
    };
    let destination = match row.destination.as_deref() {
        None | Some("") => None,
        Some(d) => Some(Destination::parse_in(d, house)?),
    };
    Task::new(
        row.target.split(sep).map(ObjectType::new).collect(),
        goal,
        destination,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_bad_line_names_its_line_and_field() {
        let dir = tempfile::tempdir().unwrap();
        let write = |text: &str| {
            let p = dir.path().join("t.csv");
            std::fs::write(&p, text).unwrap();
            p
        };
        let err = |text: &str| read_task_file(&write(text)).unwrap_err().to_string();
        let e = err("house,targets,goal,destination\n0,Mug Apple,all,start\n1,Mug Mug,all,\n");
        assert!(
            e.contains("line 3") && e.contains("targets") && e.contains("twice"),
            "{e}"
        );
        let e = err("house,targets,goal,destination\n0,A B C D E,all,\n");
        assert!(e.contains("line 2") && e.contains("at most 4"), "{e}");
        let e = err("house,targets,goal,destination\n0,Mug,some,\n");
        assert!(e.contains("line 2") && e.contains("goal"), "{e}");
        let e = err("house,targets,goal,destination\nzero,Mug,all,\n");
        assert!(e.contains("house") && e.contains("zero"), "{e}");
        let e = err("house,targets\n");
        assert!(e.contains("no task"), "{e}");
        let ok = read_task_file(&write(
            "house,targets,goal,destination\n0,Mug+Apple,,start\n2, Cup ,any,\n",
        ))
        .unwrap();
        assert_eq!(ok.len(), 2);
        assert_eq!(ok[0].task.targets, ["Mug", "Apple"]);
        assert_eq!(ok[0].task.to_string(), "Mug+Apple@start");
        assert_eq!(ok[1].task.to_string(), "Cup");
        assert_eq!(ok[1].task.goal, Goal::Any);
    }

    #[test]
    fn task_texts_parse_and_print() {
        for s in ["Mug", "Mug+Apple@start", "Mug|Cup", "Mug@room:room|4"] {
            assert_eq!(s.parse::<TaskText>().unwrap().to_string(), s);
        }
        assert_eq!("Mug|Cup".parse::<TaskText>().unwrap().goal, Goal::Any);
        assert_eq!(
            "A+B+C+D+E".parse::<TaskText>().unwrap_err().field,
            "targets"
        );
        assert!("Mug+Mug".parse::<TaskText>().is_err());
    }

    #[test]
    fn deliver_rules_parse_and_print() {
        for s in ["start", "room:Kitchen", "container:Sofa"] {
            assert_eq!(s.parse::<Deliver>().unwrap().to_string(), s);
        }
        assert_eq!("moon".parse::<Deliver>().unwrap_err().field, "destination");
        assert!("room:".parse::<Deliver>().is_err());
    }
}
