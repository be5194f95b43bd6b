"""The node's own overhead per search step and per goal: planning plus messaging, with the
simulated Nav2 arriving at once (speed 0 = no driving time), so that every second measured is
the node's and DDS's, not the robot's.

    scripts/ros-tests.sh install            # prints the venv
    ROS_DOMAIN_ID=42 PYTHONPATH=ros VENV/bin/python ros/bench_overhead.py --rounds 5

The node, the simulated robot and the action client are separate nodes on separate executors in
this one process (they share its interpreter, so the figures are if anything pessimistic), and
talk over Fast DDS on this host only. Every target of the scene is searched `--rounds` times, in
one deployment over `--strategies`.
"""

import argparse
import os
import statistics
import sys
import threading
import time

os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")

import rclpy  # noqa: E402
from rclpy.action import ActionClient  # noqa: E402
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402

import ferret  # noqa: E402
from ferret_interfaces.action import SearchObject  # noqa: E402
from ferret_ros.maps import read_scene_map  # noqa: E402
from ferret_ros.node import FerretNode  # noqa: E402
from ferret_ros.sim import MapServer, SimDetector, SimNav2  # noqa: E402


def pct(xs, q):
    xs = sorted(xs)
    return xs[min(len(xs) - 1, int(round(q / 100 * (len(xs) - 1))))]


def spin(nodes, threads):
    ex = MultiThreadedExecutor(num_threads=threads) if threads > 1 else SingleThreadedExecutor()
    for n in nodes:
        ex.add_node(n)
    t = threading.Thread(target=ex.spin, daemon=True)
    t.start()
    return ex, t, nodes


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scene", default="examples/apartment/scene.yaml")
    ap.add_argument("--strategies", default="model/prior,model/uniform,optimistic+greedy")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument(
        "--from-pose",
        action="store_true",
        help="the robot stays where a search ended and the next plans from there (the scene "
        "placed at that pose, built once per pose); default: every search from the start",
    )
    args = ap.parse_args()
    rclpy.init()
    house = ferret.load_houses(args.scene)[0]
    node = FerretNode(
        "ferret_bench",
        parameter_overrides=[
            Parameter("scene", value=args.scene),
            Parameter("strategies", value=args.strategies.split(",")),
            Parameter("plan_from_robot_pose", value=args.from_pose),
        ],
    )
    nav = SimNav2(house, speed=0.0)
    sims = [nav, SimDetector(house), MapServer(read_scene_map(args.scene))]
    client = Node("bench_client")
    action = ActionClient(client, SearchObject, "/ferret_bench/search_object")
    spinning = [spin([node], 6), spin(sims, 4), spin([client], 1)]
    if not action.wait_for_server(timeout_sec=30):
        print("the node's action server did not come up", file=sys.stderr)
        return 1
    goal_s, steps = [], 0
    targets = house.target_types()
    for _ in range(args.rounds):
        for target in targets:
            if not args.from_pose:
                nav.reset()
            t = time.perf_counter()
            sent = action.send_goal_async(SearchObject.Goal(target_type=target))
            deadline = time.monotonic() + 60
            while not sent.done() and time.monotonic() < deadline:
                time.sleep(0.0005)
            res = sent.result().get_result_async()
            while not res.done() and time.monotonic() < deadline:
                time.sleep(0.0005)
            if not res.done():
                print(f"no result for {target} within 60 s", file=sys.stderr)
                return 1
            goal_s.append(time.perf_counter() - t)
            r = res.result().result
            if not r.found:
                print(f"{target}: {r.message}", file=sys.stderr)
                return 1
            steps += len(r.searched_containers)
    timed = [s for g in node.timings for s in g.steps]
    print(
        f"{len(goal_s)} goals from {'where the last ended' if args.from_pose else 'the start'}, "
        f"{steps} steps ({args.rounds} rounds of {len(targets)} targets in "
        f"{house.name}, strategies {args.strategies}); "
        f"simulated driving time {sum(nav.drive_s):.3f} s"
    )
    print(f"{'per step (node side)':<34} {'p50 ms':>8} {'p99 ms':>8} {'max ms':>8}")
    for name, xs in [
        ("total: plan + navigate + detect", [s.total_s for s in timed]),
        ("  ferret (next, record, belief)", [s.plan_s for s in timed]),
        ("  NavigateToPose round trip", [s.nav_s for s in timed]),
        ("  detection wait", [s.detect_s for s in timed]),
    ]:
        print(f"{name:<34} {pct(xs, 50) * 1e3:8.2f} {pct(xs, 99) * 1e3:8.2f} {max(xs) * 1e3:8.2f}")
    setup = [g.total_s - sum(s.total_s for s in g.steps) for g in node.timings]
    for name, xs in [
        ("per goal: trial setup (node side)", setup),
        ("per goal (client side)", goal_s),
    ]:
        print(f"{name:<34} {pct(xs, 50) * 1e3:8.2f} {pct(xs, 99) * 1e3:8.2f} {max(xs) * 1e3:8.2f}")
    median = statistics.median(goal_s)
    print(f"mean steps per goal {steps / len(goal_s):.2f}; median goal {median:.3f} s")
    # Executors stopped and their threads joined before the nodes go, so that no callback runs
    # into a destroyed node.
    for ex, thread, nodes in spinning:
        ex.shutdown(timeout_sec=5)
        thread.join(5)
        for n in nodes:
            n.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
