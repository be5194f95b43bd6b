"""What the node draws for rviz2 and Foxglove, with their stock displays and no plugin: a
`visualization_msgs/MarkerArray` of the containers coloured by the belief, and a
`nav_msgs/Path` of the route to the next container (or, once a household task's goal holds, to
its destination).

Every array is a whole picture: it starts with a DELETEALL, so markers of an earlier trial (or an
earlier step) never linger, and a viewer that joins late gets everything from the one latched
array.

Namespaces (ids are the containers' indices in the scene, stable across a trial):

- `containers`: a cylinder per container. Not yet searched: white (p = 0) through yellow to red
  (the largest p among the containers not yet searched); light grey when the strategy gives no
  likelihood. Searched in vain: dark grey. Where the target was found: green. The next container
  is drawn larger. For a household task, p is the chance that the container holds a target still
  wanted, and every container where a target was found is green.
- `searched`: a black cross over each container searched in vain.
- `next`: a blue ring around the next container (id 0; absent once the search has ended).
- `labels`: the container's id and type, and its p (or "searched", "found"; for a task "found"
  and the targets found there).
- `destination` (a task with a destination only): a purple diamond where the robot brings what
  it found (id 0) and its label (id 1).
"""

import math
from typing import Collection, Dict, List, Mapping, Optional, Sequence, Tuple, Union

from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point, PoseStamped
from nav_msgs.msg import Path
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

# Sizes, metres: a container's cylinder, the next one's, the ring, the text.
BODY_M = 0.3
NEXT_BODY_M = 0.5
RING_RADIUS_M = 0.45
LINE_M = 0.05
TEXT_M = 0.18

UNKNOWN = (0.6, 0.6, 0.6)
SEARCHED = (0.25, 0.25, 0.25)
FOUND = (0.1, 0.8, 0.2)
CROSS = (0.0, 0.0, 0.0)
RING = (0.1, 0.5, 1.0)
TEXT = (1.0, 1.0, 1.0)
DESTINATION = (0.6, 0.2, 0.85)
# The destination's diamond: a flat square turned by 45 degrees, metres.
DIAMOND_M = 0.4

# Stamp 0: viewers draw these with the latest transform, so a latched array shown long after it
# was sent still appears when the viewer's fixed frame is not the map frame.
STAMP_ZERO = Time()


def heat(t: float) -> Tuple[float, float, float]:
    """White (t = 0) through yellow (0.5) to red (1): red stays 1, blue falls over the first
    half, green over the second, so (1 - g) + (1 - b) = 2t grows with t all the way."""
    t = min(1.0, max(0.0, t))
    if t <= 0.5:
        return (1.0, 1.0, 1.0 - 2.0 * t)
    return (1.0, 2.0 - 2.0 * t, 0.0)


def container_colour(
    p: float, searched: bool, found: bool, top: float
) -> Tuple[float, float, float]:
    """A container's colour: its state, or its p on the heat scale relative to `top` (the
    largest p of the containers not yet searched)."""
    if found:
        return FOUND
    if searched:
        return SEARCHED
    if math.isnan(p):
        return UNKNOWN
    return heat(p / top if top > 0 else 0.0)


def _rgba(rgb: Tuple[float, float, float], a: float = 1.0) -> ColorRGBA:
    return ColorRGBA(r=float(rgb[0]), g=float(rgb[1]), b=float(rgb[2]), a=float(a))


def _marker(frame: str, ns: str, id_: int, type_: int) -> Marker:
    m = Marker()
    m.header.frame_id = frame
    m.header.stamp = STAMP_ZERO
    m.ns = ns
    m.id = id_
    m.type = type_
    m.action = Marker.ADD
    m.pose.orientation.w = 1.0
    return m


def container_markers(
    frame: str,
    places: Sequence,
    probability: Sequence[float],
    searched: Sequence[bool],
    found: Union[None, str, Mapping[str, Sequence[str]]],
    next_id: Optional[str],
    destination: Optional[Tuple[float, float, str]] = None,
) -> MarkerArray:
    """The picture of one moment of a search. `places` are the scene's containers (`id`,
    `type`, `position`), `probability` and `searched` the belief in the same order, `found` the
    container where the target was found (for a household task: each container where targets
    were found, with them), `next_id` the one the robot goes to next, `destination` where a
    task's robot brings what it found (x, y and a label)."""
    out = MarkerArray()
    clear = Marker()
    clear.header.frame_id = frame
    clear.header.stamp = STAMP_ZERO
    # An empty namespace: rviz2 clears only the named namespace otherwise.
    clear.action = Marker.DELETEALL
    out.markers.append(clear)
    open_ps = [p for p, s in zip(probability, searched) if not s and not math.isnan(p)]
    top = max(open_ps, default=0.0)
    holding: Mapping[str, Sequence[str]] = (
        {} if found is None else {found: ()} if isinstance(found, str) else found
    )
    for i, (place, p, s) in enumerate(zip(places, probability, searched)):
        x, y = place.position
        is_found = place.id in holding
        is_next = place.id == next_id
        size = NEXT_BODY_M if is_next else BODY_M
        body = _marker(frame, "containers", i, Marker.CYLINDER)
        body.pose.position.x, body.pose.position.y = float(x), float(y)
        body.pose.position.z = size / 2
        body.scale.x = body.scale.y = body.scale.z = size
        body.color = _rgba(container_colour(p, s, is_found, top), 0.9)
        out.markers.append(body)

        if s and not is_found:
            cross = _marker(frame, "searched", i, Marker.LINE_LIST)
            cross.scale.x = LINE_M
            cross.color = _rgba(CROSS)
            h, z = BODY_M * 0.8, BODY_M + 0.01
            for dx, dy in ((-h, -h), (h, h), (-h, h), (h, -h)):
                cross.points.append(Point(x=float(x + dx), y=float(y + dy), z=z))
            out.markers.append(cross)

        label = _marker(frame, "labels", i, Marker.TEXT_VIEW_FACING)
        label.pose.position.x, label.pose.position.y = float(x), float(y)
        label.pose.position.z = size + 0.25
        label.scale.z = TEXT_M
        label.color = _rgba(TEXT)
        if is_found:
            state = " ".join(["found", ", ".join(holding[place.id])]).strip()
        elif s:
            state = "searched"
        elif math.isnan(p):
            state = "p unknown"
        else:
            state = f"p {p:.3f}"
        label.text = f"{place.id} ({place.type})\n{state}"
        out.markers.append(label)

        if is_next:
            ring = _marker(frame, "next", 0, Marker.LINE_STRIP)
            ring.scale.x = LINE_M
            ring.color = _rgba(RING)
            for k in range(33):
                a = 2 * math.pi * k / 32
                ring.points.append(
                    Point(
                        x=float(x + RING_RADIUS_M * math.cos(a)),
                        y=float(y + RING_RADIUS_M * math.sin(a)),
                        z=0.02,
                    )
                )
            out.markers.append(ring)
    if destination is not None:
        x, y, name = destination
        diamond = _marker(frame, "destination", 0, Marker.CUBE)
        diamond.pose.position.x, diamond.pose.position.y = float(x), float(y)
        diamond.pose.position.z = 0.03
        diamond.pose.orientation.z = math.sin(math.pi / 8)
        diamond.pose.orientation.w = math.cos(math.pi / 8)
        diamond.scale.x = diamond.scale.y = DIAMOND_M
        diamond.scale.z = 0.06
        diamond.color = _rgba(DESTINATION, 0.9)
        out.markers.append(diamond)
        label = _marker(frame, "destination", 1, Marker.TEXT_VIEW_FACING)
        label.pose.position.x, label.pose.position.y = float(x), float(y)
        label.pose.position.z = 0.35
        label.scale.z = TEXT_M
        label.color = _rgba(TEXT)
        label.text = f"destination: {name}"
        out.markers.append(label)
    return out


def route(
    frame: str,
    points: Sequence[Tuple[float, float]],
    goal: Optional[PoseStamped],
) -> Path:
    """The route to the next container: the planner's path (cell centres, map frame) as poses
    heading along it, ending with `goal` (the access point, facing the container). No goal (the
    search has ended): an empty path, so viewers stop drawing the last one."""
    path = Path()
    path.header.frame_id = frame
    path.header.stamp = STAMP_ZERO
    if goal is None:
        return path
    gx, gy = goal.pose.position.x, goal.pose.position.y
    pts: List[Tuple[float, float]] = [(float(x), float(y)) for x, y in points]
    # The planner's path ends on the access point's cell centre, which is the access point;
    # anything else (no path at all) still ends where the robot is sent.
    if pts and math.dist(pts[-1], (gx, gy)) < 1e-6:
        pts.pop()
    for k, (x, y) in enumerate(pts):
        nx, ny = pts[k + 1] if k + 1 < len(pts) else (gx, gy)
        yaw = math.atan2(ny - y, nx - x)
        ps = PoseStamped()
        ps.header.frame_id = frame
        ps.header.stamp = STAMP_ZERO
        ps.pose.position.x, ps.pose.position.y = x, y
        ps.pose.orientation.z = math.sin(yaw / 2)
        ps.pose.orientation.w = math.cos(yaw / 2)
        path.poses.append(ps)
    end = PoseStamped()
    end.header.frame_id = frame
    end.header.stamp = STAMP_ZERO
    end.pose = goal.pose
    path.poses.append(end)
    return path


def probabilities(
    ids: Sequence[str],
    now: Optional[Dict[str, float]],
    searched: Sequence[str],
    found: Union[None, str, Collection[str]],
) -> List[float]:
    """Per container: the planner's probability now where it gives one; otherwise 1 where the
    target was found (a task's targets: any of the containers in `found`), 0 where searched in
    vain, NaN (unknown) elsewhere."""
    done = set(searched)
    holding = set() if found is None else {found} if isinstance(found, str) else set(found)
    out = []
    for i in ids:
        if now is not None and i in now and now[i] is not None:
            out.append(float(now[i]))
        elif i in holding:
            out.append(1.0)
        elif i in done:
            out.append(0.0)
        else:
            out.append(float("nan"))
    return out
