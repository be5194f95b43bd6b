"""Occupancy maps: reading a map_server map (YAML + PGM) and checking a received /map against
the scene the node plans in.

Plain Python (no ROS imports), so that it is tested and used without a running graph. A grid is
a `Grid`: row-major int8-like values as nav_msgs/OccupancyGrid carries them (row 0 at the
origin's y, -1 unknown, 0 free .. 100 occupied).
"""

import math
import os
from dataclasses import dataclass
from typing import List, Optional, Sequence, Tuple

import yaml

# A cell at or below this occupancy is free for the check; above OCCUPIED it is an obstacle.
# map_server writes 0 and 100 for trinary maps; anything between counts as neither.
FREE_MAX = 25
OCCUPIED_MIN = 65
# Share of cells that must be in the same class (free, occupied, unknown) as the scene's own map.
AGREEMENT_MIN = 0.98


@dataclass
class Grid:
    """An occupancy grid in the map frame: `origin` is the (x, y) of cell (0, 0)'s corner."""

    resolution: float
    width: int
    height: int
    origin: Tuple[float, float]
    data: Sequence[int]
    frame_id: str = "map"
    origin_yaw: float = 0.0

    def cell(self, x: float, y: float) -> Optional[int]:
        """The occupancy at (x, y) metres, or None outside the grid."""
        i = math.floor((x - self.origin[0]) / self.resolution)
        j = math.floor((y - self.origin[1]) / self.resolution)
        if not (0 <= i < self.width and 0 <= j < self.height):
            return None
        return int(self.data[j * self.width + i])


def read_map_yaml(path: str) -> Grid:
    """A map_server map (the YAML and the PGM/PNM image it names), as map_server would publish it
    in trinary mode: 100 above occupied_thresh, 0 below free_thresh, -1 between."""
    with open(path, encoding="utf-8") as f:
        meta = yaml.safe_load(f)
    for key in ("image", "resolution", "origin"):
        if key not in meta:
            raise ValueError(f"{path}: missing `{key}`")
    image = os.path.join(os.path.dirname(os.path.abspath(path)), meta["image"])
    width, height, maxval, pixels = _read_pnm(image)
    negate = bool(meta.get("negate", 0))
    occ_t = float(meta.get("occupied_thresh", 0.65))
    free_t = float(meta.get("free_thresh", 0.196))
    data = [0] * (width * height)
    for row in range(height):
        # The image's first row is the top of the map; the grid's row 0 is its bottom.
        j = height - 1 - row
        for i in range(width):
            v = pixels[row * width + i] / maxval
            p = v if negate else 1.0 - v
            data[j * width + i] = 100 if p > occ_t else (0 if p < free_t else -1)
    ox, oy = float(meta["origin"][0]), float(meta["origin"][1])
    yaw = float(meta["origin"][2]) if len(meta["origin"]) > 2 else 0.0
    return Grid(float(meta["resolution"]), width, height, (ox, oy), data, "map", yaw)


def _read_pnm(path: str) -> Tuple[int, int, int, bytes]:
    """A binary greyscale PGM (P5, 8-bit), the format map_server's map_saver writes."""
    with open(path, "rb") as f:
        raw = f.read()
    tokens: List[bytes] = []
    pos = 0
    while len(tokens) < 4:
        while raw[pos : pos + 1].isspace():
            pos += 1
        if raw[pos : pos + 1] == b"#":
            pos = raw.index(b"\n", pos) + 1
            continue
        start = pos
        while not raw[pos : pos + 1].isspace():
            pos += 1
        tokens.append(raw[start:pos])
    if tokens[0] != b"P5":
        raise ValueError(f"{path}: only binary PGM (P5) maps are read, not {tokens[0]!r}")
    width, height, maxval = int(tokens[1]), int(tokens[2]), int(tokens[3])
    if maxval > 255:
        raise ValueError(f"{path}: 16-bit PGM maps are not read")
    pixels = raw[pos + 1 : pos + 1 + width * height]
    if len(pixels) != width * height:
        raise ValueError(f"{path}: {len(pixels)} pixels, expected {width}×{height}")
    return width, height, maxval, pixels


def _class(v: int) -> int:
    return 0 if 0 <= v <= FREE_MAX else (1 if v >= OCCUPIED_MIN else 2)


def check_map(
    grid: Grid,
    places: Sequence[Tuple[str, float, float]],
    frame_id: str,
    reference: Optional[Grid] = None,
) -> List[str]:
    """Why `grid` is not the map of the scene, as sentences (empty: it matches).

    `places` are the points the robot must reach, (name, x, y) in metres: every container's
    access point and the start pose. Each must be inside the grid on a free cell, else the robot
    would be sent into a wall or off the map. With `reference` (the scene's own map), the
    resolution, origin and size must be equal and AGREEMENT_MIN of the cells in the same class.
    """
    problems = []
    if grid.frame_id != frame_id:
        problems.append(f"frame {grid.frame_id!r}, expected {frame_id!r}")
    if abs(grid.origin_yaw) > 1e-6:
        problems.append(f"a rotated origin (yaw {grid.origin_yaw:.3f} rad) is not supported")
    if not (grid.resolution > 0 and grid.width > 0 and grid.height > 0):
        problems.append(f"an empty grid ({grid.width}×{grid.height} at {grid.resolution} m)")
        return problems
    if len(grid.data) != grid.width * grid.height:
        problems.append(f"{len(grid.data)} cells for a {grid.width}×{grid.height} grid")
        return problems
    bad = []
    for name, x, y in places:
        v = grid.cell(x, y)
        if v is None:
            bad.append(f"{name} ({x:.2f}, {y:.2f}) is outside the map")
        elif not 0 <= v <= FREE_MAX:
            what = "unknown" if v < 0 else f"occupied ({v})"
            bad.append(f"{name} ({x:.2f}, {y:.2f}) is on an {what} cell")
    if bad:
        shown = "; ".join(bad[:4]) + (f"; and {len(bad) - 4} more" if len(bad) > 4 else "")
        problems.append(f"{len(bad)} of {len(places)} places the robot must reach: {shown}")
    if reference is not None:
        half = reference.resolution / 2
        if (
            abs(grid.resolution - reference.resolution) > 1e-6
            or (grid.width, grid.height) != (reference.width, reference.height)
            or abs(grid.origin[0] - reference.origin[0]) > half
            or abs(grid.origin[1] - reference.origin[1]) > half
        ):
            problems.append(
                "not the scene's map: "
                f"{grid.width}×{grid.height} cells of {grid.resolution:g} m at "
                f"({grid.origin[0]:g}, {grid.origin[1]:g}), the scene's is "
                f"{reference.width}×{reference.height} of {reference.resolution:g} m at "
                f"({reference.origin[0]:g}, {reference.origin[1]:g})"
            )
        else:
            same = sum(1 for a, b in zip(grid.data, reference.data) if _class(a) == _class(b))
            share = same / len(reference.data)
            if share < AGREEMENT_MIN:
                problems.append(
                    f"only {share:.1%} of the cells agree with the scene's map "
                    f"(free/occupied/unknown), at least {AGREEMENT_MIN:.0%} needed"
                )
    return problems


def read_scene_map(scene_path: str) -> Optional[Grid]:
    """The ROS map a ferret scene file names (`map: {ros: map.yaml}`), or None when it names
    none (a JSON or ProcTHOR scene, or a scene without a map)."""
    try:
        with open(scene_path, encoding="utf-8") as f:
            scene = yaml.safe_load(f)
    except (OSError, UnicodeDecodeError, yaml.YAMLError):
        return None
    m = scene.get("map") if isinstance(scene, dict) else None
    if isinstance(m, dict) and m.get("ros"):
        return read_map_yaml(os.path.join(os.path.dirname(os.path.abspath(scene_path)), m["ros"]))
    return None
