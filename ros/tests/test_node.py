"""The ferret node over real DDS against a simulated Nav2 and detector."""

import csv
import dataclasses
import hashlib
import json
import math
import os
import re
import subprocess
import time
import urllib.request

import pytest

import ferret
from conftest import SCENE, STRATEGIES, ferret_bin
from ferret_interfaces.action import SearchObject
from ferret_ros.maps import read_scene_map

Status = SearchObject.Result


def run_ferret(*args):
    out = subprocess.run([ferret_bin(), *args], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return out


def test_finds_every_target_as_ferret_deploy(start_node, robot, house, tmp_path):
    """Every target of the apartment, in one deployment over three strategies: each trial's
    chosen strategy, searched containers, cost and found container are those of `ferret deploy`
    (searched orders from `ferret eval` of the chosen strategy), and the robot really drove to
    each searched container."""
    nav, detector, _ = robot
    targets = house.target_types()
    run_ferret(
        "deploy",
        "--houses",
        str(SCENE),
        "--find",
        ",".join(targets),
        "--strategies",
        ",".join(STRATEGIES),
        "--seed",
        "0",
        "--out",
        str(tmp_path / "deploy"),
    )
    run_ferret(
        "eval",
        "--houses",
        str(SCENE),
        "--strategies",
        ",".join(STRATEGIES),
        "--trials-per-house",
        "all",
        "--out",
        str(tmp_path / "eval"),
    )
    with open(tmp_path / "deploy" / "deploy.csv") as f:
        deployed = list(csv.DictReader(f))
    with open(tmp_path / "eval" / "trials.csv") as f:
        orders = {(r["target"], r["strategy"]): r["searched"].split() for r in csv.DictReader(f)}
    assert [r["target"] for r in deployed] == targets

    # Every trial from the scene's start, as `ferret deploy` runs them.
    _, client = start_node(
        "ferret_deploy", strategies=STRATEGIES, seed=0, plan_from_robot_pose=False
    )
    for row in deployed:
        nav.reset()
        before = len(nav.visited)
        status, result, feedback = client.send(row["target"])
        assert result.status == Status.FOUND, result.message
        assert result.found and status == 4  # GoalStatus.STATUS_SUCCEEDED
        assert result.strategy == row["chosen"], row
        assert result.container == row["found_container"], row
        assert math.isclose(result.cost_m, float(row["cost_m"]), abs_tol=1e-9), (result.cost_m, row)
        assert list(result.searched_containers) == orders[(row["target"], row["chosen"])], row
        assert nav.visited[before:] == list(result.searched_containers)
        # Feedback and result travel apart: the last feedback may land just after the result.
        deadline = time.monotonic() + 5
        while len(feedback) < len(result.searched_containers) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert [fb.next_container for fb in feedback] == list(result.searched_containers)
        assert feedback[-1].searched == len(result.searched_containers) - 1
    # The belief after the last trial: 1 where found, 0 where searched in vain.
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        last = client.beliefs[-1] if client.beliefs else None
        if last is not None and last.target_type == targets[-1] and 1.0 in list(last.probability):
            break
        time.sleep(0.02)
    ids = list(last.containers)
    assert sorted(ids) == sorted(c.id for c in house.containers)
    probs = dict(zip(ids, last.probability))
    assert probs[result.container] == 1.0
    for c in result.searched_containers[:-1]:
        assert probs[c] == 0.0


def test_nav2_abort_ends_the_search(start_node, robot):
    nav, _, _ = robot
    _, client = start_node("ferret_abort", strategies=["model/prior"])
    nav.reset()
    # The second goal of the search fails.
    nav.mode, nav.fail_from = "abort", nav.goals + 2
    try:
        t = time.monotonic()
        status, result, _ = client.send("Wallet")
    finally:
        nav.mode = "ok"
    assert result.status == Status.NAVIGATION_FAILED
    assert not result.found and status == 6  # GoalStatus.STATUS_ABORTED
    assert "aborted" in result.message and "simulated failure" in result.message, result.message
    assert len(result.searched_containers) == 1
    assert time.monotonic() - t < 10


def test_nav2_timeout_cancels_navigation(start_node, robot):
    nav, _, _ = robot
    _, client = start_node("ferret_navtimeout", strategies=["model/prior"], nav_timeout_s=1.0)
    nav.reset()
    nav.mode, nav.fail_from = "hang", nav.goals + 1
    try:
        t = time.monotonic()
        _, result, _ = client.send("Wallet")
        took = time.monotonic() - t
    finally:
        nav.mode = "ok"
    assert result.status == Status.NAVIGATION_FAILED
    assert "timed out after 1 s" in result.message, result.message
    assert result.searched_containers == []
    assert took < 8


def test_silent_detector_ends_the_search(start_node, robot):
    nav, detector, _ = robot
    _, client = start_node("ferret_mute", strategies=["model/prior"], detection_timeout_s=1.0)
    nav.reset()
    detector.muted = True
    try:
        t = time.monotonic()
        _, result, _ = client.send("Wallet")
        took = time.monotonic() - t
    finally:
        detector.muted = False
    assert result.status == Status.DETECTOR_TIMEOUT
    assert "no detection at" in result.message and "within 1 s" in result.message, result.message
    assert took < 8


def test_cancel_stops_the_search(start_node, robot):
    nav, _, _ = robot
    _, client = start_node("ferret_cancel", strategies=["model/prior"])
    nav.reset()
    nav.mode, nav.fail_from = "hang", nav.goals + 1
    try:
        t = time.monotonic()
        second = []
        status, result, _ = client.send(
            "Wallet",
            cancel_after_feedback=True,
            while_running=lambda: second.append(client.try_goal("Apple")),
        )
        took = time.monotonic() - t
    finally:
        nav.mode = "ok"
    assert result.status == Status.CANCELED and status == 5  # GoalStatus.STATUS_CANCELED
    assert took < 8
    assert second == [False]  # a second goal while one runs is rejected
    # The simulated Nav2 saw its goal canceled: the next search runs normally.
    nav.reset()
    _, result, _ = client.send("Wallet")
    assert result.status == Status.FOUND, result.message


def test_map_that_does_not_match_is_refused(start_node, robot):
    _, _, maps = robot
    good = read_scene_map(str(SCENE))
    shifted = dataclasses.replace(good, origin=(good.origin[0] + 1.5, good.origin[1]))
    maps.publish(shifted)
    try:
        proc, client = start_node("ferret_badmap", strategies=["model/prior"])
        _, result, _ = client.send("Wallet")
        assert result.status == Status.REFUSED
        assert result.message.startswith("map refused:"), result.message
        assert "not the scene's map" in result.message, result.message
        assert result.searched_containers == []
        # Nav2 was never asked, and the log says why as soon as the map arrived.
        assert "refusing the map on /map" in proc.text()
        # The right map, published again, is accepted without restarting the node.
        maps.publish(good)
        deadline = time.monotonic() + 10
        while "matches scene" not in proc.text():
            assert time.monotonic() < deadline, proc.text()
            time.sleep(0.05)
        robot[0].reset()
        _, result, _ = client.send("Wallet")
        assert result.status == Status.FOUND, result.message
    finally:
        maps.publish(good)


def test_map_of_another_layout_is_refused(start_node, robot):
    """Same size and origin, but the doorways walled up: the cells disagree."""
    _, _, maps = robot
    good = read_scene_map(str(SCENE))
    walled = list(good.data)
    # Block every free cell in a band along y = 4.5 m (the wall between the two room rows).
    j0 = int((4.2 - good.origin[1]) / good.resolution)
    j1 = int((4.8 - good.origin[1]) / good.resolution)
    for j in range(j0, j1):
        for i in range(good.width):
            walled[j * good.width + i] = 100
    maps.publish(dataclasses.replace(good, data=walled))
    try:
        _, client = start_node("ferret_walled", strategies=["model/prior"])
        _, result, _ = client.send("Wallet")
        assert result.status == Status.REFUSED
        assert "of the cells agree" in result.message, result.message
    finally:
        maps.publish(good)


def test_unknown_scene_and_empty_target_are_refused(start_node, robot):
    _, client = start_node("ferret_refuse", strategies=["model/prior"])
    _, result, _ = client.send("")
    assert result.status == Status.REFUSED and "target_type is empty" in result.message
    goal_scene = SearchObject.Goal(target_type="Wallet", scene="another-house")
    sent = client.action.send_goal_async(goal_scene)
    deadline = time.monotonic() + 30
    while not sent.done():
        assert time.monotonic() < deadline
        time.sleep(0.01)
    res = sent.result().get_result_async()
    while not res.done():
        assert time.monotonic() < deadline
        time.sleep(0.01)
    r = res.result().result
    assert r.status == Status.REFUSED and "another-house" in r.message, r.message


def test_unknown_target_is_refused_with_the_known_name(start_node, robot, house):
    nav, _, _ = robot
    nav.reset()
    _, client = start_node("ferret_vocabulary", strategies=["model/prior"])
    # The detector's names are CamelCase; a name that differs only in case or spacing is refused
    # at once with the one it most likely meant, before any container is searched.
    for asked, meant in [("wallet", "Wallet"), ("remote control", "RemoteControl")]:
        _, result, feedback = client.send(asked)
        assert result.status == Status.REFUSED, result.message
        assert result.message == f"unknown target {asked!r}: did you mean {meant!r}?"
        assert not feedback and not result.searched_containers
    # Nothing close: the scene's object types are listed.
    _, result, _ = client.send("Spaceship")
    types = sorted({o.type for o in house.objects})
    assert result.status == Status.REFUSED
    assert result.message == (
        f"unknown target 'Spaceship': scene 'apartment' holds {len(types)} object types: "
        + ", ".join(types)
    )
    # The same node still searches for a name it knows.
    _, result, _ = client.send("Wallet")
    assert result.status == Status.FOUND, result.message


def searches_as_deployed(client, nav, rows):
    """Each row's target searched through the node: the strategy chosen, the container it was
    found in and the cost are those of `ferret deploy`'s row."""
    for row in rows:
        nav.reset()
        _, result, _ = client.send(row["target"])
        assert result.status == Status.FOUND, result.message
        assert (result.strategy, result.container) == (row["chosen"], row["found_container"])
        assert math.isclose(result.cost_m, float(row["cost_m"]), abs_tol=1e-9)


def deploy_rows(tmp_path, targets):
    run_ferret(
        "deploy",
        "--houses",
        str(SCENE),
        "--find",
        ",".join(targets),
        "--strategies",
        ",".join(STRATEGIES),
        "--seed",
        "0",
        "--out",
        str(tmp_path / "deploy"),
    )
    with open(tmp_path / "deploy" / "deploy.csv") as f:
        return list(csv.DictReader(f))


# A word table small enough to write here: kitchen, bedroom and bathroom words pointing different
# ways, so the learned heads have meaning to learn from (names with no word get a zero vector).
WORDS = {
    "kitchen": (1.0, 0.0, 0.0, 0.1),
    "fridge": (0.9, 0.1, 0.0, 0.0),
    "counter": (0.8, 0.0, 0.1, 0.2),
    "cabinet": (0.6, 0.3, 0.2, 0.0),
    "bedroom": (0.0, 1.0, 0.0, 0.1),
    "bed": (0.1, 0.9, 0.0, 0.0),
    "dresser": (0.0, 0.8, 0.1, 0.2),
    "bathroom": (0.0, 0.0, 1.0, 0.1),
    "toilet": (0.1, 0.0, 0.9, 0.0),
    "sink": (0.4, 0.0, 0.7, 0.0),
    "living": (0.2, 0.2, 0.0, 1.0),
    "sofa": (0.0, 0.3, 0.0, 0.9),
    "table": (0.5, 0.1, 0.0, 0.6),
    "desk": (0.3, 0.6, 0.0, 0.4),
}


def test_learned_likelihood_reaches_the_node(start_node, robot, house, tmp_path, monkeypatch):
    """A prior with a learned part (`ferret prior train --embeddings`: word vectors and heads)
    as the node's `prior`: its searches with model/learned are those of `ferret deploy` with the
    same file, the names the file lacks (the apartment's, never in its training houses) embedded
    through FERRET_EMBEDDINGS in the node as in the binary."""
    nav, _, _ = robot
    table = tmp_path / "words"
    table.mkdir()
    # A name with no known word is refused: every other word of the generator's names and the
    # apartment's gets a small fixed vector on a fifth axis of its own.
    words = {w: (*v, 0.0) for w, v in WORDS.items()}
    houses = ferret.generate_houses(200, 0) + ferret.load_houses(SCENE)
    names = {c.type for h in houses for c in h.containers}
    names |= {c.room_type for h in houses for c in h.containers if c.room_type}
    names |= {o.type for h in houses for o in h.objects}
    for name in sorted(names):
        for w in (m.lower() for m in re.findall(r"[A-Z]+(?![a-z])|[A-Z]?[a-z]+", name)):
            if w not in words:
                d = hashlib.sha256(w.encode()).digest()
                words[w] = (d[0] / 2550, d[1] / 2550, d[2] / 2550, d[3] / 2550, 1.0)
    lines = [f"{w} {' '.join(map(str, v))}" for w, v in words.items()]
    (table / "vectors.txt").write_text("# id: tiny\n" + "\n".join(lines) + "\n")
    prior = tmp_path / "learned.json"
    run_ferret(
        "prior",
        "train",
        "--generate",
        "30",
        "--house-seed",
        "9",
        "--embeddings",
        str(table),
        "--learned-folds",
        "3",
        "--learned-epochs",
        "10",
        "--out",
        str(prior),
    )
    strategies = ["model/learned", "model/prior"]
    targets = house.target_types()[:4]
    # Without the embeddings the node cannot answer for the apartment's names: it stops at once,
    # saying which name and what to give.
    from conftest import FerretProcess

    monkeypatch.delenv("FERRET_EMBEDDINGS", raising=False)
    p = FerretProcess(
        tmp_path,
        "ferret_learned_blind",
        {"scene": str(SCENE), "strategies": ["model/learned"], "prior": str(prior)},
    )
    try:
        assert p.proc.wait(30) == 1
    finally:
        p.stop()
    said = p.text()
    assert "[FATAL]" in said and "FERRET_EMBEDDINGS" in said and "no word vector for" in said, said
    monkeypatch.setenv("FERRET_EMBEDDINGS", str(table))
    run_ferret(
        "deploy",
        "--houses",
        str(SCENE),
        "--find",
        ",".join(targets),
        "--prior",
        str(prior),
        "--strategies",
        ",".join(strategies),
        "--seed",
        "0",
        "--out",
        str(tmp_path / "deploy"),
    )
    with open(tmp_path / "deploy" / "deploy.csv") as f:
        rows = list(csv.DictReader(f))
    assert "model/learned" in {r["chosen"] for r in rows}
    _, client = start_node(
        "ferret_learned",
        strategies=strategies,
        prior=str(prior),
        seed=0,
        plan_from_robot_pose=False,
    )
    searches_as_deployed(client, nav, rows)


def test_without_nav2_goals_go_to_goal_pose(start_node, robot, house, tmp_path):
    """No NavigateToPose server: the node publishes /goal_pose and waits for /amcl_pose to get
    there; the search is the same one."""
    nav, _, _ = robot
    targets = house.target_types()[:3]
    rows = deploy_rows(tmp_path, targets)
    _, client = start_node(
        "ferret_goalpose",
        strategies=STRATEGIES,
        seed=0,
        nav_action="no_nav2_here",
        nav_server_wait_s=0.2,
        nav_timeout_s=10.0,
        plan_from_robot_pose=False,
    )
    for row in rows:
        nav.reset()
        before = len(nav.visited)
        _, result, _ = client.send(row["target"])
        assert result.status == Status.FOUND, result.message
        assert (result.strategy, result.container) == (row["chosen"], row["found_container"])
        assert math.isclose(result.cost_m, float(row["cost_m"]), abs_tol=1e-9)
        assert nav.visited[before:] == list(result.searched_containers)


def test_goal_pose_fallback_times_out_when_the_robot_never_arrives(start_node, robot):
    nav, _, _ = robot
    _, client = start_node(
        "ferret_goalpose_stuck",
        strategies=["model/prior"],
        nav_action="no_nav2_here",
        nav_server_wait_s=0.2,
        nav_timeout_s=1.0,
    )
    nav.reset()
    nav.mode, nav.fail_from = "hang", nav.goals + 1  # it ignores /goal_pose too
    try:
        _, result, _ = client.send("Wallet")
    finally:
        nav.mode = "ok"
    assert result.status == Status.NAVIGATION_FAILED
    assert "did not reach" in result.message and "/goal_pose" in result.message, result.message


def test_serve_backend_makes_the_same_searches(start_node, robot, house, ferret_serve, tmp_path):
    """Planning and selection in `ferret serve` (a fleet's server): the same trials as
    `ferret deploy`, and the server holds them afterwards, each naming the robot (the node's
    name, as it runs in no namespace)."""
    nav, _, _ = robot
    targets = house.target_types()[:4]
    rows = deploy_rows(tmp_path, targets)
    _, client = start_node(
        "ferret_serve_backend",
        backend="serve",
        serve_url=ferret_serve,
        serve_scene="apartment",
        strategies=STRATEGIES,
        seed=0,
        plan_from_robot_pose=False,
    )
    searches_as_deployed(client, nav, rows)
    with urllib.request.urlopen(ferret_serve + "/deployments/1", timeout=5) as r:
        state = json.loads(r.read())
    assert [t["target"] for t in state["trials"]] == targets
    assert [t["strategy"] for t in state["trials"]] == [r["chosen"] for r in rows]
    assert [t["robot"] for t in state["trials"]] == ["ferret_serve_backend"] * len(targets)


def test_a_failed_search_is_abandoned_on_the_server(start_node, robot, ferret_serve):
    """Navigation fails in the middle of a serve-backed search: the node ends the trial on the
    server as abandoned instead of leaving it open, and the next search starts a trial of its
    own."""
    nav, _, _ = robot
    _, client = start_node(
        "ferret_serve_abandon",
        backend="serve",
        serve_url=ferret_serve,
        serve_scene="apartment",
        strategies=STRATEGIES,
        seed=0,
        plan_from_robot_pose=False,
    )
    nav.reset()
    nav.mode, nav.fail_from = "abort", nav.goals + 2
    try:
        _, result, _ = client.send("Wallet")
    finally:
        nav.mode = "ok"
    assert result.status == Status.NAVIGATION_FAILED, result.message
    with urllib.request.urlopen(ferret_serve + "/deployments/1", timeout=5) as r:
        state = json.loads(r.read())
    assert [t["status"] for t in state["trials"]] == ["abandoned"], state
    assert state["open_trials"] == []
    _, again, _ = client.send("Wallet")
    assert again.found, again.message
    with urllib.request.urlopen(ferret_serve + "/deployments/1", timeout=5) as r:
        state = json.loads(r.read())
    assert [t["status"] for t in state["trials"]] == ["abandoned", "done"], state


def test_trials_start_where_the_robot_is(start_node, robot, house, ferret_serve):
    """Without going back to the start between searches, each trial plans from the robot's
    pose (/amcl_pose): the node's own placing of the scene at that pose gives the searches that
    `ferret serve` gives for trials opened with the same pose."""
    nav, _, _ = robot
    targets = ["AlarmClock", "RemoteControl", "Apple", "Wallet"]
    runs = {}
    for backend in ("python", "serve"):
        nav.reset()
        params = dict(strategies=STRATEGIES, seed=0)
        if backend == "serve":
            params.update(backend="serve", serve_url=ferret_serve, serve_scene="apartment")
        _, client = start_node(f"ferret_pose_{backend}", **params)
        runs[backend] = []
        for target in targets:
            _, r, _ = client.send(target)
            assert r.status == Status.FOUND, r.message
            runs[backend].append((r.strategy, list(r.searched_containers), round(r.cost_m, 9)))
    assert runs["python"] == runs["serve"]
    # The second search set off from the AlarmClock's dresser, not from the start.
    strategy, searched, cost = runs["python"][1]
    from_start = ferret.Search(house, targets[1], strategy)
    while (c := from_start.next_container()) is not None:
        seen = house.contents(c)
        from_start.record(c, targets[1] in seen, seen)
    assert runs["python"][0][1][-1] == "dresser"
    assert cost != round(from_start.cost, 9)


@pytest.mark.parametrize(
    "params,message",
    [
        ({"scene": "no-such-scene.yaml"}, "no-such-scene.yaml: No such file or directory"),
        (
            {"scene": "no-such-scene.yaml"},
            f"a relative path is read from the current directory, {os.getcwd()}: "
            f"{os.path.join(os.getcwd(), 'no-such-scene.yaml')} does not exist",
        ),
        ({"strategies": ["model/bogus"]}, "unknown strategy `model/bogus`"),
        ({"backend": "ros1"}, "parameter `backend`: 'ros1'"),
        ({"backend": "serve"}, "parameter `serve_url`"),
    ],
)
def test_bad_parameters_stop_the_node_with_a_reason(ros, tmp_path, params, message):
    from conftest import FerretProcess

    params.setdefault("scene", str(SCENE))
    p = FerretProcess(tmp_path, "ferret_badparams", params)
    try:
        assert p.proc.wait(30) == 1
    finally:
        p.stop()
    assert "[FATAL]" in p.text() and message in p.text(), p.text()
