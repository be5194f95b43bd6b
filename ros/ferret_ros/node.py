"""The ferret ROS 2 node: find an object with ferret's planner, Nav2 and a detector.

    python3 -m ferret_ros.node --ros-args -p scene:=examples/apartment/scene.yaml \\
        -p strategies:="['model/prior', 'model/uniform', 'optimistic+greedy']"

Serves the action `~/search_object` (ferret_interfaces/action/SearchObject): one object, or a
household task (several objects, all or any of them, brought to a destination). For each step
it asks ferret for the next container, sends a nav2_msgs/NavigateToPose goal to the container's
access point (or, with no Nav2 action server, a PoseStamped on /goal_pose and waits for the
robot's pose to get there), waits for a ferret_interfaces/Detection from the detector for a
bounded time, records what was seen and repeats until the goal holds or every container was
searched; with a destination, it then sends the robot there the same way. Every wait has a
timeout; a failed or timed-out step ends the goal with a status and a sentence saying why. The
belief (per-container probability) is published on `~/belief`, drawn for rviz2 and Foxglove on
`~/markers` (visualization_msgs/MarkerArray), and the route to the next container (or the
destination) on `~/path` (nav_msgs/Path). See docs/ros2.md for the parameters and topics.
"""

import math
import os
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Deque, List, Optional

import rclpy
from action_msgs.msg import GoalStatus
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from nav2_msgs.action import NavigateToPose
from nav_msgs.msg import OccupancyGrid, Path
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from visualization_msgs.msg import MarkerArray

from ferret_interfaces.action import SearchObject
from ferret_interfaces.msg import Belief, Detection

from .maps import Grid, check_map, read_scene_map
from .markers import container_markers, probabilities, route
from .planners import (
    AT_START_M,
    InProcessPlanner,
    Place,
    PlannerError,
    ServePlanner,
)
from .tasks import Task, task_from_goal

Status = SearchObject.Result

# How often the waits look at cancellation and shutdown.
POLL_S = 0.02


class StepFailed(Exception):
    """A step could not be completed; `status` is the result's status constant."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status = status


@dataclass
class StepTiming:
    """Where one step's wall time went, seconds."""

    container: str
    plan_s: float = 0.0  # ferret: next container, recording, belief
    nav_s: float = 0.0  # goal sent until the navigation result arrived
    detect_s: float = 0.0  # arrival until the detection arrived
    total_s: float = 0.0


@dataclass
class GoalTiming:
    target: str
    steps: List[StepTiming] = field(default_factory=list)
    total_s: float = 0.0


def listed(items, word: str) -> str:
    """`a`, `a and b`, `a, b and c`."""
    items = list(items)
    return ", ".join(items[:-1]) + f" {word} " + items[-1] if len(items) > 1 else "".join(items)


def yaw_to_quaternion(yaw: float):
    return (0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2))


class FerretNode(Node):
    def __init__(self, name: str = "ferret", **kwargs):
        super().__init__(name, **kwargs)
        p = self.declare_parameter
        p("backend", "python")
        p("scene", "")
        p("strategies", ["model/prior"])
        p("selection_method", "replay")
        p("selection_c", 5.0)
        p("seed", 0)
        p("prior", "")
        p("llm_config", "")
        p("serve_url", "")
        p("serve_scene", "")
        # A team on `ferret serve`: this robot's id (default: its namespace, else the node's
        # name) and the ids of the robots that search each trial together.
        p("serve_robot_id", "")
        p("serve_team", [""])
        p("serve_team_wait_s", 60.0)
        p("map_topic", "/map")
        p("map_frame", "map")
        p("require_map", True)
        p("map_wait_s", 10.0)
        p("nav_action", "navigate_to_pose")
        p("nav_server_wait_s", 2.0)
        p("nav_timeout_s", 300.0)
        p("behavior_tree", "")
        p("goal_pose_topic", "/goal_pose")
        p("robot_pose_topic", "/amcl_pose")
        p("plan_from_robot_pose", True)
        p("arrival_tolerance_m", 0.3)
        p("detections_topic", "detections")
        p("detection_timeout_s", 5.0)
        p("detection_window_s", 0.0)
        g = lambda n: self.get_parameter(n).value  # noqa: E731

        self.frame = g("map_frame")
        strategies = list(g("strategies"))
        backend = g("backend")
        try:
            if backend == "python":
                if not g("scene"):
                    raise PlannerError("parameter `scene`: the scene file to plan in is required")
                self.planner = InProcessPlanner(
                    g("scene"),
                    strategies,
                    method=g("selection_method"),
                    c=float(g("selection_c")),
                    seed=int(g("seed")),
                    prior=g("prior") or None,
                    config=g("llm_config") or None,
                )
            elif backend == "serve":
                if not g("serve_url"):
                    raise PlannerError("parameter `serve_url`: the ferret serve URL is required")
                self.planner = ServePlanner(
                    g("serve_url"),
                    g("serve_scene"),
                    strategies,
                    method=g("selection_method"),
                    c=float(g("selection_c")),
                    seed=int(g("seed")),
                    token=os.environ.get("FERRET_SERVE_TOKEN"),
                    robot_id=g("serve_robot_id")
                    or (self.get_namespace() if self.get_namespace() != "/" else self.get_name()),
                    team=[t for t in g("serve_team") if t],
                    team_wait_s=float(g("serve_team_wait_s")),
                )
            else:
                raise PlannerError(f"parameter `backend`: {backend!r}, expected python or serve")
        except PlannerError as e:
            self.get_logger().fatal(str(e))
            raise
        # The scene's own map (map: {ros: ...} in the scene file), when there is one, is what a
        # received /map is compared with cell by cell.
        self.reference_map: Optional[Grid] = None
        if g("scene"):
            self.reference_map = read_scene_map(g("scene"))

        self.map: Optional[Grid] = None
        self.map_problems: List[str] = ["no map received yet on " + g("map_topic")]
        self.map_event = threading.Event()
        self.busy = threading.Lock()
        self.robot_pose = None
        self.robot_yaw_deg = 0.0
        self.pose_lock = threading.Lock()
        self.detections: List[Detection] = []
        self.detection_event = threading.Event()
        self.detection_lock = threading.Lock()
        # Where the time of the last searches went (ros/bench_overhead.py reads it).
        self.timings: Deque[GoalTiming] = deque(maxlen=1000)

        io = MutuallyExclusiveCallbackGroup()
        self.reentrant = ReentrantCallbackGroup()
        latched = QoSProfile(
            depth=1,
            durability=DurabilityPolicy.TRANSIENT_LOCAL,
            reliability=ReliabilityPolicy.RELIABLE,
        )
        self.create_subscription(
            OccupancyGrid, g("map_topic"), self._on_map, latched, callback_group=io
        )
        self.create_subscription(
            Detection, g("detections_topic"), self._on_detection, 10, callback_group=io
        )
        self.create_subscription(
            PoseWithCovarianceStamped, g("robot_pose_topic"), self._on_pose, 10, callback_group=io
        )
        self.belief_pub = self.create_publisher(Belief, "~/belief", latched)
        # Latched too: rviz2 or Foxglove opened in the middle of a search draws it at once.
        self.markers_pub = self.create_publisher(MarkerArray, "~/markers", latched)
        self.path_pub = self.create_publisher(Path, "~/path", latched)
        self.goal_pose_pub = self.create_publisher(PoseStamped, g("goal_pose_topic"), 10)
        self.nav = ActionClient(
            self, NavigateToPose, g("nav_action"), callback_group=self.reentrant
        )
        self.server = ActionServer(
            self,
            SearchObject,
            "~/search_object",
            execute_callback=self._execute,
            goal_callback=self._on_goal,
            cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=self.reentrant,
        )
        self.get_logger().info(
            f"ready: {self.planner.kind} planner, scene {self.planner.scene_name!r}, "
            f"strategies {strategies}"
        )

    # ----- inputs ---------------------------------------------------------------------------

    def _on_map(self, msg: OccupancyGrid) -> None:
        info = msg.info
        q = info.origin.orientation
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        grid = Grid(
            info.resolution,
            info.width,
            info.height,
            (info.origin.position.x, info.origin.position.y),
            msg.data,
            msg.header.frame_id,
            yaw,
        )
        try:
            places = [
                (f"{p.id} access point", p.access[0], p.access[1]) for p in self.planner.places()
            ]
            sx, sy = self.planner.start_pose()
            places.append(("start", sx, sy))
        except PlannerError as e:
            places = []
            self.get_logger().warning(f"map not checked against the scene's places: {e}")
        problems = check_map(grid, places, self.frame, self.reference_map)
        self.map = grid
        self.map_problems = problems
        if problems:
            self.get_logger().error(
                f"refusing the map on {self.get_parameter('map_topic').value} "
                f"({info.width}×{info.height}): it does not match scene "
                f"{self.planner.scene_name!r}: " + "; ".join(problems)
            )
        else:
            self.get_logger().info(
                f"map {info.width}×{info.height} at {info.resolution:.3g} m matches scene "
                f"{self.planner.scene_name!r}"
            )
        self.map_event.set()

    def _on_detection(self, msg: Detection) -> None:
        with self.detection_lock:
            self.detections.append((time.monotonic(), msg))
        self.detection_event.set()

    def _on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        q = msg.pose.pose.orientation
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        with self.pose_lock:
            self.robot_pose = (msg.pose.pose.position.x, msg.pose.pose.position.y)
            self.robot_yaw_deg = math.degrees(yaw)

    # ----- the action -------------------------------------------------------------------------

    def _on_goal(self, goal) -> GoalResponse:
        if self.busy.locked():
            what = goal.target_type or "+".join(goal.target_types)
            self.get_logger().warning(
                f"rejecting a search for {what!r}: a search is running (cancel it first)"
            )
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _execute(self, handle) -> SearchObject.Result:
        if not self.busy.acquire(blocking=False):
            return self._end(handle, None, Status.REFUSED, "another search is running")
        try:
            return self._search(handle)
        except Exception as e:  # a bug must end the goal, not leave its client waiting
            self.get_logger().error(f"search failed: {e!r}")
            return self._end(handle, None, Status.PLANNER_ERROR, f"internal error: {e!r}")
        finally:
            self.busy.release()

    def _search(self, handle) -> SearchObject.Result:
        goal = handle.request
        log = self.get_logger()
        # Before waiting for the map: a misspelt target or a bad task is refused at once, not
        # after a search of every container.
        try:
            scene = goal.scene or self.planner.scene_name
            known = self.planner.object_types(goal.scene)
            ids = [p.id for p in self.planner.places(goal.scene)]
            rooms = self.planner.rooms(goal.scene)
            task = task_from_goal(goal, known, ids, rooms, scene, self.frame)
        except PlannerError as e:
            return self._end(handle, None, Status.REFUSED, str(e))
        if self.get_parameter("require_map").value:
            try:
                self._wait(handle, self.map_event, self.get_parameter("map_wait_s").value)
            except StepFailed as e:
                return self._end(handle, None, e.status, "canceled while waiting for the map")
            if self.map_problems:
                why = "; ".join(self.map_problems)
                return self._end(handle, None, Status.REFUSED, f"map refused: {why}")
        started = time.perf_counter()
        pose = None
        if self.get_parameter("plan_from_robot_pose").value:
            with self.pose_lock:
                if self.robot_pose is not None:
                    pose = (*self.robot_pose, self.robot_yaw_deg)
        try:
            trial = self.planner.start(task, goal.scene, goal.deployment_id, pose)
        except PlannerError as e:
            message = str(e)
            if e.field == "destination" and task.destination is not None:
                message = f"{task.destination.field}: {message}"
            return self._end(handle, None, Status.REFUSED, message)
        where = "the scene's start"
        if pose is not None:
            try:
                away = math.dist(pose[:2], self.planner.start_pose()) > AT_START_M
            except PlannerError:
                away = True
            if away:
                where = f"({pose[0]:.2f}, {pose[1]:.2f})"
        log.info(f"searching for {task.describe()} with {trial.strategy} from {where}")
        timing = GoalTiming(task.label)
        self.timings.append(timing)
        places = {p.id: p for p in self.planner.places(goal.scene)}
        try:
            while True:
                t0 = time.perf_counter()
                step = trial.next()
                if step is None:
                    break
                timing.steps.append(StepTiming(step.id))
                st = timing.steps[-1]
                fb = self._feedback(trial)
                fb.next_container = step.id
                fb.next_container_type = step.type
                fb.next_room = step.room
                fb.next_pose = self._pose_for(step)
                self._publish_belief(trial, places, step, fb.next_pose)
                handle.publish_feedback(fb)
                st.plan_s += time.perf_counter() - t0

                t1 = time.perf_counter()
                with self.detection_lock:
                    # Detections from the drive there that name this container count; the
                    # rest is stale.
                    self.detections.clear()
                    self.detection_event.clear()
                self._navigate(handle, step, fb.next_pose)
                st.nav_s = time.perf_counter() - t1
                t2 = time.perf_counter()
                objects = self._detect(handle, step)
                st.detect_s = time.perf_counter() - t2

                t3 = time.perf_counter()
                before = set(trial.found_in)
                trial.record(step.id, objects)
                log.info(
                    f"searched {step.id} ({step.type}, {step.room}): "
                    f"{self._seen(task, trial, before, objects)}; saw {objects or 'nothing'}"
                )
                st.plan_s += time.perf_counter() - t3
                st.total_s = time.perf_counter() - t0
                if trial.goal_holds:
                    break
        except StepFailed as e:
            self._abandon(trial)
            self._publish_belief(trial, places)
            timing.total_s = time.perf_counter() - started
            return self._end(handle, trial, e.status, str(e))
        except PlannerError as e:
            self._abandon(trial)
            self._publish_belief(trial, places)
            timing.total_s = time.perf_counter() - started
            return self._end(handle, trial, Status.PLANNER_ERROR, str(e))
        try:
            replays = trial.finish()
        except Exception as e:  # selection failed to learn; the search itself is complete
            log.error(f"selection could not learn from this trial: {e}")
            replays = None
        held = trial.goal_holds
        found_at = trial.found_at if held else None
        status = Status.FOUND if held else Status.EXHAUSTED
        failed = None
        if task.destination is not None and trial.destination() is not None:
            try:
                self._deliver(handle, task, trial, places)
            except StepFailed as e:
                failed = e
        what = self._outcome(task, trial, failed is None)
        if replays:
            what += "; replays " + ", ".join(f"{k} {v:.2f} m" for k, v in replays.items())
        self._publish_belief(trial, places)
        timing.total_s = time.perf_counter() - started
        if failed is None:
            delivered = task.destination is not None
            return self._end(handle, trial, status, what, found_at, delivered)
        there = task.destination.label()
        if failed.status == Status.CANCELED:
            message = f"canceled on the way to {there}, the search done: {what}"
            return self._end(handle, trial, Status.CANCELED, message, found_at)
        if held:
            message = f"{what}; the search is done, but the robot did not reach {there}: {failed}"
            return self._end(handle, trial, Status.DELIVERY_FAILED, message, found_at)
        return self._end(
            handle, trial, Status.EXHAUSTED, f"{what}; the robot did not reach {there}: {failed}"
        )

    def _feedback(self, trial) -> SearchObject.Feedback:
        fb = SearchObject.Feedback()
        fb.travelled_m = float(trial.cost)
        fb.searched = len(trial.searched)
        found_in = trial.found_in
        fb.found_targets = list(found_in)
        fb.found_containers = list(found_in.values())
        return fb

    @staticmethod
    def _seen(task: Task, trial, before, objects) -> str:
        """A step's news for the log: which targets it found (in a team, what this robot saw,
        whatever its teammates found meanwhile)."""
        if task.single:
            target = task.targets[0]
            return f"found {target}" if target in objects else f"no {target}"
        new = [t for t in trial.found_in if t not in before]
        return "found " + ", ".join(new) if new else "no target"

    @staticmethod
    def _outcome(task: Task, trial, delivered: bool) -> str:
        """A sentence: what the search found, where, and what it cost (with a destination, the
        way there included, whether or not the robot got there)."""
        n, cost, strategy = len(trial.searched), trial.cost, trial.strategy
        found_in = trial.found_in
        if task.single:
            if trial.goal_holds:
                return (
                    f"found {task.targets[0]} in {trial.found_at} after {n} containers, "
                    f"{cost:.2f} m ({strategy})"
                )
            return f"{task.targets[0]} not found in any of the {n} containers"
        where = listed([f"{t} in {c}" for t, c in found_in.items()], "and")
        dest = task.destination
        if trial.goal_holds:
            said = f"found {where} after {n} container{'s' if n != 1 else ''}"
        else:
            missing = [t for t in task.targets if t not in found_in]
            said = f"{listed(missing, 'or' if task.goal == 'any' else 'and')} not found in any "
            said += f"of the {n} containers"
            if found_in:
                said += f" (found {where})"
        if dest is None:
            return f"{said}, {cost:.2f} m ({strategy})"
        if delivered:
            what = ("brought " + ("them" if len(found_in) > 1 else "it")) if found_in else "went"
            return (
                f"{said}, and {what} to {dest.label()}: {cost:.2f} m ({strategy}; "
                f"{trial.delivery_m:.2f} m of it the way there)"
            )
        return (
            f"{said}: {cost:.2f} m ({strategy}; {trial.delivery_m:.2f} m of it the way to "
            f"{dest.label()})"
        )

    def _deliver(self, handle, task: Task, trial, places) -> None:
        """Drives to the task's destination, the search done: a NavigateToPose goal there (or
        the /goal_pose fallback). Raises StepFailed when the robot does not get there."""
        x, y = trial.destination()
        way = trial.destination_path()
        dest = task.destination
        yaw = dest.yaw
        if dest.kind == "container" and dest.name in places:
            c = places[dest.name]
            yaw = math.atan2(c.position[1] - c.access[1], c.position[0] - c.access[0])
        elif yaw is None:
            # Heading along the way's last stretch (that of the robot as it arrives).
            far = [p for p in way if math.dist(p, (x, y)) > 1e-6]
            yaw = math.atan2(y - far[-1][1], x - far[-1][0]) if far else 0.0
        place = Place(dest.label(), "destination", "", (x, y), (x, y))
        pose = PoseStamped()
        pose.header.frame_id = self.frame
        pose.header.stamp = self.get_clock().now().to_msg()
        pose.pose.position.x, pose.pose.position.y = x, y
        o = pose.pose.orientation
        o.x, o.y, o.z, o.w = yaw_to_quaternion(yaw)
        fb = self._feedback(trial)
        fb.travelled_m = float(trial.cost - trial.delivery_m)
        fb.delivering = True
        fb.next_container = dest.name if dest.kind == "container" else ""
        fb.next_room = dest.name if dest.kind == "room" else ""
        fb.next_pose = pose
        self._publish_belief(trial, places, None, pose, way)
        handle.publish_feedback(fb)
        self.get_logger().info(
            f"bringing {', '.join(trial.found_in) or 'nothing'} to {dest.label()} at "
            f"({x:.2f}, {y:.2f}), {trial.delivery_m:.2f} m"
        )
        self._navigate(handle, place, pose)

    def _abandon(self, trial) -> None:
        """Gives the trial up (on the server too, with the serve backend)."""
        trial.abandon()
        why = getattr(trial, "abandon_error", None)
        if why:
            self.get_logger().warning(f"the server keeps the trial open: {why}")

    def _end(
        self, handle, trial, status, message, container=None, delivered=False
    ) -> SearchObject.Result:
        r = SearchObject.Result()
        r.status = status
        r.container = container or ""
        r.message = message
        r.delivered = delivered
        if trial is not None:
            r.found = bool(trial.goal_holds)
            r.cost_m = float(trial.cost)
            r.searched_containers = list(trial.searched)
            r.strategy = trial.strategy
            found_in = trial.found_in
            r.found_targets = list(found_in)
            r.found_containers = list(found_in.values())
            r.delivery_m = float(trial.delivery_m)
        log = self.get_logger()
        if status == Status.FOUND:
            log.info(message)
            handle.succeed()
        elif status == Status.CANCELED:
            log.info(message)
            handle.canceled()
        else:
            log.error(message)
            handle.abort()
        return r

    # ----- waits ------------------------------------------------------------------------------

    def _wait(self, handle, event: threading.Event, timeout_s: float) -> bool:
        """Waits for `event` up to `timeout_s`; raises StepFailed(CANCELED) on a cancel."""
        deadline = time.monotonic() + timeout_s
        while not event.wait(POLL_S):
            if handle.is_cancel_requested:
                raise StepFailed(Status.CANCELED, "canceled")
            if time.monotonic() >= deadline or not rclpy.ok(context=self.context):
                return False
        return True

    def _pose_for(self, place: Place) -> PoseStamped:
        ps = PoseStamped()
        ps.header.frame_id = self.frame
        ps.header.stamp = self.get_clock().now().to_msg()
        ps.pose.position.x, ps.pose.position.y = place.access
        # Face the container from its access point.
        yaw = math.atan2(place.position[1] - place.access[1], place.position[0] - place.access[0])
        q = yaw_to_quaternion(yaw)
        o = ps.pose.orientation
        o.x, o.y, o.z, o.w = q
        return ps

    def _navigate(self, handle, place: Place, pose: PoseStamped) -> None:
        timeout = float(self.get_parameter("nav_timeout_s").value)
        if self.nav.server_is_ready() or self.nav.wait_for_server(
            timeout_sec=float(self.get_parameter("nav_server_wait_s").value)
        ):
            self._navigate_nav2(handle, place, pose, timeout)
        else:
            self._navigate_goal_pose(handle, place, pose, timeout)

    def _navigate_nav2(self, handle, place, pose, timeout) -> None:
        goal = NavigateToPose.Goal()
        goal.pose = pose
        goal.behavior_tree = self.get_parameter("behavior_tree").value
        sent = threading.Event()
        future = self.nav.send_goal_async(goal)
        future.add_done_callback(lambda _: sent.set())
        try:
            ok = self._wait(handle, sent, min(timeout, 10.0))
        except StepFailed:
            future.add_done_callback(lambda f: f.result() and f.result().cancel_goal_async())
            raise
        if not ok:
            raise StepFailed(
                Status.NAVIGATION_FAILED, f"Nav2 did not answer the goal for {place.id} within 10 s"
            )
        nav_handle = future.result()
        if nav_handle is None or not nav_handle.accepted:
            raise StepFailed(Status.NAVIGATION_FAILED, f"Nav2 rejected the goal for {place.id}")
        done = threading.Event()
        result_future = nav_handle.get_result_async()
        result_future.add_done_callback(lambda _: done.set())
        try:
            ok = self._wait(handle, done, timeout)
        except StepFailed:
            self._cancel_nav(nav_handle)
            raise
        if not ok:
            self._cancel_nav(nav_handle)
            raise StepFailed(
                Status.NAVIGATION_FAILED,
                f"navigation to {place.id} timed out after {timeout:g} s (goal canceled)",
            )
        res = result_future.result()
        if res.status != GoalStatus.STATUS_SUCCEEDED:
            what = {
                GoalStatus.STATUS_ABORTED: "aborted",
                GoalStatus.STATUS_CANCELED: "canceled",
            }.get(res.status, f"ended with status {res.status}")
            detail = ""
            if res.result is not None and (res.result.error_code or res.result.error_msg):
                detail = f" (error {res.result.error_code}: {res.result.error_msg})"
            raise StepFailed(
                Status.NAVIGATION_FAILED, f"Nav2 {what} the goal to {place.id}{detail}"
            )

    def _cancel_nav(self, nav_handle) -> None:
        done = threading.Event()
        nav_handle.cancel_goal_async().add_done_callback(lambda _: done.set())
        if not done.wait(2.0):
            self.get_logger().warning("Nav2 did not confirm the cancel within 2 s")

    def _navigate_goal_pose(self, handle, place, pose, timeout) -> None:
        """No NavigateToPose server: publish the goal (as RViz's 2D Goal Pose does) and wait
        for the robot's pose to come within the tolerance."""
        tol = float(self.get_parameter("arrival_tolerance_m").value)
        self.goal_pose_pub.publish(pose)
        deadline = time.monotonic() + timeout
        while True:
            with self.pose_lock:
                at = self.robot_pose
            if at is not None and math.dist(at, place.access) <= tol:
                return
            if handle.is_cancel_requested:
                raise StepFailed(Status.CANCELED, "canceled")
            if time.monotonic() >= deadline or not rclpy.ok(context=self.context):
                where = (
                    "no pose received" if at is None else f"last pose ({at[0]:.2f}, {at[1]:.2f})"
                )
                raise StepFailed(
                    Status.NAVIGATION_FAILED,
                    f"no NavigateToPose server, and the robot did not reach {place.id} via "
                    f"{self.get_parameter('goal_pose_topic').value} within {timeout:g} s "
                    f"({where} on "
                    f"{self.get_parameter('robot_pose_topic').value})",
                )
            time.sleep(POLL_S)

    def _detect(self, handle, place: Place) -> List[str]:
        """What the detector reports at `place`: the first detection naming this container
        (since the robot set off for it) or naming none (since it arrived), then any more within
        `detection_window_s`."""
        timeout = float(self.get_parameter("detection_timeout_s").value)
        window = float(self.get_parameter("detection_window_s").value)
        arrived = time.monotonic()
        seen: List[str] = []
        first = None
        deadline = time.monotonic() + timeout
        while True:
            now = time.monotonic()
            end = deadline if first is None else first + window
            if now >= end:
                break
            self._wait(handle, self.detection_event, min(end - now, 0.5))
            with self.detection_lock:
                batch, self.detections = self.detections, []
                self.detection_event.clear()
            for received, d in batch:
                if d.container != place.id and (d.container or received < arrived):
                    continue
                if first is None:
                    first = time.monotonic()
                for t in d.object_types:
                    if t not in seen:
                        seen.append(t)
            if first is not None and window <= 0:
                break
        if first is None:
            raise StepFailed(
                Status.DETECTOR_TIMEOUT,
                f"no detection at {place.id} within {timeout:g} s on "
                f"{self.get_parameter('detections_topic').value}",
            )
        return seen

    def _publish_belief(self, trial, places, step=None, goal=None, way=None) -> None:
        """The belief, its markers and the route to `step` (or, while the robot brings what it
        found to the destination, `way` to `goal`; none once the search has ended)."""
        log = self.get_logger()
        try:
            now = trial.belief()
        except Exception as e:  # a failing likelihood source must not stop the search itself
            log.warning(f"no probabilities for the belief: {e}")
            now = None
        task = trial.task
        ids = list(places)
        searched = set(trial.searched)
        found_in = trial.found_in
        if task.single:
            # One target: the picture it always was.
            found = trial.found_at if trial.goal_holds else None
            holding = found
        else:
            found = {}
            for t, c in found_in.items():
                found.setdefault(c, []).append(t)
            holding = set(found)
        b = Belief()
        b.header.frame_id = self.frame
        b.header.stamp = self.get_clock().now().to_msg()
        b.target_type = task.label
        b.strategy = trial.strategy
        b.containers = ids
        b.searched = [i in searched for i in ids]
        b.probability = probabilities(ids, now, trial.searched, holding)
        b.wanted_types = [] if trial.goal_holds else [t for t in task.targets if t not in found_in]
        self.belief_pub.publish(b)
        destination = None
        if task.destination is not None:
            try:
                at = trial.destination()
            except PlannerError:
                at = None
            if at is not None:
                destination = (at[0], at[1], task.destination.label())
        self.markers_pub.publish(
            container_markers(
                self.frame,
                list(places.values()),
                b.probability,
                b.searched,
                found,
                step.id if step is not None else None,
                destination,
            )
        )
        points = way or []
        if step is not None:
            try:
                points = trial.path_to(step)
            except PlannerError as e:  # the goal pose alone still shows where the robot goes
                log.warning(f"no path to {step.id}: {e}")
        self.path_pub.publish(route(self.frame, points, goal))


def main(argv=None) -> int:
    rclpy.init(args=argv if argv is not None else sys.argv)
    try:
        node = FerretNode()
    except PlannerError:
        rclpy.try_shutdown()
        return 1
    executor = MultiThreadedExecutor(num_threads=6)
    executor.add_node(node)
    try:
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
