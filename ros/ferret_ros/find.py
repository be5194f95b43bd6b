"""Ask a running ferret node to find objects, printing its feedback and results (what
`ros2 action send_goal` would do, for a ROS 2 installed from wheels, which has no `ros2` CLI).

    python3 -m ferret_ros.find Wallet RemoteControl [--node ferret] [--timeout 600]

Exits 0 when every object was found, 1 otherwise. Ctrl-C cancels the running search.
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

STATUS = {v: k for k, v in vars(SearchObject.Result).items() if k.isupper() and isinstance(v, int)}


def main(argv=None) -> int:
    argv = argv if argv is not None else sys.argv
    ap = argparse.ArgumentParser(
        prog="python3 -m ferret_ros.find", description=__doc__.split("\n\n")[0]
    )
    ap.add_argument("targets", nargs="+", help="object types, e.g. RemoteControl")
    ap.add_argument("--node", default="ferret", help="the ferret node's name (default ferret)")
    ap.add_argument("--timeout", type=float, default=600.0, help="seconds per search (default 600)")
    args = ap.parse_args(rclpy.utilities.remove_ros_args(argv)[1:])
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
        for target in args.targets:

            def feedback(msg):
                f = msg.feedback
                p = f.next_pose.pose.position
                print(
                    f"  -> {f.next_container} ({f.next_container_type}, {f.next_room}) at "
                    f"({p.x:.2f}, {p.y:.2f}); {f.searched} searched, {f.travelled_m:.2f} m so far",
                    flush=True,
                )

            print(f"{target}:", flush=True)
            started = time.monotonic()
            sent = client.send_goal_async(
                SearchObject.Goal(target_type=target), feedback_callback=feedback
            )
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
            found_all &= r.found
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


if __name__ == "__main__":
    sys.exit(main())
