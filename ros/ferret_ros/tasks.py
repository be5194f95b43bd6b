"""Household tasks as the node takes them: several target types, a goal (`all` or `any`) and a
destination where the robot brings what it found (docs/tasks.md). `task_from_goal` reads and
checks a `SearchObject` goal, refusing a bad one with a message that names the goal's field;
`parse_task` reads the short form of `ferret deploy --find` (`Mug+Apple@start`, `Mug|Cup`).

Nothing here talks to ROS or ferret: a goal is anything with the goal's attributes.
"""

import difflib
import math
from dataclasses import dataclass
from typing import Optional, Sequence, Tuple

from .planners import PlannerError, check_target

# A task asks for 1 to this many object types (as ferret and `ferret serve` take them).
MAX_TARGETS = 4

# The goal's constants (ferret_interfaces/action/SearchObject.action).
GOAL_ALL, GOAL_ANY = 0, 1
GOALS = {GOAL_ALL: "all", GOAL_ANY: "any"}
(
    DESTINATION_NONE,
    DESTINATION_START,
    DESTINATION_CONTAINER,
    DESTINATION_ROOM,
    DESTINATION_POSE,
) = range(5)
DESTINATION_KINDS = {
    DESTINATION_NONE: "DESTINATION_NONE",
    DESTINATION_START: "DESTINATION_START",
    DESTINATION_CONTAINER: "DESTINATION_CONTAINER",
    DESTINATION_ROOM: "DESTINATION_ROOM",
    DESTINATION_POSE: "DESTINATION_POSE",
}


@dataclass(frozen=True)
class Destination:
    """Where the robot brings what it found: `kind` is `start`, `container` (`name` its id),
    `room` (`name` as the scene names it) or `point` (`x`, `y` in the map frame, `yaw` radians
    when the goal gave an orientation)."""

    kind: str
    name: str = ""
    x: float = 0.0
    y: float = 0.0
    yaw: Optional[float] = None

    @property
    def field(self) -> str:
        """The goal's field that says where it is."""
        return {"container": "destination_id", "room": "destination_id"}.get(
            self.kind, "destination_pose" if self.kind == "point" else "destination_kind"
        )

    def label(self) -> str:
        if self.kind == "start":
            return "the start"
        if self.kind in ("container", "room"):
            return f"{self.kind} {self.name}"
        return f"({self.x:.2f}, {self.y:.2f})"

    def for_python(self):
        """As `ferret.Search(destination=...)` takes it."""
        if self.kind == "point":
            return (self.x, self.y)
        if self.kind == "start":
            return "start"
        return f"{self.kind}:{self.name}"

    def for_serve(self) -> dict:
        """As `ferret serve`'s `POST /deployments/{id}/trials` takes it."""
        if self.kind == "container":
            return {"kind": "container", "id": self.name}
        if self.kind == "room":
            return {"kind": "room", "name": self.name}
        if self.kind == "point":
            return {"kind": "point", "x": self.x, "y": self.y}
        return {"kind": "start"}


@dataclass(frozen=True)
class Task:
    """What a goal asks for. One target, goal `all`, no destination is the single-target
    search the node always ran (`single`), planned exactly as before tasks."""

    targets: Tuple[str, ...]
    goal: str = "all"
    destination: Optional[Destination] = None

    @property
    def single(self) -> bool:
        return len(self.targets) == 1 and self.goal == "all" and self.destination is None

    @property
    def label(self) -> str:
        """The targets as ferret writes a task: joined by + (all) or | (any)."""
        return ("|" if self.goal == "any" else "+").join(self.targets)

    def describe(self) -> str:
        """For people: `Mug` / `Mug and Apple` / `Mug or Cup`, and where to."""
        what = self.targets[0]
        if len(self.targets) > 1:
            word = " or " if self.goal == "any" else " and "
            what = ", ".join(self.targets[:-1]) + word + self.targets[-1]
        if self.destination is not None:
            what += f", brought to {self.destination.label()}"
        return what


def _unknown(field: str, what: str, name: str, known: Sequence[str], scene: str) -> PlannerError:
    close = difflib.get_close_matches(name, list(known), 1, cutoff=0.6)
    hint = f"did you mean {close[0]!r}?" if close else f"it has {', '.join(known)}"
    return PlannerError(f"{field}: scene {scene!r} has no {what} {name!r}: {hint}")


def task_from_goal(
    goal,
    known: Sequence[str],
    containers: Sequence[str],
    rooms: Sequence[str],
    scene: str,
    frame: str,
) -> Task:
    """The task a SearchObject goal asks for, checked against the scene: its object types
    (`known`; empty: any name), container ids and room names; `frame` is the map frame a
    destination pose must be given in. Raises PlannerError naming the goal's field."""
    single = goal.target_type.strip()
    many = [t.strip() for t in goal.target_types]
    if single and many:
        raise PlannerError(
            "target_type and target_types: give one of them (target_types for a task of "
            "several targets)"
        )
    if not single and not many:
        raise PlannerError("target_type is empty")
    if single:
        # The message of a misspelt single target stays what it always was.
        check_target(single, known, scene)
        targets: Tuple[str, ...] = (single,)
    else:
        if len(many) > MAX_TARGETS:
            raise PlannerError(
                f"target_types: {len(many)} targets; a task takes 1 to {MAX_TARGETS}"
            )
        for i, t in enumerate(many):
            if not t:
                raise PlannerError(f"target_types[{i}] is empty")
            if t in many[:i]:
                raise PlannerError(
                    f"target_types[{i}]: {t!r} is given twice (also target_types[{many.index(t)}])"
                )
            try:
                check_target(t, known, scene)
            except PlannerError as e:
                raise PlannerError(f"target_types[{i}]: {e}") from e
        targets = tuple(many)
    if goal.goal_kind not in GOALS:
        raise PlannerError(
            f"goal_kind: {goal.goal_kind}; expected GOAL_ALL ({GOAL_ALL}) or GOAL_ANY ({GOAL_ANY})"
        )
    return Task(targets, GOALS[goal.goal_kind], _destination(goal, containers, rooms, scene, frame))


def _destination(goal, containers, rooms, scene, frame) -> Optional[Destination]:
    kind = goal.destination_kind
    name = goal.destination_id.strip()
    if kind not in DESTINATION_KINDS:
        expected = ", ".join(f"{v} ({k})" for k, v in DESTINATION_KINDS.items())
        raise PlannerError(f"destination_kind: {kind}; expected one of {expected}")
    if name and kind not in (DESTINATION_CONTAINER, DESTINATION_ROOM):
        # A client that named a place but forgot the kind would otherwise get no destination.
        raise PlannerError(
            f"destination_id: {name!r} with destination_kind {DESTINATION_KINDS[kind]}: a "
            "container or room needs DESTINATION_CONTAINER or DESTINATION_ROOM"
        )
    if kind == DESTINATION_NONE:
        return None
    if kind == DESTINATION_START:
        return Destination("start")
    if kind == DESTINATION_CONTAINER:
        if not name:
            raise PlannerError(
                "destination_id is empty: DESTINATION_CONTAINER needs a container id"
            )
        if name not in containers:
            raise _unknown("destination_id", "container", name, containers, scene)
        return Destination("container", name)
    if kind == DESTINATION_ROOM:
        if not name:
            raise PlannerError("destination_id is empty: DESTINATION_ROOM needs a room name")
        if name not in rooms:
            raise _unknown("destination_id", "room", name, rooms, scene)
        return Destination("room", name)
    pose = goal.destination_pose
    if pose.header.frame_id not in ("", frame):
        raise PlannerError(
            f"destination_pose.header.frame_id: {pose.header.frame_id!r}; the node plans in the "
            f"map frame {frame!r}"
        )
    p, q = pose.pose.position, pose.pose.orientation
    if not (math.isfinite(p.x) and math.isfinite(p.y)):
        raise PlannerError(f"destination_pose: ({p.x}, {p.y}) is not a point of the floor")
    yaw = None
    if (q.x, q.y, q.z, q.w) != (0.0, 0.0, 0.0, 0.0):  # an all-zero quaternion: none given
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
    return Destination("point", x=float(p.x), y=float(p.y), yaw=yaw)


def parse_task(text: str) -> Task:
    """`ferret deploy --find`'s form of one task: targets joined by + (all) or | (any), then
    optionally `@start`, `@container:<id>`, `@room:<name>` or `@<x>,<y>`. Checked against no
    scene (the node does that)."""
    what, _, where = text.partition("@")
    if "+" in what and "|" in what:
        raise ValueError(f"{text!r}: join targets with + (all) or | (any), not both")
    goal = "any" if "|" in what else "all"
    targets = tuple(t.strip() for t in what.replace("|", "+").split("+"))
    if not all(targets):
        raise ValueError(f"{text!r}: an empty target")
    where = where.strip()
    destination = None
    if where == "start":
        destination = Destination("start")
    elif where.startswith(("container:", "room:")):
        kind, _, name = where.partition(":")
        destination = Destination(kind, name.strip())
    elif where:
        try:
            x, y = (float(v) for v in where.split(","))
        except ValueError:
            raise ValueError(
                f"{text!r}: a destination is start, container:<id>, room:<name> or <x>,<y>"
            ) from None
        destination = Destination("point", x=x, y=y)
    return Task(targets, goal, destination)
