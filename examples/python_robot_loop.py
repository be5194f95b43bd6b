#!/usr/bin/env python3
"""A robot's object-search loop driven by ferret.Search, ready to move into a ROS 2 node.

The loop is what a node runs once per "find X" request: ask the planner for the next container,
drive there, look, report what was seen, until the object is found or nothing is left. The two
functions marked ROBOT are the only ones that touch hardware; here they simulate a robot in a
generated house (perfect perception, motion along the planned grid path). In an rclpy node,
`drive_to` becomes a Nav2 NavigateToPose goal to `container.access`, and `look_into` a
perception service call returning the object types detected. Nothing else changes.

    python3 examples/python_robot_loop.py [--strategy model/prior] [--seed 0]
"""

import argparse
import math
import sys
from typing import List, Optional, Tuple

import ferret


# ---------------------------------------------------------------------------------------------
# ROBOT: motion. Replace with a navigation goal (Nav2 NavigateToPose to `container.access`) and
# return the distance actually driven, metres (odometry), or None when the goal failed.
# ---------------------------------------------------------------------------------------------
def drive_to(search: ferret.Search, container: ferret.Container) -> Optional[float]:
    path: List[Tuple[float, float]] = search.path_to(container)
    return sum(math.dist(a, b) for a, b in zip(path, path[1:]))


# ---------------------------------------------------------------------------------------------
# ROBOT: perception. Replace with the detector's answer at the container: the object types seen.
# The simulation reads the house's ground truth, which a real robot never has.
# ---------------------------------------------------------------------------------------------
def look_into(house: ferret.House, container: ferret.Container) -> List[str]:
    return house.contents(container)


def find(house: ferret.House, target: str, strategy: str, prior: ferret.Prior) -> ferret.Search:
    """Searches `house` for an object of type `target`; returns the finished search."""
    search = ferret.Search(house, target, strategy, prior=prior)
    while (container := search.next_container()) is not None:
        where = f"{container.type} {container.id} in the {container.room_type or 'house'}"
        driven = drive_to(search, container)
        if driven is None:
            # Unreachable right now (a closed door, a person in the way): skip it.
            # record() it as searched-empty so the planner goes on with the rest.
            print(f"  could not reach {where}; skipping it")
            search.record(container, found=False)
            continue
        seen = look_into(house, container)
        found = target in seen
        leg = search.record(container, found=found, objects=seen)
        saw = ", ".join(seen) or "nothing"
        print(f"  {where}: planned {leg:.2f} m, driven {driven:.2f} m, saw {saw}")
        if found:
            break
    return search


def main(argv: Optional[List[str]] = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--strategy", default="model/prior")
    parser.add_argument("--seed", type=int, default=0, help="seed of the generated house")
    args = parser.parse_args(argv)

    [house] = ferret.generate_houses(1, args.seed)
    prior = ferret.Prior.default()
    # The request a node would receive; here the house's first searchable type.
    target = house.target_types()[0]
    print(
        f"{house.name}: {len(house.rooms)} rooms, {len(house.containers)} containers; "
        f"target {target}, strategy {args.strategy}"
    )
    search = find(house, target, args.strategy, prior)
    if search.found is None:
        print(f"no {target} in any container; travelled {search.cost:.2f} m")
        return 1
    searches = len(search.searched)
    print(f"found the {target} in {search.found.id} after {searches} searches, {search.cost:.2f} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
