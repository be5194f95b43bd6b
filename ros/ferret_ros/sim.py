"""A simulated robot for the node: Nav2's NavigateToPose server, a detector and a map server.

They stand in for the robot in the tests and for a first run without one (docs/ros2.md):

- `SimNav2` serves `navigate_to_pose`: it drives along ferret's own grid path from where the
  robot is to the goal's container access point, or to any other point of the floor (a household
  task's destination), at `speed` m/s, reporting feedback, and publishes the robot's pose on
  /amcl_pose. It can be told to abort goals or never finish them. Like Nav2, it also drives to
  poses published on /goal_pose (without feedback).
- `SimDetector` reports, on `detections`, what the scene's ground truth holds in the container
  whose access point the robot stands at; it can be muted.
- `MapServer` latches an occupancy grid on /map (transient local), as Nav2's map_server does.

    python3 -m ferret_ros.sim --scene examples/apartment/scene.yaml
"""

import argparse
import math
import sys
import threading
import time
from typing import List, Optional, Tuple

import rclpy
from builtin_interfaces.msg import Duration
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped
from nav2_msgs.action import NavigateToPose
from nav_msgs.msg import OccupancyGrid
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

import ferret
from ferret_interfaces.msg import Detection

from .maps import Grid

LATCHED = QoSProfile(
    depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
)
# How close (metres) a goal or the robot must be to a container's access point to be "at" it.
AT_M = 0.01


def container_at(house, x: float, y: float):
    for c in house.containers:
        a = c.access if c.access is not None else c.position
        if math.dist(a, (x, y)) <= AT_M:
            return c
    return None


class SimNav2(Node):
    """NavigateToPose over ferret's grid paths. `mode`: "ok", "abort" (every goal from the
    `fail_from`-th on is aborted after its first feedback), "hang" (such goals never end until
    canceled), "reject" (they are rejected)."""

    def __init__(self, house, speed: float = 50.0, name: str = "sim_nav2", namespace: str = ""):
        # In a namespace (one robot of several), every name below is that robot's own.
        super().__init__(name, namespace=namespace)
        self.house = house
        self.speed = speed
        self.mode = "ok"
        self.fail_from = 1
        self.goals = 0
        self.drive_s: List[float] = []  # simulated driving time of each goal, seconds
        self.visited: List[str] = []
        # Every goal received (NavigateToPose and /goal_pose), as (x, y).
        self.goal_points: List[Tuple[float, float]] = []
        self.lock = threading.Lock()
        self.pose_pub = self.create_publisher(PoseWithCovarianceStamped, "amcl_pose", LATCHED)
        self.reset()
        self.create_subscription(PoseStamped, "goal_pose", self._on_goal_pose, 10)
        self.server = ActionServer(
            self,
            NavigateToPose,
            "navigate_to_pose",
            execute_callback=self._execute,
            goal_callback=self._on_goal,
            cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=ReentrantCallbackGroup(),
        )

    def reset(self) -> None:
        """Back at the scene's start pose, as each trial of `ferret deploy` starts."""
        with self.lock:
            # The container whose access point the robot is at, or the point of the floor it
            # stands on (a tuple) away from every container; None: the start.
            self.at = None
            self.position = (self.house.start[0], self.house.start[1])
        self._publish_pose(*self.position, self.house.start[2] if len(self.house.start) > 2 else 0)

    def _search_from_here(self, destination=None):
        """A ferret search standing where the robot stands (the start or a container), with a
        destination to route to. Its target (one the scene holds, as a search needs) is never
        looked for."""
        with self.lock:
            at = self.at
        held = self.house.target_types()
        s = ferret.Search(
            self.house, held[0] if held else "_", "optimistic+greedy", destination=destination
        )
        if isinstance(at, str):
            s.record(at, False, [])
        return s

    def _route(self, c):
        """ferret's grid path and its length from where the robot is to `c`'s access point."""
        with self.lock:
            at = self.at
        if at == c.id:
            return [tuple(c.access)], 0.0
        if isinstance(at, tuple):
            # From a point of the floor: the way from the container to it, backwards.
            held = self.house.target_types()
            s = ferret.Search(
                self.house, held[0] if held else "_", "optimistic+greedy", destination=at
            )
            s.record(c, False, [])
            path = list(reversed(s.path_to_destination() or []))
            return path, _length(path)
        s = self._search_from_here()
        return s.path_to(c), s.distance_to(c)

    def _route_to_point(self, x: float, y: float):
        """ferret's grid path and its length from where the robot is to the reachable point
        nearest (x, y) (within 0.5 m, as ferret takes a destination); a point it cannot reach
        raises ferret.FerretError. From another such point, a straight line."""
        with self.lock:
            at, here = self.at, self.position
        if isinstance(at, tuple):
            return [here, (x, y)], math.dist(here, (x, y))
        path = self._search_from_here((x, y)).path_to_destination() or []
        return path, _length(path)

    def _failing(self) -> bool:
        return self.mode != "ok" and self.goals >= self.fail_from

    def _on_goal(self, goal) -> GoalResponse:
        self.goals += 1
        if self.mode == "reject" and self._failing():
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def _publish_pose(self, x, y, yaw_deg=0.0) -> None:
        m = PoseWithCovarianceStamped()
        m.header.frame_id = "map"
        m.header.stamp = self.get_clock().now().to_msg()
        m.pose.pose.position.x, m.pose.pose.position.y = x, y
        m.pose.pose.orientation.z = math.sin(math.radians(yaw_deg) / 2)
        m.pose.pose.orientation.w = math.cos(math.radians(yaw_deg) / 2)
        self.pose_pub.publish(m)

    def _on_goal_pose(self, msg: PoseStamped) -> None:
        self.goals += 1
        x, y = msg.pose.position.x, msg.pose.position.y
        self.goal_points.append((x, y))
        if self._failing():
            return  # a goal it will not reach: the robot stays where it is
        c = container_at(self.house, x, y)
        try:
            _, length = self._route(c) if c is not None else self._route_to_point(x, y)
        except ferret.FerretError:
            return  # a goal it cannot reach
        if self.speed > 0:
            time.sleep(length / self.speed)
        drive = length / self.speed if self.speed > 0 else 0.0
        self._arrive(c if c is not None else (x, y), drive, _yaw_deg(msg.pose))

    def _arrive(self, c, drive_s: float, yaw_deg: float = 0.0) -> None:
        """At container `c`'s access point, facing it, or at the point `c` (x, y) facing
        `yaw_deg`."""
        self.drive_s.append(drive_s)
        if isinstance(c, tuple):
            with self.lock:
                self.at = None if math.dist(c, self.house.start[:2]) <= AT_M else c
                self.position = c
            self._publish_pose(c[0], c[1], yaw_deg)
            return
        with self.lock:
            self.at = c.id
            self.position = tuple(c.access)
        self.visited.append(c.id)
        yaw = math.degrees(math.atan2(c.position[1] - c.access[1], c.position[0] - c.access[0]))
        self._publish_pose(c.access[0], c.access[1], yaw)

    def _execute(self, handle):
        goal = handle.request.pose.pose
        result = NavigateToPose.Result()
        x, y = goal.position.x, goal.position.y
        self.goal_points.append((x, y))
        c = container_at(self.house, x, y)
        try:
            path, length = self._route(c) if c is not None else self._route_to_point(x, y)
        except ferret.FerretError as e:
            result.error_code = NavigateToPose.Result.UNKNOWN
            result.error_msg = f"no way to ({x:.2f}, {y:.2f}): {e}"
            handle.abort()
            return result
        failing = self._failing()
        drive = length / self.speed if self.speed > 0 else 0.0
        started = time.monotonic()
        fb = NavigateToPose.Feedback()
        fb.current_pose.header.frame_id = "map"
        # Feedback at about every metre of the path (and at least once).
        every = max(1, int(len(path) / max(1.0, length)))
        for k in range(0, max(1, len(path)), every):
            if handle.is_cancel_requested:
                handle.canceled()
                return result
            px, py = path[k] if path else self.position
            fb.current_pose.pose.position.x, fb.current_pose.pose.position.y = px, py
            frac = k / max(1, len(path) - 1)
            fb.distance_remaining = float(length * (1 - frac))
            elapsed = time.monotonic() - started
            fb.navigation_time = Duration(sec=int(elapsed), nanosec=int((elapsed % 1) * 1e9))
            handle.publish_feedback(fb)
            if failing and self.mode == "abort":
                result.error_code = NavigateToPose.Result.UNKNOWN
                result.error_msg = "simulated failure: no path to the goal"
                handle.abort()
                return result
            target_t = started + drive * (k + every) / max(1, len(path))
            pause = target_t - time.monotonic()
            if pause > 0:
                time.sleep(pause)
        if failing and self.mode == "hang":
            while not handle.is_cancel_requested:
                time.sleep(0.02)
            handle.canceled()
            return result
        self._arrive(c if c is not None else (x, y), time.monotonic() - started, _yaw_deg(goal))
        handle.succeed()
        return result


def _yaw_deg(pose) -> float:
    q = pose.orientation
    return math.degrees(math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z)))


def _length(path) -> float:
    return sum(math.dist(a, b) for a, b in zip(path, path[1:]))


class SimDetector(Node):
    """Reports the ground truth of the container the robot stands at (from /amcl_pose): once
    on arrival and then at `rate_hz`. `muted` makes it report nothing."""

    def __init__(
        self, house, rate_hz: float = 10.0, name: str = "sim_detector", namespace: str = ""
    ):
        super().__init__(name, namespace=namespace)
        self.house = house
        self.muted = False
        self.at = None
        self.pub = self.create_publisher(Detection, "detections", 10)
        self.create_subscription(PoseWithCovarianceStamped, "amcl_pose", self._on_pose, LATCHED)
        self.create_timer(1.0 / rate_hz, self._report)

    def _on_pose(self, msg) -> None:
        p = msg.pose.pose.position
        self.at = container_at(self.house, p.x, p.y)
        self._report()

    def _report(self) -> None:
        c = self.at
        if c is None or self.muted:
            return
        d = Detection()
        d.header.frame_id = "map"
        d.header.stamp = self.get_clock().now().to_msg()
        d.container = c.id
        d.object_types = list(self.house.contents(c))
        self.pub.publish(d)


class MapServer(Node):
    """Latches one occupancy grid on /map."""

    def __init__(self, grid: Grid, name: str = "sim_map_server", topic: str = "/map"):
        super().__init__(name)
        self.pub = self.create_publisher(OccupancyGrid, topic, LATCHED)
        self.publish(grid)

    def publish(self, grid: Grid) -> None:
        m = OccupancyGrid()
        m.header.frame_id = grid.frame_id
        m.header.stamp = self.get_clock().now().to_msg()
        m.info.resolution = float(grid.resolution)
        m.info.width, m.info.height = grid.width, grid.height
        m.info.origin.position.x, m.info.origin.position.y = grid.origin
        m.info.origin.orientation.z = math.sin(grid.origin_yaw / 2)
        m.info.origin.orientation.w = math.cos(grid.origin_yaw / 2)
        m.data = [int(v) for v in grid.data]
        self.pub.publish(m)


def main(argv: Optional[List[str]] = None) -> int:
    """Runs the three simulated parts for a scene until interrupted."""
    from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor

    from .maps import read_scene_map
    from .planners import path_problem

    args_in = rclpy.utilities.remove_ros_args(argv if argv is not None else sys.argv)[1:]
    ap = argparse.ArgumentParser(
        prog="python3 -m ferret_ros.sim", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument(
        "--scene", required=True, help="ferret scene file (YAML) with a `map: {ros: ...}`"
    )
    ap.add_argument("--speed", type=float, default=0.5, help="simulated driving speed, m/s")
    args = ap.parse_args(args_in)
    try:
        house = ferret.load_houses(args.scene)[0]
    except ferret.FerretError as e:
        print(f"scene {path_problem(args.scene, e)}", file=sys.stderr)
        return 1
    grid = read_scene_map(args.scene)
    if grid is None:
        print(f"{args.scene}: names no ROS map (map: {{ros: map.yaml}})", file=sys.stderr)
        return 1
    rclpy.init(args=argv)
    nodes = [SimNav2(house, args.speed), SimDetector(house), MapServer(grid)]
    ex = MultiThreadedExecutor(num_threads=4)
    for n in nodes:
        ex.add_node(n)
    # The line to wait for before starting the node (docs/ros2.md): everything is served.
    nodes[0].get_logger().info(
        f"ready: simulated robot in scene {house.name!r}: navigate_to_pose at {args.speed:g} m/s, "
        f"a detector on detections, a {grid.width}×{grid.height} map on /map"
    )
    try:
        ex.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        ex.shutdown()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
