#!/usr/bin/env python3
"""Draws the example apartment: a ROS map_server map (map.pgm + map.yaml) and the ferret scene
(scene.yaml), both from the one geometry below.

    python3 examples/apartment/draw_map.py            # writes the three files next to this script
    python3 examples/apartment/draw_map.py --ascii    # also prints the map, 0.2 m per character
    python3 examples/apartment/draw_map.py --check    # only checks the geometry, writes nothing

The apartment is about 10 m x 8 m, four rooms like the one of the paper's real-robot experiment:

    y=8 +-----------+----------------------+
        | kitchen   |  dining room         |
        |           D                      |
    4.5 +-----------+----D-----+-----------+
        |                      |           |
        | living room          D  bedroom  |
        |                      |           |
    y=0 +----------------------+-----------+
       x=0         4          6           10

Coordinates are the robot's map frame: metres, x to the right, y up; yaw in degrees
counter-clockwise from +x (ROS). Room polygons run along the centre lines of the walls, which are
WALL thick. Furniture is not drawn in the map (ferret draws container footprints itself); a
container's footprint is `size` = [along its own x, along its own y] turned by its yaw, and its
own +x is its front (the side the robot searches it from).

Standard library only.
"""

import argparse
import math
import os
import sys

# ---------------------------------------------------------------------------------------------
# The geometry: everything below is derived from these tables.
# ---------------------------------------------------------------------------------------------

NAME = "apartment"
RESOLUTION = 0.05  # metres per pixel
WALL = 0.10  # wall thickness, metres, centred on the room polygons' edges
MARGIN = 0.5  # unknown space around the outer walls, metres
ROBOT_RADIUS = 0.18  # ferret's default; used only by the checks here
FRONT_CLEARANCE = 0.5  # free floor required in front of every container, metres

# name, type, polygon (counter-clockwise), metres.
ROOMS = [
    ("kitchen", "Kitchen", [(0.0, 4.5), (4.0, 4.5), (4.0, 8.0), (0.0, 8.0)]),
    ("dining room", "DiningRoom", [(4.0, 4.5), (10.0, 4.5), (10.0, 8.0), (4.0, 8.0)]),
    ("living room", "LivingRoom", [(0.0, 0.0), (6.0, 0.0), (6.0, 4.5), (0.0, 4.5)]),
    ("bedroom", "Bedroom", [(6.0, 0.0), (10.0, 0.0), (10.0, 4.5), (6.0, 4.5)]),
]

# Openings in the walls: from, to (on a shared edge). Between which rooms is only a comment.
DOORS = [
    ((4.6, 4.5), (5.6, 4.5)),  # living room <-> dining room, 1.0 m
    ((4.0, 5.8), (4.0, 6.8)),  # kitchen <-> dining room, 1.0 m
    ((6.0, 3.3), (6.0, 4.2)),  # living room <-> bedroom, 0.9 m
]

# id, type, room, pose [x, y, yaw deg], size [along own x (depth: front to back), along own y],
# contents (CamelCase object types; what a simulated robot finds there).
CONTAINERS = [
    ("fridge", "Fridge", "kitchen", (0.50, 7.55, -90), (0.70, 0.80), ["Apple", "Egg", "Tomato"]),
    (
        "countertop",
        "CounterTop",
        "kitchen",
        (2.00, 7.60, -90),
        (0.60, 2.00),
        ["Mug", "Bread", "KeyChain"],
    ),
    (
        "dining_table",
        "DiningTable",
        "dining room",
        (7.00, 6.25, 0),
        (1.60, 0.90),
        ["CellPhone", "Laptop", "Apple"],
    ),
    ("shelf", "Shelf", "dining room", (9.70, 6.25, 180), (0.40, 1.20), ["Book", "Vase"]),
    ("sofa", "Sofa", "living room", (0.55, 2.20, 0), (0.90, 2.00), ["Pillow", "Blanket"]),
    (
        "coffee_table",
        "CoffeeTable",
        "living room",
        (2.00, 2.20, 0),
        (0.50, 1.00),
        ["RemoteControl", "Mug", "Book"],
    ),
    (
        "tv_stand",
        "TVStand",
        "living room",
        (5.675, 2.20, 180),
        (0.45, 1.60),
        ["Television", "Statue"],
    ),
    ("bed", "Bed", "bedroom", (8.90, 2.00, 180), (2.00, 1.60), ["Pillow", "Blanket", "Book"]),
    (
        "dresser",
        "Dresser",
        "bedroom",
        (9.10, 4.15, -90),
        (0.50, 1.20),
        ["Wallet", "AlarmClock", "KeyChain"],
    ),
]

START = (3.20, 1.20, 90)  # living room, facing the dining-room door

# The paper's five targets: each must be in at least one container.
TARGETS = ["Blanket", "CellPhone", "RemoteControl", "Pillow", "Wallet"]

# map_server pixel values (negate: 0): occupied, free, unknown.
OCCUPIED, FREE, UNKNOWN = 0, 254, 205

# ---------------------------------------------------------------------------------------------
# Geometry helpers.
# ---------------------------------------------------------------------------------------------


def bounds():
    """Outer corners of the apartment including the walls' outer halves."""
    xs = [p[0] for _, _, poly in ROOMS for p in poly]
    ys = [p[1] for _, _, poly in ROOMS for p in poly]
    h = WALL / 2
    return min(xs) - h, min(ys) - h, max(xs) + h, max(ys) + h


def image_frame():
    """(origin_x, origin_y, width_px, height_px) of the map image."""
    x0, y0, x1, y1 = bounds()
    ox, oy = round(x0 - MARGIN, 6), round(y0 - MARGIN, 6)
    w = int(round((x1 + MARGIN - ox) / RESOLUTION))
    h = int(round((y1 + MARGIN - oy) / RESOLUTION))
    return ox, oy, w, h


def in_polygon(poly, x, y):
    """Even-odd rule, as ferret's Polygon::contains."""
    inside = False
    j = len(poly) - 1
    for i in range(len(poly)):
        (xi, yi), (xj, yj) = poly[i], poly[j]
        if (yi > y) != (yj > y) and x < (xj - xi) * (y - yi) / (yj - yi) + xi:
            inside = not inside
        j = i
    return inside


def local(a, b, x, y):
    """(along, across, length) of point (x, y) relative to segment a-b."""
    dx, dy = b[0] - a[0], b[1] - a[1]
    length = math.hypot(dx, dy)
    ux, uy = dx / length, dy / length
    px, py = x - a[0], y - a[1]
    return px * ux + py * uy, px * uy - py * ux, length


def walls():
    """Every room edge once (shared edges are drawn once)."""
    seen, out = set(), []
    for _, _, poly in ROOMS:
        for k in range(len(poly)):
            a, b = poly[k], poly[(k + 1) % len(poly)]
            key = tuple(sorted([a, b]))
            if key not in seen:
                seen.add(key)
                out.append((a, b))
    return out


def is_wall(x, y, wall_list):
    h = WALL / 2
    for a, b in wall_list:
        along, across, length = local(a, b, x, y)
        # Square ends extended by half the thickness, so corners close.
        if abs(across) <= h and -h <= along <= length + h:
            return True
    return False


def in_door(x, y):
    h = WALL / 2 + 1e-9
    for a, b in DOORS:
        along, across, length = local(a, b, x, y)
        if abs(across) <= h and 0.0 <= along <= length:
            return True
    return False


def room_of(x, y):
    for name, _, poly in ROOMS:
        if in_polygon(poly, x, y):
            return name
    return None


def corners(pose, size, grow_front=0.0):
    """Corners of a footprint (optionally the strip `grow_front` deep in front of it)."""
    x, y, yaw = pose
    sx, sy = size
    c, s = math.cos(math.radians(yaw)), math.sin(math.radians(yaw))
    if grow_front > 0.0:
        lx0, lx1 = sx / 2, sx / 2 + grow_front
    else:
        lx0, lx1 = -sx / 2, sx / 2
    pts = [(lx0, -sy / 2), (lx1, -sy / 2), (lx1, sy / 2), (lx0, sy / 2)]
    return [(x + px * c - py * s, y + px * s + py * c) for px, py in pts]


def in_rect(rect, x, y):
    """Point in a convex quadrilateral given counter-clockwise (or clockwise)."""
    sign = 0
    for k in range(4):
        (ax, ay), (bx, by) = rect[k], rect[(k + 1) % 4]
        cross = (bx - ax) * (y - ay) - (by - ay) * (x - ax)
        if abs(cross) < 1e-12:
            continue
        if sign == 0:
            sign = 1 if cross > 0 else -1
        elif (cross > 0) != (sign > 0):
            return False
    return True


# ---------------------------------------------------------------------------------------------
# Drawing.
# ---------------------------------------------------------------------------------------------


def draw():
    """The map as rows of pixel values, row 0 the bottom (lowest y). Decided by pixel centres."""
    ox, oy, w, h = image_frame()
    wall_list = walls()
    rows = []
    for r in range(h):
        y = oy + (r + 0.5) * RESOLUTION
        row = bytearray(w)
        for c in range(w):
            x = ox + (c + 0.5) * RESOLUTION
            if in_door(x, y):
                row[c] = FREE
            elif is_wall(x, y, wall_list):
                row[c] = OCCUPIED
            elif room_of(x, y) is not None:
                row[c] = FREE
            else:
                row[c] = UNKNOWN
        rows.append(row)
    return rows


def pgm_bytes(rows):
    """Binary P5; the image's first row is the map's top."""
    w, h = len(rows[0]), len(rows)
    return b"P5\n%d %d\n255\n" % (w, h) + b"".join(bytes(r) for r in reversed(rows))


def map_yaml():
    ox, oy, _, _ = image_frame()
    return (
        "image: map.pgm\n"
        f"resolution: {RESOLUTION}\n"
        f"origin: [{ox}, {oy}, 0.0]\n"
        "negate: 0\n"
        "occupied_thresh: 0.65\n"
        "free_thresh: 0.196\n"
    )


def num(v):
    """A number as YAML: integers without a decimal point, others without float noise."""
    v = round(float(v), 4)
    return str(int(v)) if v == int(v) else repr(v)


def pair(p):
    return "[" + ", ".join(num(v) for v in p) + "]"


def scene_yaml():
    lines = [
        "# Generated by draw_map.py from the same geometry as map.pgm; edit that script, not this.",
        "# Metres in the map frame (x right, y up); yaw in degrees counter-clockwise (ROS).",
        "ferret_scene: 1",
        f"name: {NAME}",
        "map: {ros: map.yaml}",
        "rooms:",
    ]
    for name, rtype, poly in ROOMS:
        lines.append(
            f"  - {{name: {name}, type: {rtype}, polygon: [{', '.join(pair(p) for p in poly)}]}}"
        )
    lines.append("# Openings in the walls; the map shows them too (they are free pixels there).")
    lines.append("doors:")
    for a, b in DOORS:
        lines.append(f"  - {{from: {pair(a)}, to: {pair(b)}}}")
    lines.append("containers:")
    for cid, ctype, room, pose, size, contents in CONTAINERS:
        lines += [
            f"  - id: {cid}",
            f"    type: {ctype}",
            f"    room: {room}",
            f"    pose: {pair(pose)}",
            f"    size: {pair(size)}",
            f"    contents: [{', '.join(contents)}]",
        ]
    lines.append(f"start: {pair(START)}")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------
# Checks.
# ---------------------------------------------------------------------------------------------


def pixels_in(rows, rect):
    """(col, row) of the pixels whose centre lies in the quadrilateral `rect`."""
    ox, oy, w, h = image_frame()
    xs, ys = [p[0] for p in rect], [p[1] for p in rect]
    c0 = max(0, int(math.floor((min(xs) - ox) / RESOLUTION)) - 1)
    c1 = min(w, int(math.ceil((max(xs) - ox) / RESOLUTION)) + 1)
    r0 = max(0, int(math.floor((min(ys) - oy) / RESOLUTION)) - 1)
    r1 = min(h, int(math.ceil((max(ys) - oy) / RESOLUTION)) + 1)
    out = []
    for r in range(r0, r1):
        for c in range(c0, c1):
            x, y = ox + (c + 0.5) * RESOLUTION, oy + (r + 0.5) * RESOLUTION
            if in_rect(rect, x, y):
                out.append((c, r))
    return out


def reachable(rows):
    """Free pixels reachable from the start by a disc of ROBOT_RADIUS, with container footprints
    drawn as obstacles: roughly what ferret does with the map (8-connected, no corner cutting)."""
    ox, oy, w, h = image_frame()
    blocked = [[rows[r][c] != FREE for c in range(w)] for r in range(h)]
    for _, _, _, pose, size, _ in CONTAINERS:
        for c, r in pixels_in(rows, corners(pose, size)):
            blocked[r][c] = True
    rad = ROBOT_RADIUS / RESOLUTION
    k = int(math.floor(rad))
    disc = [
        (dc, dr)
        for dr in range(-k, k + 1)
        for dc in range(-k, k + 1)
        if dc * dc + dr * dr < rad * rad
    ]
    ok = [[not blocked[r][c] for c in range(w)] for r in range(h)]
    for r in range(h):
        for c in range(w):
            if blocked[r][c]:
                for dc, dr in disc:
                    if 0 <= r + dr < h and 0 <= c + dc < w:
                        ok[r + dr][c + dc] = False
    sc = int((START[0] - ox) / RESOLUTION)
    sr = int((START[1] - oy) / RESOLUTION)
    seen = [[False] * w for _ in range(h)]
    if not ok[sr][sc]:
        return seen, False
    seen[sr][sc] = True
    stack = [(sc, sr)]
    while stack:
        c, r = stack.pop()
        for dc in (-1, 0, 1):
            for dr in (-1, 0, 1):
                nc, nr = c + dc, r + dr
                if (dc or dr) and 0 <= nc < w and 0 <= nr < h and ok[nr][nc] and not seen[nr][nc]:
                    if dc and dr and not (ok[r][nc] and ok[nr][c]):
                        continue
                    seen[nr][nc] = True
                    stack.append((nc, nr))
    return seen, True


def check(rows):
    """Returns a list of problems (empty when the geometry is consistent)."""
    problems = []
    ox, oy, w, h = image_frame()
    names = [r[0] for r in ROOMS]
    polys = {r[0]: r[2] for r in ROOMS}
    for a, b in DOORS:
        mid = ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)
        c, r = int((mid[0] - ox) / RESOLUTION), int((mid[1] - oy) / RESOLUTION)
        if rows[r][c] != FREE:
            problems.append(f"door {a}-{b}: its middle is not free")
        width = math.dist(a, b)
        if not 0.85 <= width <= 1.05:
            problems.append(f"door {a}-{b}: {width:.2f} m wide")
    ids = set()
    for cid, ctype, room, pose, size, contents in CONTAINERS:
        if cid in ids:
            problems.append(f"{cid}: duplicate id")
        ids.add(cid)
        if room not in names:
            problems.append(f"{cid}: unknown room {room!r}")
            continue
        if room_of(pose[0], pose[1]) != room:
            problems.append(f"{cid}: pose is not in {room}")
        for x, y in corners(pose, size):
            if not in_polygon(polys[room], x, y):
                problems.append(f"{cid}: corner ({x:.2f}, {y:.2f}) outside {room}")
        for c, r in pixels_in(rows, corners(pose, size)):
            if rows[r][c] != FREE:
                problems.append(f"{cid}: footprint overlaps a wall pixel ({c}, {r})")
                break
        front = corners(pose, size, grow_front=FRONT_CLEARANCE)
        bad = False
        for c, r in pixels_in(rows, front):
            x, y = ox + (c + 0.5) * RESOLUTION, oy + (r + 0.5) * RESOLUTION
            if rows[r][c] != FREE or room_of(x, y) != room:
                bad = True
            for oid, _, _, opose, osize, _ in CONTAINERS:
                if oid != cid and in_rect(corners(opose, osize), x, y):
                    bad = True
        if bad:
            problems.append(f"{cid}: less than {FRONT_CLEARANCE} m of free floor in front")
        mine = set(pixels_in(rows, corners(pose, size)))
        for oid, _, _, opose, osize, _ in CONTAINERS:
            if oid != cid and mine & set(pixels_in(rows, corners(opose, osize))):
                problems.append(f"{cid}: overlaps {oid}")
        if not contents or not all(t.isalnum() for t in contents):
            problems.append(f"{cid}: contents must be CamelCase object types")
    for t in TARGETS:
        if not any(t in c[5] for c in CONTAINERS):
            problems.append(f"target {t} is in no container")
    if room_of(START[0], START[1]) != "living room":
        problems.append("the start is not in the living room")
    seen, start_ok = reachable(rows)
    if not start_ok:
        problems.append("the start is not free (walls or furniture within the robot radius)")
    else:
        for cid, _, room, pose, size, _ in CONTAINERS:
            # Some reachable pixel within a robot diameter in front of the footprint.
            near = corners(pose, size, grow_front=2 * ROBOT_RADIUS + RESOLUTION)
            hits = [(c, r) for c, r in pixels_in(rows, near) if seen[r][c]]
            if not hits:
                problems.append(f"{cid}: no reachable floor in front of it")
    return problems


# ---------------------------------------------------------------------------------------------
# Output.
# ---------------------------------------------------------------------------------------------


def ascii_map(rows, step=4):
    """One character per step x step pixels: '#' any wall, '.' floor, ' ' unknown, a letter for
    the container whose footprint holds the block's centre, '@' the start."""
    ox, oy, w, h = image_frame()
    letters = {c[0]: chr(ord("A") + i) for i, c in enumerate(CONTAINERS)}
    out = []
    for r in range(h - 1, -1, -step):
        line = []
        for c in range(0, w, step):
            block = [
                rows[rr][cc]
                for rr in range(max(0, r - step + 1), r + 1)
                for cc in range(c, min(w, c + step))
            ]
            x = ox + (c + step / 2) * RESOLUTION
            y = oy + (r - step / 2 + 1) * RESOLUTION
            ch = "#" if OCCUPIED in block else "." if FREE in block else " "
            for cid, _, _, pose, size, _ in CONTAINERS:
                if in_rect(corners(pose, size), x, y):
                    ch = letters[cid]
            if (
                abs(x - START[0]) < step * RESOLUTION / 2
                and abs(y - START[1]) < step * RESOLUTION / 2
            ):
                ch = "@"
            line.append(ch)
        out.append("".join(line).rstrip())
    legend = ", ".join(f"{letters[c[0]]}={c[0]}" for c in CONTAINERS)
    return "\n".join(out) + f"\n{legend}, @=start; {step * RESOLUTION:g} m per character\n"


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--out",
        default=os.path.dirname(os.path.abspath(__file__)),
        help="folder to write map.pgm, map.yaml and scene.yaml (default: this one)",
    )
    ap.add_argument("--ascii", action="store_true", help="print the map, 0.2 m per character")
    ap.add_argument("--check", action="store_true", help="check the geometry, write nothing")
    args = ap.parse_args()

    rows = draw()
    problems = check(rows)
    if args.ascii:
        sys.stdout.write(ascii_map(rows))
    if problems:
        for p in problems:
            print(f"problem: {p}", file=sys.stderr)
        sys.exit(1)
    ox, oy, w, h = image_frame()
    if not args.check:
        os.makedirs(args.out, exist_ok=True)
        with open(os.path.join(args.out, "map.pgm"), "wb") as f:
            f.write(pgm_bytes(rows))
        with open(os.path.join(args.out, "map.yaml"), "w") as f:
            f.write(map_yaml())
        with open(os.path.join(args.out, "scene.yaml"), "w") as f:
            f.write(scene_yaml())
        print(
            f"wrote map.pgm ({w}x{h} px, origin [{ox}, {oy}]), map.yaml, scene.yaml to {args.out}"
        )
    else:
        print(f"geometry consistent: {w}x{h} px, origin [{ox}, {oy}]")


if __name__ == "__main__":
    main()
