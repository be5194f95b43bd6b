"""What rviz2 and Foxglove show: the node's MarkerArray and Path, read back over DDS, and the
belief's probabilities with the `ferret serve` backend, against the server's trial view."""

import itertools
import json
import math
import time
import urllib.request

from visualization_msgs.msg import Marker

import ferret
from ferret_interfaces.action import SearchObject

Status = SearchObject.Result
STRATEGY = "model/prior"


def wait_until(pred, what, timeout=10.0):
    deadline = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < deadline, f"within {timeout} s: {what}"
        time.sleep(0.01)


def get(url):
    with urllib.request.urlopen(url, timeout=5) as r:
        return json.loads(r.read())


def searched_order(house, target, strategy=STRATEGY):
    s = ferret.Search(house, target, strategy)
    while (c := s.next_container()) is not None:
        seen = house.contents(c)
        s.record(c, target in seen, seen)
    return list(s.searched)


def longest_search(house):
    """The target whose search visits the most containers: the most pictures to check."""
    return max(house.target_types(), key=lambda t: len(searched_order(house, t)))


def by_ns(array):
    """{namespace: {id: marker}} of an array's markers, the DELETEALL aside."""
    out = {}
    for m in array.markers:
        if m.action == Marker.ADD:
            out.setdefault(m.ns, {})[m.id] = m
    return out


def heat(m):
    """How far along white -> yellow -> red a marker's colour is: 0 white, 2 red."""
    return (1 - m.color.g) + (1 - m.color.b)


def check_picture(array, ids, positions, probs, searched, found, next_id):
    """One MarkerArray: cleared first, in the map frame, a body and a label per container;
    searched ones dark and crossed, the found one green; the open ones' colours ordered like
    `probs` (the largest red); the next one larger and ringed."""
    first = array.markers[0]
    assert (first.action, first.ns, first.header.frame_id) == (Marker.DELETEALL, "", "map")
    assert {m.header.frame_id for m in array.markers} == {"map"}
    ns = by_ns(array)
    bodies, labels = ns["containers"], ns["labels"]
    assert sorted(bodies) == sorted(labels) == list(range(len(ids)))
    crosses = ns.get("searched", {})
    assert sorted(crosses) == sorted(ids.index(c) for c in searched if c != found)
    open_ = []
    for i, cid in enumerate(ids):
        body, label = bodies[i], labels[i]
        assert (body.type, body.pose.position.x, body.pose.position.y) == (
            Marker.CYLINDER,
            positions[cid][0],
            positions[cid][1],
        )
        assert label.text.startswith(f"{cid} (")
        c = body.color
        if cid == found:
            assert c.g > 0.5 > max(c.r, c.b), (cid, c)
            assert label.text.endswith("found")
        elif cid in searched:
            assert c.r == c.g == c.b < 0.5, (cid, c)
            assert label.text.endswith("searched")
        else:
            assert label.text.endswith(f"p {probs[cid]:.3f}"), label.text
            open_.append(cid)
    for a, b in itertools.combinations(open_, 2):
        pa, pb, ha, hb = probs[a], probs[b], heat(bodies[ids.index(a)]), heat(bodies[ids.index(b)])
        assert (pa > pb) == (ha > hb + 1e-9) and (pa < pb) == (ha < hb - 1e-9), (
            a,
            pa,
            ha,
            b,
            pb,
            hb,
        )
    if open_ and max(probs[c] for c in open_) > 0:
        assert max(heat(bodies[ids.index(c)]) for c in open_) == 2.0  # the likeliest is red
    rings = ns.get("next", {})
    if next_id is None:
        assert rings == {}
        return
    k = ids.index(next_id)
    assert all(bodies[k].scale.x > b.scale.x for i, b in bodies.items() if i != k)
    (ring,) = rings.values()
    pts = ring.points[:-1]  # the strip closes on its first point
    centre = (sum(p.x for p in pts) / len(pts), sum(p.y for p in pts) / len(pts))
    assert math.dist(centre, positions[next_id]) < 1e-9


def path_points(path):
    return [(p.pose.position.x, p.pose.position.y) for p in path.poses]


def length(points):
    return sum(math.dist(a, b) for a, b in zip(points, points[1:]))


def test_markers_and_path_follow_an_in_process_search(start_node, robot, house):
    """Every step's MarkerArray and Path, and the last ones: the searched containers dark and
    crossed, the found one green, the next one larger and ringed, the open ones coloured in the
    order of the strategy's likelihoods; each Path is ferret's leg (from the last container, or
    the start, to the next container's access point; together they measure the trial's cost),
    and an empty one once the search has ended."""
    nav, _, _ = robot
    target = longest_search(house)
    ids = [c.id for c in house.containers]
    positions = {c.id: tuple(c.position) for c in house.containers}
    access = {c.id: tuple(c.access) for c in house.containers}
    likelihoods = dict(zip(ids, ferret.Search(house, target, STRATEGY).likelihoods()))
    assert len(set(likelihoods.values())) > 2  # colours with an order to check
    _, client = start_node("ferret_markers", strategies=[STRATEGY], plan_from_robot_pose=False)
    nav.reset()
    # Slow enough that each step's picture arrives before the next one.
    nav.speed = 10.0
    try:
        _, result, _ = client.send(target)
    finally:
        nav.speed = 200.0
    assert result.status == Status.FOUND, result.message
    searched = list(result.searched_containers)
    assert searched == searched_order(house, target) and len(searched) >= 3
    n = len(searched)
    wait_until(
        lambda: len(client.markers) >= n + 1 and len(client.paths) >= n + 1,
        f"{n + 1} marker arrays and paths (one per step, one at the end)",
    )
    assert (len(client.markers), len(client.paths)) == (n + 1, n + 1)
    for k, next_id in enumerate(searched):
        probs = dict(likelihoods, **{c: 0.0 for c in searched[:k]})
        check_picture(client.markers[k], ids, positions, probs, searched[:k], None, next_id)
        path = client.paths[k]
        assert path.header.frame_id == "map"
        assert {p.header.frame_id for p in path.poses} == {"map"}
        pts = path_points(path)
        assert math.dist(pts[-1], access[next_id]) < 1e-9
        if k == 0:  # the start's cell centre
            assert math.dist(pts[0], house.start[:2]) < 0.05
        else:
            assert math.dist(pts[0], access[searched[k - 1]]) < 1e-9
    legs = [length(path_points(p)) for p in client.paths[:n]]
    assert math.isclose(sum(legs), result.cost_m, abs_tol=1e-6), (legs, result.cost_m)
    probs = dict(likelihoods, **{c: 0.0 for c in searched})
    check_picture(client.markers[n], ids, positions, probs, searched, result.container, None)
    assert client.paths[n].header.frame_id == "map" and list(client.paths[n].poses) == []
    # No destination: nothing of a task's drawn.
    assert all("destination" not in by_ns(m) for m in client.markers)


def test_serve_belief_and_markers_carry_the_trial_view(start_node, robot, house, ferret_serve):
    """With `ferret serve` planning, the belief's probabilities are the server's trial view's
    likelihoods (what its web page shows), finite, during the search and after it; the markers
    are coloured by them, and the Path is the server's `next.path`."""
    nav, _, _ = robot
    target = longest_search(house)
    ids = [c.id for c in house.containers]
    positions = {c.id: tuple(c.position) for c in house.containers}
    access = {c.id: tuple(c.access) for c in house.containers}
    _, client = start_node(
        "ferret_serve_view",
        backend="serve",
        serve_url=ferret_serve,
        serve_scene="apartment",
        strategies=[STRATEGY],
        plan_from_robot_pose=False,
    )
    during = {}

    def while_driving_to_the_first():
        wait_until(lambda: client.beliefs and client.markers and client.paths, "the first step")
        trial = get(ferret_serve + "/deployments/1")["open_trial"]
        during["view"] = get(f"{ferret_serve}/trials/{trial}/view")
        during["belief"] = client.beliefs[-1]
        during["markers"] = client.markers[-1]
        during["path"] = client.paths[-1]
        nav.speed = 200.0  # the rest of the search at full speed

    nav.reset()
    # Slow: the first leg takes a second, time enough to read the view before the robot looks.
    nav.speed = 2.0
    try:
        _, result, _ = client.send(target, while_running=while_driving_to_the_first)
    finally:
        nav.speed = 200.0
    assert result.status == Status.FOUND, result.message

    view, belief = during["view"], during["belief"]
    state = view["trial"]
    assert state["searched"] == [], "the view was read after the first observation"
    first = state["next"]["container"]
    assert first == result.searched_containers[0]
    likelihoods = view["likelihoods"]
    assert likelihoods is not None and set(likelihoods) == set(ids)
    probs = dict(zip(belief.containers, belief.probability))
    assert all(math.isfinite(p) for p in probs.values()), probs
    assert probs == likelihoods
    check_picture(during["markers"], ids, positions, likelihoods, [], None, first)
    path = path_points(during["path"])
    assert during["path"].header.frame_id == "map"
    assert len(path) == len(state["next"]["path"]) > 1
    assert all(math.dist(a, b) < 1e-9 for a, b in zip(path, state["next"]["path"]))
    assert math.dist(path[-1], access[first]) < 1e-9

    # After the search: the last belief is the finished trial's view.
    trial = get(ferret_serve + "/deployments/1")["trials"][0]["trial"]
    end = get(f"{ferret_serve}/trials/{trial}/view")
    assert end["trial"]["status"] == "done"
    wait_until(
        lambda: client.beliefs and 1.0 in list(client.beliefs[-1].probability),
        "the belief of the found target",
    )
    last = client.beliefs[-1]
    probs = dict(zip(last.containers, last.probability))
    assert all(math.isfinite(p) for p in probs.values()), probs
    assert probs == end["likelihoods"]
    assert probs[result.container] == 1.0
    assert all(probs[c] == 0.0 for c in result.searched_containers[:-1])
    wait_until(lambda: list(client.paths[-1].poses) == [], "the empty path at the end")
    searched = list(result.searched_containers)
    check_picture(
        client.markers[-1], ids, positions, end["likelihoods"], searched, result.container, None
    )


def task_search(house, targets, strategy, destination):
    """A task searched by `ferret.Search` with the scene's ground truth: the containers in
    order, where each target was found, the way to the destination and its length."""
    s = ferret.Search(house, targets, strategy, destination=destination)
    while (c := s.next_container()) is not None:
        s.record(c, objects=house.contents(c))
    way = s.path_to_destination()
    leg = s.finish()
    return s, {t: c.id for t, c in s.found_in.items()}, way, leg


def task_belief(rows, ids, searched, found_in, holds):
    """What the belief of a task should say: 1 where a target was found, 0 where searched in
    vain (and everywhere once the goal holds), else 1 - prod(1 - p_t) over the targets still
    wanted (`ferret serve`'s view computes the same)."""
    wanted = [r for t, r in rows.items() if t not in found_in]
    out = {}
    for i, c in enumerate(ids):
        if c in found_in.values():
            out[c] = 1.0
        elif holds or c in searched:
            out[c] = 0.0
        else:
            none = 1.0
            for r in wanted:
                none *= 1.0 - r[i]
            out[c] = 1.0 - none
    return out


def test_markers_and_belief_of_a_task(start_node, robot, house):
    """A task of two targets brought to a room: at each step the belief is the chance that a
    container holds a target still wanted (the targets' own likelihoods combined), the targets
    found are green and labelled with what was found there, the destination is a diamond; once
    the goal holds the path is ferret's way to the destination (its length the result's
    delivery_m), and at the end the path is empty and nothing is wanted."""
    nav, _, _ = robot
    targets, strategy = ["Egg", "Statue"], STRATEGY
    ids = [c.id for c in house.containers]
    s, found_in, way, leg = task_search(house, targets, strategy, "room:bedroom")
    searched = list(s.searched)
    assert len(searched) >= 3 and len(set(found_in.values())) == 2
    rows = {t: s.likelihoods(t) for t in targets}
    _, client = start_node("ferret_task_markers", strategies=[strategy], plan_from_robot_pose=False)
    nav.reset()
    nav.speed = 10.0  # slow enough that each step's picture arrives before the next one
    try:
        goal = SearchObject.Goal(target_types=targets)
        goal.destination_kind = SearchObject.Goal.DESTINATION_ROOM
        goal.destination_id = "bedroom"
        _, result, _ = client.send(goal)
    finally:
        nav.speed = 200.0
    assert result.status == Status.FOUND and result.delivered, result.message
    assert list(result.searched_containers) == searched
    n = len(searched)
    wait_until(
        lambda: len(client.beliefs) >= n + 2 and len(client.markers) >= n + 2,
        f"{n + 2} beliefs and pictures (one per step, one on the way, one at the end)",
    )
    assert (len(client.beliefs), len(client.markers), len(client.paths)) == (n + 2,) * 3
    for k, belief in enumerate(client.beliefs):
        before = searched[: min(k, n)]
        found = {t: c for t, c in found_in.items() if c in before}
        holds = k >= n
        want = task_belief(rows, ids, before, found, holds)
        assert belief.target_type == "Egg+Statue"
        assert list(belief.containers) == ids
        assert all(
            math.isclose(p, want[c], abs_tol=1e-12) for c, p in zip(ids, belief.probability)
        ), (k, list(belief.probability), want)
        assert list(belief.wanted_types) == (
            [] if holds else [t for t in targets if t not in found]
        )
        ns = by_ns(client.markers[k])
        labels, bodies = ns["labels"], ns["containers"]
        for c in set(found.values()):
            i = ids.index(c)
            here = [t for t, at in found.items() if at == c]
            assert labels[i].text.endswith("found " + ", ".join(here)), labels[i].text
            assert bodies[i].color.g > 0.5 > max(bodies[i].color.r, bodies[i].color.b)
        crossed = {ids[i] for i in ns.get("searched", {})}
        assert crossed == {c for c in before if c not in found.values()}
        diamond, label = ns["destination"][0], ns["destination"][1]
        assert math.dist((diamond.pose.position.x, diamond.pose.position.y), s.destination) < 1e-9
        assert label.text == "destination: room bedroom"
        assert ("next" in ns) == (k < n)
    # On the way: ferret's way from the last container to the room, as long as the last leg.
    on_the_way = path_points(client.paths[n])
    assert math.dist(on_the_way[-1], s.destination) < 1e-9
    assert all(math.dist(a, b) < 1e-9 for a, b in zip(on_the_way, way))
    assert math.isclose(length(on_the_way), leg, abs_tol=1e-6)
    assert math.isclose(result.delivery_m, leg, abs_tol=1e-9)
    assert list(client.paths[n + 1].poses) == []


def test_serve_belief_of_a_task_is_the_trial_view(start_node, robot, house, ferret_serve):
    """With `ferret serve`, a task's belief is the view's `likelihoods` (the chance that a
    container holds a target still wanted), which is the targets' own likelihoods combined as
    the in-process node combines them; at the end, 1 where a target was found, and the
    destination drawn where the server says it is."""
    nav, _, _ = robot
    targets = ["Egg", "Statue"]
    ids = [c.id for c in house.containers]
    rows = {t: ferret.Search(house, targets, STRATEGY).likelihoods(t) for t in targets}
    _, client = start_node(
        "ferret_serve_task_view",
        backend="serve",
        serve_url=ferret_serve,
        serve_scene="apartment",
        strategies=[STRATEGY],
        plan_from_robot_pose=False,
    )
    during = {}

    def while_driving_to_the_first():
        wait_until(lambda: client.beliefs and client.markers, "the first step")
        trial = get(ferret_serve + "/deployments/1")["open_trial"]
        during["view"] = get(f"{ferret_serve}/trials/{trial}/view")
        during["belief"] = client.beliefs[-1]
        nav.speed = 200.0

    goal = SearchObject.Goal(target_types=targets)
    goal.destination_kind = SearchObject.Goal.DESTINATION_START
    nav.reset()
    nav.speed = 2.0
    try:
        _, result, _ = client.send(goal, while_running=while_driving_to_the_first)
    finally:
        nav.speed = 200.0
    assert result.status == Status.FOUND and result.delivered, result.message
    view, belief = during["view"], during["belief"]
    assert view["trial"]["searched"] == [], "the view was read after the first observation"
    probs = dict(zip(belief.containers, belief.probability))
    assert probs == view["likelihoods"]
    want = task_belief(rows, ids, [], {}, False)
    assert all(math.isclose(probs[c], want[c], abs_tol=1e-12) for c in ids), (probs, want)
    assert list(belief.wanted_types) == targets

    trial = get(ferret_serve + "/deployments/1")["trials"][0]["trial"]
    end = get(f"{ferret_serve}/trials/{trial}/view")
    wait_until(lambda: list(client.paths[-1].poses) == [], "the empty path at the end")
    last = client.beliefs[-1]
    probs = dict(zip(last.containers, last.probability))
    assert probs == end["likelihoods"]
    found = dict(zip(result.found_targets, result.found_containers))
    assert {c for c, p in probs.items() if p == 1.0} == set(found.values())
    assert all(p == 0.0 for c, p in probs.items() if c not in found.values())
    assert list(last.wanted_types) == []
    diamond = by_ns(client.markers[-1])["destination"][0]
    at = end["trial"]["destination"]["at"]
    assert math.dist((diamond.pose.position.x, diamond.pose.position.y), at) < 1e-9
