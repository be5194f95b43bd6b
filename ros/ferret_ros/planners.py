"""Where the node asks which container to search next: the `ferret` Python package in process
(default), or a `ferret serve` server shared by a fleet. Both give the node the same small
interface, so the ROS side does not know which it talks to.

A *planner* holds the scene and, across trials, the deployment that selects the strategy of
each trial (`ferret deploy`'s selection). `start(task, scene, deployment)` opens a *trial* for a
target or a household task (ferret_ros.tasks.Task: several targets, a goal, a destination):
`next()` says which container to search (None once the goal holds or every container was
searched), `record()` what was seen there, `finish()` ends it (selection learns from a search
whose goal holds; with a destination, the way there is then part of its cost) and `abandon()`
ends it after a failure (selection learns nothing). `found_in` says which targets were found
where, `destination()` where the robot brings them and `destination_path()` the way there.
`belief()` gives the probability that each container holds a target still wanted (None when the
strategy has no likelihood), `path_to()` the planner's route to a container.
"""

import difflib
import json
import math
import os
import tempfile
import time
import urllib.error
import urllib.parse
import urllib.request
import uuid
from dataclasses import dataclass
from typing import TYPE_CHECKING, Dict, List, Optional, Sequence, Tuple, Union

import yaml

import ferret

if TYPE_CHECKING:
    from .tasks import Task

# A robot pose this close to the scene's start (metres) plans from the start itself.
AT_START_M = 0.05
# Scenes placed at other poses kept at once (each holds its grid and distances).
PLACED_MAX = 32


class PlannerError(Exception):
    """ferret refused or failed; the message says why, for the action's result. `status` is the
    HTTP status when `ferret serve` answered with an error; `field` names what of a task was
    refused when that was its destination (`destination`, the message then without the field)."""

    def __init__(self, message: str, status: Optional[int] = None, field: str = ""):
        super().__init__(message)
        self.status = status
        self.field = field


def path_problem(path: str, error: Exception) -> str:
    """`error` about reading `path`, saying which file a relative path that does not exist was
    taken to be: the node (and the simulator) may run from any directory."""
    message = f"{path}: {error}" if path not in str(error) else str(error)
    if not os.path.isabs(path) and not os.path.exists(path):
        message += (
            f" (a relative path is read from the current directory, {os.getcwd()}: "
            f"{os.path.abspath(path)} does not exist)"
        )
    return message


def _squashed(name: str) -> str:
    return "".join(c for c in name.casefold() if c.isalnum())


def check_target(target: str, known: Sequence[str], scene: str) -> None:
    """Refuses a target that is not one of the object types the scene lists (`known`): a search
    for it could only end "not found" after visiting every container. A name that differs from a
    known one only in case, spaces or punctuation ("wallet", "remote control"), or by a typo, is
    suggested; otherwise the known names are listed. A scene that lists no objects (a real home,
    where nobody wrote down what is where) has no vocabulary to check against."""
    if not known or target in known:
        return
    same = [k for k in known if _squashed(k) == _squashed(target)]
    # 0.8: one letter off in a long name ("Walet", "AlarmClok"), not merely a similar word
    # ("Toaster" is not "Tomato").
    lower = [k.casefold() for k in known]
    close = same or difflib.get_close_matches(target.casefold(), lower, 1, cutoff=0.8)
    if close:
        match = next(k for k in known if k.casefold() == close[0].casefold())
        raise PlannerError(f"unknown target {target!r}: did you mean {match!r}?")
    raise PlannerError(
        f"unknown target {target!r}: scene {scene!r} holds {len(known)} object types: "
        + ", ".join(known)
    )


@dataclass(frozen=True)
class Place:
    """A container as the node needs it: where to drive to and where to look."""

    id: str
    type: str
    room: str
    access: Tuple[float, float]
    position: Tuple[float, float]


class InProcessPlanner:
    """The `ferret` package in this process: `ferret.Search` per trial and, with several
    strategies, a `ferret.Deployment` choosing among them between trials."""

    kind = "python"

    def __init__(
        self,
        scene: str,
        strategies: Sequence[str],
        method: str = "replay",
        c: float = 5.0,
        seed: int = 0,
        prior: Optional[str] = None,
        config: Optional[str] = None,
    ):
        try:
            houses = ferret.load_houses(scene)
        except ferret.FerretError as e:
            raise PlannerError(f"scene {path_problem(scene, e)}") from e
        if len(houses) != 1:
            raise PlannerError(f"scene {scene}: holds {len(houses)} houses, the node needs one")
        self.house = houses[0]
        self.scene_name = self.house.name
        self.scene_path = os.path.abspath(scene)
        self._placed: Dict[Tuple[int, int, int], "ferret.House"] = {}
        strategies = [s.strip() for s in strategies if s.strip()]
        if not strategies:
            raise PlannerError("strategies: name at least one strategy")
        self.options = {}
        if prior:
            self.options["prior"] = prior
        if config:
            self.options["config"] = config
        self.strategies = strategies
        self.deployment = None
        try:
            if len(strategies) > 1:
                self.deployment = ferret.Deployment(
                    strategies, method=method, c=c, seed=seed, **self.options
                )
            else:
                # Fails now, not at the first goal, for a spec that names no strategy or a
                # likelihood source that cannot answer for this scene (a learned prior without the
                # embeddings for its names): planned once for one of its own targets.
                targets = self.house.target_types()
                ferret.Search(
                    self.house, targets[0] if targets else "_", strategies[0], **self.options
                )
        except ferret.FerretError as e:
            raise PlannerError(str(e)) from e
        self._places = [
            Place(
                c.id,
                c.type,
                c.room or "",
                c.access if c.access is not None else c.position,
                c.position,
            )
            for c in self.house.containers
        ]

    def places(self, scene: str = "") -> List[Place]:
        self._check_scene(scene)
        return self._places

    def object_types(self, scene: str = "") -> List[str]:
        """The object types the scene lists in its containers, sorted."""
        self._check_scene(scene)
        return sorted({o.type for o in self.house.objects})

    def start_pose(self) -> Tuple[float, float]:
        return (self.house.start[0], self.house.start[1])

    def _check_scene(self, scene: str) -> None:
        if scene and scene != self.scene_name:
            raise PlannerError(
                f"scene {scene!r}: this node plans in {self.scene_name!r} (its `scene` parameter)"
            )

    def house_at(self, pose: Optional[Tuple[float, float, float]]) -> "ferret.House":
        """The scene with the robot starting at `pose` (x, y metres, yaw degrees), so that a
        trial plans from where the robot is, as a `ferret serve` trial with a pose does: the
        scene file with its start moved, loaded again (its grid and distances are built anew,
        about a second for the example apartment; kept per pose)."""
        if pose is None or math.dist(pose[:2], self.start_pose()) <= AT_START_M:
            return self.house
        key = (round(pose[0] / 0.01), round(pose[1] / 0.01), round(pose[2]))
        if key in self._placed:
            return self._placed[key]
        try:
            with open(self.scene_path, encoding="utf-8") as f:
                doc = yaml.safe_load(f)
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:
            raise PlannerError(
                f"scene {self.scene_path}: cannot be read again to move its start: {e}"
            ) from e
        if not isinstance(doc, dict) or "ferret_scene" not in doc:
            raise PlannerError(
                f"scene {self.scene_path}: only ferret scene files can start from the robot's "
                "pose (set plan_from_robot_pose to false to plan from the house's start)"
            )
        doc["start"] = [pose[0], pose[1], pose[2]]
        m = doc.get("map")
        if isinstance(m, dict) and m.get("ros"):
            # The copy lives elsewhere: its map path must not be relative.
            m["ros"] = os.path.join(os.path.dirname(self.scene_path), m["ros"])
        fd, tmp = tempfile.mkstemp(suffix=".json", prefix="ferret-scene-")
        try:
            with os.fdopen(fd, "w") as f:
                json.dump(doc, f)
            house = ferret.load_houses(tmp)[0]
            house.distances()  # the grid is built here, not in the first planning step
        except ferret.FerretError as e:
            raise PlannerError(f"the robot's pose ({pose[0]:.2f}, {pose[1]:.2f}): {e}") from e
        finally:
            os.unlink(tmp)
        if len(self._placed) >= PLACED_MAX:
            self._placed.pop(next(iter(self._placed)))
        self._placed[key] = house
        return house

    def start(
        self,
        task: Union[str, "Task"],
        scene: str = "",
        deployment: int = 0,
        pose: Optional[Tuple[float, float, float]] = None,
    ) -> "InProcessTrial":
        task = as_task(task)
        self._check_scene(scene)
        if deployment:
            raise PlannerError(
                f"deployment_id {deployment}: deployments by id are `ferret serve`'s; this node "
                "runs its own (leave deployment_id 0)"
            )
        house = self.house_at(pose)
        strategy = self.deployment.choose() if self.deployment else self.strategies[0]
        try:
            if task.single:
                # The paper's search, exactly as before tasks.
                search = ferret.Search(house, task.targets[0], strategy, **self.options)
            else:
                search = ferret.Search(
                    house,
                    list(task.targets),
                    strategy,
                    goal=task.goal,
                    destination=(
                        task.destination.for_python() if task.destination is not None else None
                    ),
                    **self.options,
                )
        except ferret.FerretError as e:
            if self.deployment:
                self.deployment.abandon()
            message = str(e)
            if message.startswith("destination: "):
                raise PlannerError(message[len("destination: ") :], field="destination") from e
            raise PlannerError(message) from e
        return InProcessTrial(self, search, task)

    def rooms(self, scene: str = "") -> List[str]:
        """The rooms' names, as a destination names them."""
        self._check_scene(scene)
        return [r.id for r in self.house.rooms]


def as_task(task: Union[str, "Task"]) -> "Task":
    """A target's name as the task of one target it is."""
    from .tasks import Task

    return Task((task,)) if isinstance(task, str) else task


class InProcessTrial:
    def __init__(self, planner: InProcessPlanner, search: "ferret.Search", task: "Task"):
        self.planner = planner
        self.search = search
        self.task = task
        self.strategy = search.strategy
        self.ended = False
        self._by_id = {p.id: p for p in planner._places}
        self._likelihoods: Optional[Dict[str, List[float]]] = None
        self._asked = False
        # The way from the last container to the destination, taken when the trial ends.
        self._way: Optional[List[Tuple[float, float]]] = None
        self.delivery_m = 0.0

    def next(self) -> Optional[Place]:
        try:
            c = self.search.next_container()
        except ferret.FerretError as e:
            raise PlannerError(str(e)) from e
        return None if c is None else self._by_id[c.id]

    def record(self, container: str, objects: Sequence[str]) -> float:
        """What the detector saw in `container`: the targets among `objects` are found."""
        seen = [t for t in self.task.targets if t in objects]
        try:
            if self.task.single:
                return self.search.record(container, bool(seen), list(objects))
            return self.search.record(container, objects=list(objects), found_targets=seen)
        except ferret.FerretError as e:
            raise PlannerError(str(e)) from e

    @property
    def found_in(self) -> Dict[str, str]:
        """Each target found so far and the container it was first seen in, in task order."""
        return {t: c.id for t, c in self.search.found_in.items()}

    @property
    def goal_holds(self) -> bool:
        return self.search.goal_holds

    @property
    def found_at(self) -> Optional[str]:
        """The container where the goal came to hold."""
        f = self.search.found
        return None if f is None else f.id

    def destination(self) -> Optional[Tuple[float, float]]:
        """Where the robot brings what it found (the point it stands at there), or None."""
        return self.search.destination

    def destination_path(self) -> List[Tuple[float, float]]:
        """ferret's way to the destination from the last container searched (from where the
        robot is until the trial ends); empty without a destination."""
        if self._way is not None:
            return self._way
        return [tuple(p) for p in self.search.path_to_destination() or []]

    def belief(self) -> Optional[Dict[str, float]]:
        """Per container id: the chance that it holds a target still wanted, from the
        strategy's likelihoods before the search, 0 once searched in vain, 1 where a target was
        found (what `ferret serve`'s trial view gives); None without a likelihood source. For a
        task, 1 - prod(1 - p_t) over the targets not found yet, 0 everywhere else once the goal
        holds. The source is asked once per trial: an LLM source that fails is not asked again
        at every step."""
        if not self._asked:
            self._asked = True
            rows = {t: self.search.likelihoods(t) for t in self.task.targets}
            if all(r is not None for r in rows.values()):
                self._likelihoods = rows
        if self._likelihoods is None:
            return None
        searched = set(self.search.searched)
        if len(self.task.targets) == 1:
            (row,) = self._likelihoods.values()
            found = self.search.found
            out = {}
            for p, likelihood in zip(self.planner._places, row):
                if found is not None and p.id == found.id:
                    out[p.id] = 1.0
                elif p.id in searched:
                    out[p.id] = 0.0
                else:
                    out[p.id] = float(likelihood)
            return out
        found_in = self.found_in
        holding = set(found_in.values())
        done = self.search.goal_holds
        wanted = [r for t, r in self._likelihoods.items() if t not in found_in]
        out = {}
        for i, p in enumerate(self.planner._places):
            if p.id in holding:
                out[p.id] = 1.0
            elif done or p.id in searched:
                out[p.id] = 0.0
            else:
                none = 1.0
                for r in wanted:
                    none *= 1.0 - float(r[i])
                out[p.id] = 1.0 - none
        return out

    def path_to(self, place: Place) -> List[Tuple[float, float]]:
        """ferret's grid path from where the robot is to `place`'s access point."""
        try:
            return [tuple(p) for p in self.search.path_to(place.id)]
        except ferret.FerretError as e:
            raise PlannerError(str(e)) from e

    @property
    def searched(self) -> List[str]:
        return self.search.searched

    @property
    def cost(self) -> float:
        return self.search.cost

    def finish(self) -> Optional[Dict[str, float]]:
        """Ends the trial; with a destination the robot's way there is added to its cost (the
        driving itself is the node's). With a deployment, every candidate's replay cost when the
        goal holds (the deployment learns), else None."""
        if self.ended:
            return None
        self.ended = True
        if self.task.destination is not None:
            self._way = [tuple(p) for p in self.search.path_to_destination() or []]
        d = self.planner.deployment
        replays = None
        try:
            if d is not None:
                if self.search.goal_holds:
                    # Deployment.finish takes the search to its destination itself.
                    replays = d.finish(self.search)
                else:
                    d.abandon()
        finally:
            if self.task.destination is not None:
                self.delivery_m = self.search.finish()  # the same leg again once finished
        return replays

    def abandon(self) -> None:
        if not self.ended:
            self.ended = True
            if self.planner.deployment is not None:
                self.planner.deployment.abandon()


class ServePlanner:
    """A `ferret serve` server: the scene, the deployment and every trial live there (see
    docs/serve.md); the node only drives the robot. Requests carry ids, so a retried request
    changes nothing."""

    kind = "serve"

    def __init__(
        self,
        url: str,
        scene: str,
        strategies: Sequence[str],
        method: str = "replay",
        c: float = 5.0,
        seed: int = 0,
        token: Optional[str] = None,
        timeout_s: float = 30.0,
        robot_id: str = "",
        team: Sequence[str] = (),
        team_wait_s: float = 60.0,
    ):
        self.url = url.rstrip("/")
        # A team (robot ids, this robot's among them) searches each trial together: the first
        # starts it, the others join it (see ServeTeamTrial).
        self.robot_id = robot_id
        self.team = [r for r in team if r]
        self.team_wait_s = team_wait_s
        if self.team and robot_id not in self.team:
            raise PlannerError(
                f"parameter `serve_team`: {list(self.team)} does not name this robot "
                f"({robot_id!r}, parameter `serve_robot_id`)"
            )
        self.token = token or None
        self.timeout_s = timeout_s
        self.scene_name = scene
        self.strategies = [s.strip() for s in strategies if s.strip()]
        self.method, self.c, self.seed = method, c, seed
        self.deployment_id = 0
        self._scenes: Dict[str, dict] = {}
        # Cleared when the server turns out to have no trial view (one older than the node).
        self.has_view = True
        if scene:
            self.places(scene)

    def request(self, method: str, path: str, body: Optional[dict] = None) -> dict:
        data = None
        headers = {"Accept": "application/json"}
        if body is not None:
            body = dict(body, request_id=str(uuid.uuid4()))
            data = json.dumps(body).encode()
            headers["Content-Type"] = "application/json"
        if self.token:
            headers["Authorization"] = "Bearer " + self.token
        req = urllib.request.Request(self.url + path, data=data, headers=headers, method=method)
        try:
            with urllib.request.urlopen(req, timeout=self.timeout_s) as resp:
                return json.loads(resp.read() or b"{}")
        except urllib.error.HTTPError as e:
            try:
                err = json.loads(e.read()).get("error", {})
                message, field = err.get("message", ""), err.get("field", "")
            except (ValueError, AttributeError):
                message, field = "", ""
            if field.startswith("destination"):
                # A task's destination the scene does not have or the robot cannot reach: the
                # node names the goal's own field.
                raise PlannerError(message, status=e.code, field="destination") from e
            raise PlannerError(
                f"ferret serve: {method} {path} -> {e.code}: {message}", status=e.code
            ) from e
        except (urllib.error.URLError, OSError) as e:
            raise PlannerError(f"ferret serve at {self.url} unreachable: {e}") from e

    def _scene(self, scene: str) -> dict:
        name = scene or self.scene_name
        if not name:
            raise PlannerError("no scene: set the `serve_scene` parameter or the goal's scene")
        if name not in self._scenes:
            self._scenes[name] = self.request("GET", "/scenes/" + urllib.parse.quote(name, safe=""))
        return self._scenes[name]

    def places(self, scene: str = "") -> List[Place]:
        s = self._scene(scene)
        out = []
        for c in s["containers"]:
            access = c.get("access") or [c["x"], c["y"]]
            out.append(
                Place(
                    c["id"],
                    c["type"],
                    c.get("room") or "",
                    (access[0], access[1]),
                    (c["x"], c["y"]),
                )
            )
        return out

    def object_types(self, scene: str = "") -> List[str]:
        """The object types the scene lists in its containers, sorted."""
        s = self._scene(scene)
        return sorted({t for c in s["containers"] for t in c.get("contents") or []})

    def start_pose(self, scene: str = "") -> Tuple[float, float]:
        start = self._scene(scene)["start"]
        return (start[0], start[1])

    def rooms(self, scene: str = "") -> List[str]:
        """The rooms' names, as a destination names them."""
        return [r["name"] for r in self._scene(scene).get("rooms") or []]

    def start(
        self,
        task: Union[str, "Task"],
        scene: str = "",
        deployment: int = 0,
        pose: Optional[Tuple[float, float, float]] = None,
    ) -> "ServeTrial":
        task = as_task(task)
        scene = scene or self.scene_name
        places = {p.id: p for p in self.places(scene)}
        if deployment == 0:
            if not self.deployment_id:
                body = {"selector": self.method, "c": self.c, "seed": self.seed}
                if self.strategies:
                    body["strategies"] = self.strategies
                self.deployment_id = self.request("POST", "/deployments", body)["id"]
            deployment = self.deployment_id
        if self.team:
            return self._team_trial(task, scene, deployment, places, pose)
        state = self.request("GET", f"/deployments/{deployment}")
        me = self.robot_id or None
        open_trial = next(
            (
                t["trial"]
                for t in state.get("trials") or []
                if t.get("status") == "searching" and t.get("robot") == me
            ),
            None,
        )
        if open_trial:
            # A trial of this robot left open (this node stopped in the middle of a search,
            # before it could abandon it): go on with it when it looks for the same object.
            # Other robots' open trials are theirs.
            t = self.request("GET", f"/trials/{open_trial}")
            if not same_task(t, task) or t["scene"] != scene:
                raise PlannerError(
                    f"deployment {deployment} has trial {open_trial} open (a search for "
                    f"{t['target']} in {t['scene']}); finish that search first"
                )
            return ServeTrial(self, t, places, task)
        if task.single:
            body = {"scene": scene, "target": task.targets[0]}
        else:
            body = {"scene": scene, "targets": list(task.targets), "goal": task.goal}
            if task.destination is not None:
                body["destination"] = task.destination.for_serve()
        if pose is not None:
            body["pose"] = [pose[0], pose[1], pose[2]]
        if me is not None:
            body["robot"] = me
        t = self.request("POST", f"/deployments/{deployment}/trials", body)
        return ServeTrial(self, t, places, task)

    def _team_trial(self, task, scene, deployment, places, pose) -> "ServeTeamTrial":
        """The team's trial for `task`: started by the team's first robot (naming the team,
        from this robot's pose), found among the deployment's trials by the others (the newest
        one naming this robot that asks for the same and that this robot has not searched)."""
        if task.destination is not None:
            raise PlannerError(
                "a team's robots do not bring what they found yet: give the team a task "
                "without a destination",
                field="destination",
            )
        if self.robot_id == self.team[0]:
            if task.single:
                body = {"scene": scene, "target": task.targets[0]}
            else:
                body = {"scene": scene, "targets": list(task.targets), "goal": task.goal}
            if pose is not None:
                body["pose"] = [pose[0], pose[1], pose[2]]
            body["robots"] = [{"id": r} for r in self.team]
            t = self.request("POST", f"/deployments/{deployment}/trials", body)
            return ServeTeamTrial(self, t, places, task)
        deadline = time.monotonic() + self.team_wait_s
        while True:
            state = self.request("GET", f"/deployments/{deployment}")
            for summary in reversed(state.get("trials") or []):
                if summary.get("status") != "searching":
                    continue
                t = self.request("GET", f"/trials/{summary['trial']}")
                mine = [r for r in t.get("robots") or [] if r.get("id") == self.robot_id]
                if mine and same_task(t, task) and t["scene"] == scene and not mine[0]["searched"]:
                    return ServeTeamTrial(self, t, places, task)
            if time.monotonic() > deadline:
                raise PlannerError(
                    f"no trial of deployment {deployment} for {task.label} names this robot "
                    f"({self.robot_id}) after {self.team_wait_s:g} s: the team's first robot, "
                    f"{self.team[0]}, starts it"
                )
            time.sleep(0.1)


def same_task(state: dict, task: "Task") -> bool:
    """Whether a trial's state asks for `task` (an open trial the node may go on with)."""
    if list(state.get("targets") or [state["target"]]) != list(task.targets):
        return False
    if state.get("goal", "all") != task.goal:
        return False
    d = state.get("destination")
    if task.destination is None or d is None:
        return task.destination is None and d is None
    want = task.destination.for_serve()
    return all(d.get(k) == v for k, v in want.items())


class ServeTrial:
    def __init__(self, planner: ServePlanner, state: dict, places: Dict[str, Place], task: "Task"):
        self.planner = planner
        self.state = state
        self.places = places
        self.task = task
        self.strategy = state["strategy"]
        self.ended = False
        # Why the server could not be told of an abandoned search, if it could not.
        self.abandon_error: Optional[str] = None

    def next(self) -> Optional[Place]:
        n = self.state.get("next")
        if self.state.get("status") != "searching" or not n:
            return None
        return self.places[n["container"]]

    def record(self, container: str, objects: Sequence[str]) -> float:
        """What the detector saw in `container`: the targets among `objects` are found."""
        before = self.state.get("cost_m") or 0.0
        seen = [t for t in self.task.targets if t in objects]
        body = {"container": container, "found": bool(seen), "objects": list(objects)}
        if not self.task.single:
            body["found_targets"] = seen
        self.state = self.planner.request(
            "POST", f"/trials/{self.state['trial']}/observations", body
        )
        return (self.state.get("cost_m") or 0.0) - before

    @property
    def found_in(self) -> Dict[str, str]:
        """Each target found so far and the container it was first seen in, in task order (a
        one-target trial's `found_in` stays empty until it ends: its found container then)."""
        f = self.state.get("found_in") or {}
        out = {t: f[t] for t in self.task.targets if t in f}
        if not out and self.task.single and self.state.get("status") == "done":
            out = {self.task.targets[0]: self.searched[-1]}
        return out

    @property
    def goal_holds(self) -> bool:
        return self.state.get("status") == "done"

    @property
    def found_at(self) -> Optional[str]:
        """The container where the goal came to hold: the last searched, once done."""
        return self.searched[-1] if self.goal_holds and self.searched else None

    def destination(self) -> Optional[Tuple[float, float]]:
        d = self.state.get("destination")
        if not d or not d.get("at"):
            return None
        return (float(d["at"][0]), float(d["at"][1]))

    def destination_path(self) -> List[Tuple[float, float]]:
        """The server's way to the destination, once the trial has ended (`destination.path`)."""
        d = self.state.get("destination") or {}
        return [(float(x), float(y)) for x, y in d.get("path") or []]

    @property
    def delivery_m(self) -> float:
        d = self.state.get("destination") or {}
        return float(d.get("distance_m") or 0.0)

    def belief(self) -> Optional[Dict[str, float]]:
        """The trial view's likelihoods (`GET /trials/{id}/view`): what the server's web page
        shows, already 0 where searched in vain and 1 where found; None for a strategy without
        a likelihood, or from a server without the view (said once, by the PlannerError)."""
        if not self.planner.has_view:
            return None
        try:
            view = self.planner.request("GET", f"/trials/{self.state['trial']}/view")
        except PlannerError as e:
            # The trial exists (the server just answered for it): a 404 or 405 is the route.
            if e.status in (404, 405):
                self.planner.has_view = False
                raise PlannerError(
                    f"{e} (this ferret serve has no trial view: the belief's probabilities are NaN)"
                ) from e
            raise
        ps = view.get("likelihoods")
        if ps is None:
            return None
        return {k: float(v) for k, v in ps.items()}

    def path_to(self, place: Place) -> List[Tuple[float, float]]:
        """The server's path to its next container (`next.path`): cell centres from where the
        robot is to the access point; empty for any other container."""
        n = self.state.get("next") or {}
        if n.get("container") != place.id:
            return []
        return [(float(x), float(y)) for x, y in n.get("path") or []]

    @property
    def searched(self) -> List[str]:
        return list(self.state.get("searched") or [])

    @property
    def cost(self) -> float:
        return float(self.state.get("cost_m") or 0.0)

    def finish(self) -> Optional[Dict[str, float]]:
        self.ended = True
        return self.state.get("replays_m")

    def abandon(self) -> None:
        """Ends the trial on the server as abandoned (it teaches selection nothing), so that a
        failed search does not stay open there. Best effort: a server out of reach keeps the
        trial open, and the next search for the same object goes on with it."""
        if self.ended:
            return
        self.ended = True
        try:
            self.state = self.planner.request("POST", f"/trials/{self.state['trial']}/abandon", {})
        except PlannerError as e:
            self.abandon_error = str(e)


class ServeTeamTrial(ServeTrial):
    """This robot's part of a team's trial on `ferret serve`: the server claims each robot's
    next container (never a teammate's), and every robot reports with its id. A robot with
    nothing left to claim waits for its teammates; the trial ends for all once one finds what
    it asks for. The cost is this robot's own way (the trial's is the team's makespan)."""

    # How often a robot with nothing to do asks again, and for how long at most.
    POLL_S = 0.1

    def __init__(self, planner: ServePlanner, state: dict, places: Dict[str, Place], task: "Task"):
        super().__init__(planner, state, places, task)
        self.state = self._claim()

    def _claim(self) -> dict:
        return self.planner.request(
            "POST", f"/trials/{self.state['trial']}/claims", {"robot": self.planner.robot_id}
        )

    def next(self) -> Optional[Place]:
        deadline = time.monotonic() + self.planner.team_wait_s
        while self.state.get("status") == "searching" and not self.state.get("next"):
            if time.monotonic() > deadline:
                raise PlannerError(
                    f"trial {self.state['trial']}: nothing left for {self.planner.robot_id} to "
                    f"search for {self.planner.team_wait_s:g} s while its teammates hold the rest"
                )
            time.sleep(self.POLL_S)
            self.state = self._claim()
        return super().next()

    def record(self, container: str, objects: Sequence[str]) -> float:
        before = self.cost
        seen = [t for t in self.task.targets if t in objects]
        body = {
            "robot": self.planner.robot_id,
            "container": container,
            "found": bool(seen),
            "objects": list(objects),
        }
        if not self.task.single:
            body["found_targets"] = seen
        try:
            self.state = self.planner.request(
                "POST", f"/trials/{self.state['trial']}/observations", body
            )
        except PlannerError as e:
            if e.status != 409:
                raise
            # The trial ended meanwhile (a teammate found it), or a teammate searched there
            # first: where the team stands now.
            self.state = self._claim()
        return self.cost - before

    @property
    def cost(self) -> float:
        me = [r for r in self.state.get("robots") or [] if r.get("id") == self.planner.robot_id]
        return float(me[0].get("cost_m") or 0.0) if me else 0.0

    @property
    def mine(self) -> List[str]:
        """The containers this robot searched."""
        me = [r for r in self.state.get("robots") or [] if r.get("id") == self.planner.robot_id]
        return list(me[0].get("searched") or []) if me else []

    def abandon(self) -> None:
        """A robot of a team that fails leaves the trial to its teammates: its claim lapses on
        the server, and the trial goes on."""
        self.ended = True
