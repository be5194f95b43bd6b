"""Ask a running ferret node to find objects, printing its feedback and results (what
`ros2 action send_goal` would do, for a ROS 2 installed from wheels, which has no `ros2` CLI).

    python3 -m ferret_ros.find Wallet RemoteControl [--node ferret] [--timeout 600]
    python3 -m ferret_ros.find 'Mug+Wallet@start' 'Apple|Book@room:bedroom'

Each argument is one search: an object type, or a household task as `ferret deploy --find`
writes it, targets joined by + (all of them) or | (any one), then optionally where to bring
them: `@start`, `@container:<id>`, `@room:<name>` or `@<x>,<y>` (map frame). Exits 0 when every
search's goal held (and what was found was brought where asked), 1 otherwise. Ctrl-C cancels the
running search.
"""

import argparse
import sys
import threading
import time

import rclpy
from rclpy.action import ActionClient
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from ferret_interfaces.action import SearchObject

from .tasks import (
    DESTINATION_CONTAINER,
    DESTINATION_POSE,
    DESTINATION_ROOM,
    DESTINATION_START,
    GOAL_ANY,
    parse_task,
)

STATUS = {v: k for k, v in vars(SearchObject.Result).items() if k.isupper() and isinstance(v, int)}


def main(argv=None) -> int:
    argv = argv if argv is not None else sys.argv
    ap = argparse.ArgumentParser(
        prog="python3 -m ferret_ros.find", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument(
        "targets",
        nargs="+",
        help="object types, e.g. RemoteControl, or tasks, e.g. 'Mug+Wallet@start', 'Apple|Book'",
    )
    ap.add_argument("--node", default="ferret", help="the ferret node's name (default ferret)")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per search (default 600)")
    args = ap.parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
    try:
        goals = [goal_of(t) for t in args.targets]
    except ValueError as e:
        ap.error(str(e))
    rclpy.init(args=argv)
    node = Node("ferret_find")
    client = ActionClient(node, SearchObject, f"/{args.node}/search_object")
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    spinner = threading.Thread(target=ex.spin, daemon=True)
    spinner.start()
    found_all = True
    try:
        if not client.wait_for_server(timeout_sec=10):
            print(f"no ferret node serving /{args.node}/search_object", file=sys.stderr)
            return 1
        for target, goal in zip(args.targets, goals):

            def feedback(msg):
                f = msg.feedback
                p = f.next_pose.pose.position
                found = "".join(
                    f"; {t} in {c}" for t, c in zip(f.found_targets, f.found_containers)
                )
                if f.delivering:
                    where = f.next_container or f.next_room or "the destination"
                    print(
                        f"  => bringing what was found to {where} at ({p.x:.2f}, {p.y:.2f}); "
                        f"{f.searched} searched, {f.travelled_m:.2f} m so far{found}",
                        flush=True,
                    )
                    return
                print(
                    f"  -> {f.next_container} ({f.next_container_type}, {f.next_room}) at "
                    f"({p.x:.2f}, {p.y:.2f}); {f.searched} searched, {f.travelled_m:.2f} m so far"
                    f"{found}",
                    flush=True,
                )

            print(f"{target}:", flush=True)
            started = time.monotonic()
            sent = client.send_goal_async(goal, feedback_callback=feedback)
            while not sent.done():
                if time.monotonic() - started > 10:
                    print("  the node did not answer the goal within 10 s", file=sys.stderr)
                    return 1
                time.sleep(0.01)
            handle = sent.result()
            if not handle.accepted:
                print("  rejected (is another search running?)")
                found_all = False
                continue
            result = handle.get_result_async()
            try:
                while not result.done():
                    if time.monotonic() - started > args.timeout:
                        handle.cancel_goal_async()
                        print(f"  no result within {args.timeout:g} s: canceled", file=sys.stderr)
                        return 1
                    time.sleep(0.01)
            except KeyboardInterrupt:
                handle.cancel_goal_async()
                time.sleep(0.5)
                return 1
            r = result.result().result
            found_all &= r.status == SearchObject.Result.FOUND
            print(
                f"  {STATUS.get(r.status, r.status)}: {r.message}\n"
                f"  searched {' '.join(r.searched_containers) or 'nothing'}; "
                f"{time.monotonic() - started:.1f} s",
                flush=True,
            )
    finally:
        # The executor's thread ends before the node goes, so no callback meets a destroyed node.
        ex.shutdown(timeout_sec=2)
        spinner.join(2)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0 if found_all else 1


def goal_of(text: str) -> SearchObject.Goal:
    """The goal for one argument: a single object type as `target_type` (the search the node
    always ran), anything with + | or @ as a task."""
    if not any(c in text for c in "+|@"):
        return SearchObject.Goal(target_type=text)
    task = parse_task(text)
    goal = SearchObject.Goal(target_types=list(task.targets))
    if task.goal == "any":
        goal.goal_kind = GOAL_ANY
    d = task.destination
    if d is None:
        return goal
    if d.kind == "start":
        goal.destination_kind = DESTINATION_START
    elif d.kind in ("container", "room"):
        goal.destination_kind = DESTINATION_CONTAINER if d.kind == "container" else DESTINATION_ROOM
        goal.destination_id = d.name
    else:
        goal.destination_kind = DESTINATION_POSE
        goal.destination_pose.header.frame_id = "map"
        goal.destination_pose.pose.position.x = d.x
        goal.destination_pose.pose.position.y = d.y
    return goal


if __name__ == "__main__":
    sys.exit(main())
