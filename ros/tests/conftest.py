"""The ferret node under test runs as its own process (`python -m ferret_ros.node`); the
simulated robot (Nav2, detector, map server) and the action client run in this process, each
node on its own executor thread. Everything talks over Fast DDS, on a domain of its own
(ROS_DOMAIN_ID from scripts/ros-tests.sh, or one picked here) and only on this host."""

import json
import os
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import pytest

# Before rclpy starts: nothing leaves this host, nothing from other runs gets in.
os.environ.setdefault("ROS_DOMAIN_ID", str(1 + os.getpid() % 100))
os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
os.environ.setdefault("RMW_IMPLEMENTATION", "rmw_fastrtps_cpp")

import rclpy  # noqa: E402
from nav_msgs.msg import Path as PathMsg  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

import ferret  # noqa: E402
from ferret_interfaces.action import SearchObject  # noqa: E402
from ferret_interfaces.msg import Belief  # noqa: E402
from ferret_ros.maps import read_scene_map  # noqa: E402
from ferret_ros.sim import MapServer, SimDetector, SimNav2  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]
SCENE = ROOT / "examples" / "apartment" / "scene.yaml"
ROS_DIR = ROOT / "ros"
STRATEGIES = ["model/prior", "model/uniform", "optimistic+greedy"]
# Generous bounds: the machine may be busy; a hang still fails the test in bounded time.
START_TIMEOUT_S = 30.0
GOAL_TIMEOUT_S = 60.0
# The node's outputs are latched with depth 1; the client keeps every one it receives, so that a
# slow callback here never drops a step's belief or picture.
KEEP_ALL = QoSProfile(
    depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE
)


def ferret_bin():
    path = os.environ.get("FERRET_BIN")
    if not path or not os.access(path, os.X_OK):
        pytest.fail(
            "FERRET_BIN must name the ferret binary to compare with (scripts/ros-tests.sh sets it)"
        )
    return path


@pytest.fixture(scope="session")
def house():
    return ferret.load_houses(str(SCENE))[0]


@pytest.fixture(scope="session")
def ros():
    rclpy.init()
    yield
    rclpy.try_shutdown()


class Spinner:
    """Nodes spun by one executor on a daemon thread until closed."""

    def __init__(self, *nodes, threads=4):
        self.nodes = nodes
        self.executor = MultiThreadedExecutor(num_threads=threads)
        for n in nodes:
            self.executor.add_node(n)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def close(self):
        self.executor.shutdown(timeout_sec=5)
        self.thread.join(5)
        for n in self.nodes:
            n.destroy_node()


@pytest.fixture(scope="session")
def robot(ros, house):
    """The simulated robot: Nav2 at 200 m/s (the tests wait for no real driving), the
    detector, and the scene's own map on /map."""
    nav = SimNav2(house, speed=200.0)
    detector = SimDetector(house)
    maps = MapServer(read_scene_map(str(SCENE)))
    spin = Spinner(nav, detector, maps)
    yield nav, detector, maps
    spin.close()


class Client:
    """The action client a user's code would be, plus listeners of the belief, the markers and
    the path."""

    def __init__(self, node_name, namespace=""):
        self.node = Node(
            "test_client_" + (namespace + "_" + node_name).strip("_").replace("-", "_")
        )
        at = f"/{namespace}/{node_name}" if namespace else f"/{node_name}"
        self.action = ActionClient(self.node, SearchObject, f"{at}/search_object")
        self.beliefs = []
        self.markers = []
        self.paths = []
        self.node.create_subscription(
            Belief, f"{at}/belief", lambda m: self.beliefs.append(m), KEEP_ALL
        )
        self.node.create_subscription(
            MarkerArray, f"{at}/markers", lambda m: self.markers.append(m), KEEP_ALL
        )
        self.node.create_subscription(
            PathMsg, f"{at}/path", lambda m: self.paths.append(m), KEEP_ALL
        )
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(self.node)
        self.thread = threading.Thread(target=self.executor.spin, daemon=True)
        self.thread.start()

    def try_goal(self, target, timeout=10.0):
        """Whether the node accepts a goal (the goal is canceled if it was)."""
        sent = self.action.send_goal_async(SearchObject.Goal(target_type=target))
        deadline = time.monotonic() + timeout
        while not sent.done():
            assert time.monotonic() < deadline, f"goal for {target} not answered in {timeout} s"
            time.sleep(0.005)
        if sent.result().accepted:
            sent.result().cancel_goal_async()
        return sent.result().accepted

    def send(self, target, timeout=GOAL_TIMEOUT_S, cancel_after_feedback=False, while_running=None):
        """Sends a goal (a target's name, or a SearchObject.Goal) and waits (bounded) for its
        result: (status, result, feedback list)."""
        goal = (
            target
            if isinstance(target, SearchObject.Goal)
            else SearchObject.Goal(target_type=target)
        )
        fbs = []
        first_fb = threading.Event()

        def on_fb(msg):
            fbs.append(msg.feedback)
            first_fb.set()

        sent = self.action.send_goal_async(goal, feedback_callback=on_fb)
        deadline = time.monotonic() + timeout
        while not sent.done():
            assert time.monotonic() < deadline, f"goal for {target} not answered in {timeout} s"
            time.sleep(0.005)
        handle = sent.result()
        assert handle.accepted, f"goal for {target} rejected"
        if while_running is not None or cancel_after_feedback:
            assert first_fb.wait(timeout), "no feedback from the running search"
        if while_running is not None:
            while_running()
        if cancel_after_feedback:
            handle.cancel_goal_async()
        res = handle.get_result_async()
        while not res.done():
            assert time.monotonic() < deadline, f"no result for {target} within {timeout} s"
            time.sleep(0.005)
        return res.result().status, res.result().result, fbs

    def close(self):
        self.executor.shutdown(timeout_sec=5)
        self.thread.join(5)
        self.node.destroy_node()


class FerretProcess:
    """`python -m ferret_ros.node` with parameters, its log in a file shown on failure."""

    def __init__(self, tmp_path, name, params, namespace=""):
        self.name = f"{namespace}-{name}" if namespace else name
        args = [sys.executable, "-m", "ferret_ros.node", "--ros-args", "-r", f"__node:={name}"]
        if namespace:
            args += ["-r", f"__ns:=/{namespace}"]
        for k, v in params.items():
            if isinstance(v, list):
                v = "[" + ",".join(f"'{x}'" for x in v) + "]"
            elif isinstance(v, bool):
                v = "true" if v else "false"
            args += ["-p", f"{k}:={v}"]
        self.log_path = tmp_path / f"{self.name}.log"
        self.log = open(self.log_path, "w")
        env = dict(os.environ, PYTHONPATH=str(ROS_DIR), PYTHONUNBUFFERED="1")
        self.proc = subprocess.Popen(args, stdout=self.log, stderr=subprocess.STDOUT, env=env)

    def text(self):
        if not self.log.closed:
            self.log.flush()
        return self.log_path.read_text()

    def stop(self):
        if self.proc.poll() is None:
            self.proc.send_signal(2)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5)
        self.log.close()


@pytest.fixture
def start_node(ros, robot, tmp_path):
    """Starts a ferret node with parameters; returns (process, client) once its action server
    is up. Stops both after the test, printing the node's log when the test failed."""
    started = []

    def start(name, namespace="", **params):
        params.setdefault("scene", str(SCENE))
        p = FerretProcess(tmp_path, name, params, namespace)
        c = Client(name, namespace)
        started.append((p, c))
        if not c.action.wait_for_server(timeout_sec=START_TIMEOUT_S):
            raise AssertionError(
                f"the node's action server did not come up in {START_TIMEOUT_S} s:\n{p.text()}"
            )
        # wait_for_server sees the server's endpoints, not the server seeing ours: a goal sent
        # at once can be executed while its acceptance is lost ("failed to send response
        # (timeout)" in the node's log) when the server has not matched the client's response
        # reader yet. A moment for discovery to finish both ways.
        time.sleep(1.0)
        return p, c

    yield start
    for p, c in started:
        c.close()
        p.stop()
        sys.stderr.write(f"--- {p.name} log ---\n{p.text()}\n")


@pytest.fixture
def ferret_serve(tmp_path):
    """`ferret serve` on a free loopback port, the apartment as its scene."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    log = open(tmp_path / "serve.log", "w")
    proc = subprocess.Popen(
        [
            ferret_bin(),
            "serve",
            "--scene",
            str(SCENE),
            "--strategies",
            ",".join(STRATEGIES),
            "--listen",
            f"127.0.0.1:{port}",
            "--db",
            str(tmp_path / "serve.sqlite"),
        ],
        stdout=log,
        stderr=subprocess.STDOUT,
        cwd=tmp_path,
    )
    url = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 30
    while True:
        try:
            with urllib.request.urlopen(url + "/health", timeout=1) as r:
                if json.loads(r.read()).get("status") == "ok":
                    break
        except OSError:
            pass
        assert proc.poll() is None and time.monotonic() < deadline, (
            tmp_path / "serve.log"
        ).read_text()
        time.sleep(0.1)
    yield url
    proc.terminate()
    proc.wait(10)
    log.close()
