"""Household tasks through the node: several targets, all or any of them, brought to a
destination, over real DDS against the simulated Nav2 and detector, compared with `ferret deploy
--find` and `ferret.Search` on the same house and strategies."""

import csv
import json
import math
import subprocess
import time
import urllib.request

import pytest

import ferret
from conftest import SCENE, STRATEGIES, ferret_bin
from ferret_interfaces.action import SearchObject
from ferret_ros import tasks as node_tasks
from ferret_ros.find import goal_of
from ferret_ros.tasks import parse_task

Status = SearchObject.Result
Goal = SearchObject.Goal

# Tasks of 2 and 3 targets, every one of them brought to where the robot started.
ALL_TO_START = [
    "Mug+Wallet+Pillow@start",
    "Egg+Statue@start",
    "Pillow+Blanket@start",  # one container holds both: opening it finds both
    "RemoteControl+KeyChain@start",
]
# Any one of two, with each kind of destination `ferret deploy --find` takes, and none.
ANY = ["Apple|Book", "Vase|Egg@container:sofa", "Statue|Laptop@room:kitchen"]


def run_ferret(*args):
    out = subprocess.run([ferret_bin(), *args], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    return out


def deploy(tmp_path, tasks, strategies=STRATEGIES):
    """`ferret deploy --find` of `tasks` in the apartment: its rows."""
    run_ferret(
        "deploy",
        "--houses",
        str(SCENE),
        "--find",
        ",".join(tasks),
        "--strategies",
        ",".join(strategies),
        "--seed",
        "0",
        "--out",
        str(tmp_path / "deploy"),
    )
    with open(tmp_path / "deploy" / "deploy.csv") as f:
        rows = list(csv.DictReader(f))
    assert [r["target"] for r in rows] == [parse_task(t).label for t in tasks]
    return rows


def simulate(house, text, strategy):
    """`text`'s task searched by `ferret.Search` with `strategy`, every container showing what
    the scene says it holds: (the finished search, its last leg, the way to the destination)."""
    task = parse_task(text)
    dest = task.destination.for_python() if task.destination is not None else None
    s = ferret.Search(house, list(task.targets), strategy, goal=task.goal, destination=dest)
    while (c := s.next_container()) is not None:
        s.record(c, objects=house.contents(c))
    way = s.path_to_destination()
    leg = s.finish()
    return s, leg, way


def replays_said(row):
    """The replays of a deploy.csv row as the node's result message says them."""
    pairs = (r.split("=") for r in row["replays"].split())
    return "replays " + ", ".join(f"{k} {v} m" for k, v in pairs)


def wait_for(feedback, n, timeout=5.0):
    # Feedback and result travel apart: the last feedback may land just after the result.
    deadline = time.monotonic() + timeout
    while len(feedback) < n and time.monotonic() < deadline:
        time.sleep(0.01)


def check_as_deployed(house, nav, text, row, result, feedback, goals_before):
    """One task's result against `ferret deploy`'s row (the strategy chosen, the cost, where
    the goal came to hold, the replays) and against `ferret.Search` with the chosen strategy
    (the containers searched, where each target was found, the way to the destination); the
    robot was sent to each searched container and then to the destination, and nowhere else."""
    task = parse_task(text)
    assert result.status == Status.FOUND, result.message
    assert result.found
    assert result.strategy == row["chosen"], (text, row)
    assert math.isclose(result.cost_m, float(row["cost_m"]), abs_tol=1e-9), (result.cost_m, row)
    assert result.container == row["found_container"], (text, row)
    assert replays_said(row) in result.message, (result.message, row)
    s, leg, _ = simulate(house, text, row["chosen"])
    assert math.isclose(result.cost_m, s.cost, abs_tol=1e-9)
    assert list(result.searched_containers) == s.searched
    found = dict(zip(result.found_targets, result.found_containers))
    assert found == {t: c.id for t, c in s.found_in.items()}
    assert len(result.found_targets) == len(result.found_containers)
    if task.goal == "all":
        assert list(result.found_targets) == list(task.targets)
    else:
        assert set(result.found_targets) & set(task.targets)
    goals = nav.goal_points[goals_before:]
    expected = [house.container_by_id(c).access for c in s.searched]
    if task.destination is not None:
        assert result.delivered
        assert math.isclose(result.delivery_m, leg, abs_tol=1e-9)
        assert leg > 0
        expected.append(s.destination)
        # The robot's last Nav2 goal is the destination.
        assert math.dist(goals[-1], s.destination) < 1e-9, (goals[-1], s.destination)
    else:
        assert not result.delivered and result.delivery_m == 0.0
    assert len(goals) == len(expected), (goals, expected)
    assert all(math.dist(g, e) < 1e-9 for g, e in zip(goals, expected)), (goals, expected)
    # Feedback: one per container, then (with a destination) one on the way there, naming
    # every target found.
    steps = len(s.searched) + (task.destination is not None)
    wait_for(feedback, steps)
    assert [fb.next_container for fb in feedback[: len(s.searched)]] == s.searched
    assert [fb.delivering for fb in feedback] == [False] * len(s.searched) + [True] * (
        steps - len(s.searched)
    )
    if task.destination is not None:
        last = feedback[-1]
        p = last.next_pose.pose.position
        assert math.dist((p.x, p.y), s.destination) < 1e-9
        assert dict(zip(last.found_targets, last.found_containers)) == found
        assert math.isclose(last.travelled_m, s.cost - leg, abs_tol=1e-9)
    # What was found by each step: the targets of the containers searched before it.
    for k, fb in enumerate(feedback[: len(s.searched)]):
        before = set(s.searched[:k])
        assert set(fb.found_targets) == {t for t, c in found.items() if c in before}


def test_all_task_brought_to_the_start_as_ferret_deploy(start_node, robot, house, tmp_path):
    """Tasks of 2 and 3 targets, all of them brought to the start, in one deployment over three
    strategies: each ends FOUND with every target found, the robot's last Nav2 goal the start,
    and the strategy chosen, cost, replays and searches are those of `ferret deploy --find
    'A+B@start'` and `ferret.Search`. The robot is not taken back between tasks: each starts
    where the last brought its finds."""
    nav, _, _ = robot
    rows = deploy(tmp_path, ALL_TO_START)
    _, client = start_node("ferret_tasks_all", strategies=STRATEGIES, seed=0)
    nav.reset()
    for text, row in zip(ALL_TO_START, rows):
        before = len(nav.goal_points)
        status, result, feedback = client.send(goal_of(text))
        assert status == 4  # GoalStatus.STATUS_SUCCEEDED
        check_as_deployed(house, nav, text, row, result, feedback, before)
        assert "brought them to the start" in result.message, result.message


def test_any_task_as_ferret_deploy(start_node, robot, house, tmp_path):
    """`any` tasks: the search ends as soon as one of the targets is found, then brings it to a
    container, a room or nowhere, as `ferret deploy --find 'A|B@...'` does."""
    nav, _, _ = robot
    rows = deploy(tmp_path, ANY)
    _, client = start_node(
        "ferret_tasks_any", strategies=STRATEGIES, seed=0, plan_from_robot_pose=False
    )
    for text, row in zip(ANY, rows):
        nav.reset()
        before = len(nav.goal_points)
        _, result, feedback = client.send(goal_of(text))
        check_as_deployed(house, nav, text, row, result, feedback, before)
        assert len(result.found_targets) == 1, result.found_targets


def test_task_to_a_point_as_ferret_search(start_node, robot, house):
    """A destination given as a pose in the map frame: the robot goes to the reachable point
    nearest it, as `ferret.Search(destination=(x, y))` says."""
    nav, _, _ = robot
    _, client = start_node("ferret_tasks_point", strategies=["model/prior"])
    nav.reset()
    goal = Goal(target_types=["Laptop", "Pillow"])
    goal.destination_kind = Goal.DESTINATION_POSE
    goal.destination_pose.header.frame_id = "map"
    goal.destination_pose.pose.position.x, goal.destination_pose.pose.position.y = 6.0, 2.5
    goal.destination_pose.pose.orientation.z = math.sin(math.pi / 4)  # facing +y
    goal.destination_pose.pose.orientation.w = math.cos(math.pi / 4)
    _, result, _ = client.send(goal)
    s, leg, _ = simulate(house, "Laptop+Pillow@6.0,2.5", "model/prior")
    assert result.status == Status.FOUND, result.message
    assert list(result.searched_containers) == s.searched
    assert math.isclose(result.cost_m, s.cost, abs_tol=1e-9)
    assert result.delivered and math.isclose(result.delivery_m, leg, abs_tol=1e-9)
    assert math.dist(nav.goal_points[-1], s.destination) < 1e-9
    assert math.dist(nav.position, s.destination) < 1e-9  # the simulated robot got there


def bad_goals():
    """(goal, the start of the message refusing it)."""
    out = []

    def goal(**kw):
        g = Goal()
        for k, v in kw.items():
            setattr(g, k, v)
        return g

    out.append(
        (goal(target_types=["Mug", "Apple", "Mug"]), "target_types[2]: 'Mug' is given twice")
    )
    out.append(
        (
            goal(target_types=["Mug", "Apple", "Book", "Vase", "Egg"]),
            "target_types: 5 targets; a task takes 1 to 4",
        )
    )
    out.append(
        (
            goal(target_types=["Mug", "wallet"]),
            "target_types[1]: unknown target 'wallet': did you mean 'Wallet'?",
        )
    )
    out.append(
        (
            goal(target_types=["Mug", "Spaceship"]),
            "target_types[1]: unknown target 'Spaceship': scene 'apartment' holds 17 object types",
        )
    )
    out.append(
        (goal(target_type="Mug", target_types=["Apple"]), "target_type and target_types: give one")
    )
    out.append((goal(target_types=["Mug", ""]), "target_types[1] is empty"))
    out.append(
        (
            goal(target_types=["Mug", "Apple"], goal_kind=2),
            "goal_kind: 2; expected GOAL_ALL (0) or GOAL_ANY (1)",
        )
    )
    out.append((goal(target_types=["Mug", "Apple"], destination_kind=9), "destination_kind: 9;"))
    out.append(
        (
            goal(
                target_types=["Mug", "Apple"],
                destination_kind=Goal.DESTINATION_CONTAINER,
                destination_id="garage",
            ),
            "destination_id: scene 'apartment' has no container 'garage'",
        )
    )
    out.append(
        (
            goal(
                target_types=["Mug", "Apple"],
                destination_kind=Goal.DESTINATION_ROOM,
                destination_id="Bedroom",
            ),
            "destination_id: scene 'apartment' has no room 'Bedroom': did you mean 'bedroom'?",
        )
    )
    out.append(
        (
            goal(target_types=["Mug", "Apple"], destination_id="sofa"),
            "destination_id: 'sofa' with destination_kind DESTINATION_NONE",
        )
    )
    far = goal(target_types=["Mug", "Apple"], destination_kind=Goal.DESTINATION_POSE)
    far.destination_pose.header.frame_id = "map"
    far.destination_pose.pose.position.x = far.destination_pose.pose.position.y = 50.0
    out.append((far, "destination_pose: apartment: (50, 50) is not on floor the robot can reach"))
    odom = goal(target_types=["Mug", "Apple"], destination_kind=Goal.DESTINATION_POSE)
    odom.destination_pose.header.frame_id = "odom"
    out.append((odom, "destination_pose.header.frame_id: 'odom'; the node plans in the map frame"))
    return out


@pytest.mark.parametrize("backend", ["python", "serve"])
def test_bad_task_goals_are_refused_naming_the_field(start_node, robot, request, backend):
    """Every bad task is refused (REFUSED, the action aborted) with a message naming the goal's
    field, before the robot is sent anywhere; the same node then runs a good task."""
    nav, _, _ = robot
    params = dict(strategies=STRATEGIES, seed=0, plan_from_robot_pose=False)
    if backend == "serve":
        ferret_serve = request.getfixturevalue("ferret_serve")
        params.update(backend="serve", serve_url=ferret_serve, serve_scene="apartment")
    _, client = start_node(f"ferret_tasks_refuse_{backend}", **params)
    nav.reset()
    goals_before = nav.goals
    for goal, message in bad_goals():
        status, result, feedback = client.send(goal)
        assert result.status == Status.REFUSED, (message, result.message)
        assert status == 6  # GoalStatus.STATUS_ABORTED
        assert result.message.startswith(message), (message, result.message)
        assert not feedback and not result.searched_containers and not result.found
    assert nav.goals == goals_before  # nothing was driven
    if backend == "serve":
        # The server stored no trial for them.
        with urllib.request.urlopen(ferret_serve + "/deployments", timeout=5) as r:
            assert all(d["trials"] == 0 for d in json.loads(r.read())), "a refused task was stored"
    _, result, _ = client.send(goal_of("Mug+Apple@start"))
    assert result.status == Status.FOUND, result.message


def test_serve_backend_runs_the_same_tasks(start_node, robot, house, ferret_serve, tmp_path):
    """With `ferret serve` planning: the same tasks give the same choices, costs, searches and
    destinations as `ferret deploy --find` and `ferret.Search`, and the server holds each
    trial's task, where each target was found and the way to the destination."""
    nav, _, _ = robot
    tasks = ALL_TO_START[1:3] + ANY
    rows = deploy(tmp_path, tasks)
    _, client = start_node(
        "ferret_tasks_serve",
        backend="serve",
        serve_url=ferret_serve,
        serve_scene="apartment",
        strategies=STRATEGIES,
        seed=0,
        plan_from_robot_pose=False,
    )
    results = []
    for text, row in zip(tasks, rows):
        nav.reset()
        before = len(nav.goal_points)
        _, result, feedback = client.send(goal_of(text))
        check_as_deployed(house, nav, text, row, result, feedback, before)
        results.append(result)
    with urllib.request.urlopen(ferret_serve + "/deployments/1", timeout=5) as r:
        trials = json.loads(r.read())["trials"]
    assert [t["status"] for t in trials] == ["done"] * len(tasks)
    for text, t, result in zip(tasks, trials, results):
        with urllib.request.urlopen(f"{ferret_serve}/trials/{t['trial']}", timeout=5) as r:
            state = json.loads(r.read())
        task = parse_task(text)
        assert (state["targets"], state["goal"]) == (list(task.targets), task.goal)
        assert state["found_in"] == dict(zip(result.found_targets, result.found_containers))
        d = state["destination"]
        if task.destination is None:
            assert d is None
        else:
            assert d["kind"] == task.destination.kind
            assert math.isclose(d["distance_m"], result.delivery_m, abs_tol=1e-9)


def fail_the_delivery(nav, house, text, strategy):
    """Makes the simulated Nav2 abort the goal after the task's last container: the one to
    the destination."""
    s, _, _ = simulate(house, text, strategy)
    nav.mode, nav.fail_from = "abort", nav.goals + len(s.searched) + 1
    return s


def test_nav2_failing_on_the_way_to_the_destination_is_reported(start_node, robot, house, tmp_path):
    """Nav2 aborts the goal to the destination: the result says the search was done and the
    robot did not get there (DELIVERY_FAILED, the action aborted), with every target found and
    the trial's cost; the deployment learnt from the search all the same, so the next search's
    strategy is the one `ferret deploy` chose after it (model/prior after this task; alone, as a
    first trial, CellPhone would get model/uniform)."""
    nav, _, _ = robot
    tasks = ["Egg+Statue@start", "CellPhone"]
    rows = deploy(tmp_path, tasks)
    assert rows[1]["chosen"] != deploy(tmp_path / "alone", tasks[1:])[0]["chosen"]
    _, client = start_node(
        "ferret_tasks_undelivered", strategies=STRATEGIES, seed=0, plan_from_robot_pose=False
    )
    nav.reset()
    s = fail_the_delivery(nav, house, tasks[0], rows[0]["chosen"])
    try:
        t = time.monotonic()
        status, result, _ = client.send(goal_of(tasks[0]))
    finally:
        nav.mode = "ok"
    assert result.status == Status.DELIVERY_FAILED, result.message
    assert status == 6  # GoalStatus.STATUS_ABORTED
    assert result.found and not result.delivered
    assert list(result.found_targets) == ["Egg", "Statue"]
    assert list(result.searched_containers) == s.searched
    assert math.isclose(result.cost_m, float(rows[0]["cost_m"]), abs_tol=1e-9)
    assert "the search is done, but the robot did not reach the start" in result.message
    assert "simulated failure" in result.message, result.message
    assert time.monotonic() - t < 20
    nav.reset()
    _, result, _ = client.send(goal_of(tasks[1]))
    assert result.status == Status.FOUND, result.message
    assert (result.strategy, result.container) == (rows[1]["chosen"], rows[1]["found_container"])
    assert math.isclose(result.cost_m, float(rows[1]["cost_m"]), abs_tol=1e-9)


def test_serve_keeps_the_trial_when_the_delivery_fails(start_node, robot, house, ferret_serve):
    """With `ferret serve`, a delivery that fails leaves the server's trial done (its goal held,
    the deployment learnt from it), not abandoned."""
    nav, _, _ = robot
    text = "Egg+Statue@room:bedroom"
    _, client = start_node(
        "ferret_tasks_serve_undelivered",
        backend="serve",
        serve_url=ferret_serve,
        serve_scene="apartment",
        strategies=["model/prior"],
        plan_from_robot_pose=False,
    )
    nav.reset()
    s = fail_the_delivery(nav, house, text, "model/prior")
    try:
        _, result, _ = client.send(goal_of(text))
    finally:
        nav.mode = "ok"
    assert result.status == Status.DELIVERY_FAILED, result.message
    assert "did not reach room bedroom" in result.message, result.message
    with urllib.request.urlopen(ferret_serve + "/deployments/1", timeout=5) as r:
        state = json.loads(r.read())
    (trial,) = state["trials"]
    assert trial["status"] == "done" and state["open_trials"] == [], state
    assert math.isclose(trial["cost_m"], s.cost, abs_tol=1e-9)
    assert math.isclose(result.cost_m, s.cost, abs_tol=1e-9)


def test_cancel_on_the_way_to_the_destination(start_node, robot, house):
    """Canceled while it brings what it found: CANCELED, the goal held (`found`), not
    delivered; Nav2's goal is canceled, and the next task runs."""
    nav, _, _ = robot
    text = "Egg+Statue@start"
    _, client = start_node("ferret_tasks_cancel", strategies=["model/prior"])
    nav.reset()
    s, _, _ = simulate(house, text, "model/prior")
    nav.mode, nav.fail_from = "hang", nav.goals + len(s.searched) + 1
    seen = []

    def cancel_once_delivering():
        deadline = time.monotonic() + 20
        while not any(fb.delivering for fb in seen):
            assert time.monotonic() < deadline, "never on the way to the destination"
            time.sleep(0.01)

    try:
        sent = client.action.send_goal_async(
            goal_of(text), feedback_callback=lambda m: seen.append(m.feedback)
        )
        deadline = time.monotonic() + 30
        while not sent.done():
            assert time.monotonic() < deadline, "the goal was not answered"
            time.sleep(0.01)
        handle = sent.result()
        cancel_once_delivering()
        handle.cancel_goal_async()
        res = handle.get_result_async()
        while not res.done():
            assert time.monotonic() < deadline, "no result after the cancel"
            time.sleep(0.01)
    finally:
        nav.mode = "ok"
    status, result = res.result().status, res.result().result
    assert result.status == Status.CANCELED and status == 5, result.message  # STATUS_CANCELED
    assert result.found and not result.delivered
    assert result.message.startswith("canceled on the way to the start, the search done")
    assert list(result.searched_containers) == s.searched
    nav.reset()
    _, result, _ = client.send(goal_of(text))
    assert result.status == Status.FOUND and result.delivered, result.message


def test_find_client_reads_tasks():
    """`python -m ferret_ros.find 'Mug+Apple@room:kitchen'` makes the goal a client would."""
    g = goal_of("Mug+Apple@room:kitchen")
    assert (list(g.target_types), g.target_type, g.goal_kind) == (["Mug", "Apple"], "", 0)
    assert (g.destination_kind, g.destination_id) == (Goal.DESTINATION_ROOM, "kitchen")
    g = goal_of("Mug|Cup@1.5,2")
    assert g.goal_kind == Goal.GOAL_ANY and g.destination_kind == Goal.DESTINATION_POSE
    p = g.destination_pose
    assert (p.header.frame_id, p.pose.position.x, p.pose.position.y) == ("map", 1.5, 2.0)
    g = goal_of("Wallet")
    assert (g.target_type, list(g.target_types)) == ("Wallet", [])
    with pytest.raises(ValueError, match="not both"):
        goal_of("Mug+Apple|Cup")
    # The node's constants are the action's.
    assert (node_tasks.GOAL_ALL, node_tasks.GOAL_ANY) == (Goal.GOAL_ALL, Goal.GOAL_ANY)
    kinds = ["NONE", "START", "CONTAINER", "ROOM", "POSE"]
    assert [getattr(node_tasks, "DESTINATION_" + k) for k in kinds] == [
        getattr(Goal, "DESTINATION_" + k) for k in kinds
    ]
