"""Several ferret nodes, one per robot namespace, search one trial together on `ferret serve`:
each robot has its own simulated Nav2 and detector (/r1/navigate_to_pose, /r1/detections,
/r1/amcl_pose, ...), names itself by its namespace, and is sent only where no teammate is
going. Real DDS and a real server on 127.0.0.1."""

import json
import threading
import urllib.request

from conftest import SCENE, FerretProcess, Spinner
from ferret_interfaces.action import SearchObject
from ferret_ros.sim import SimDetector, SimNav2

TEAM = ["r1", "r2", "r3"]


def get(url):
    with urllib.request.urlopen(url, timeout=10) as r:
        return json.loads(r.read())


def post(url, body):
    req = urllib.request.Request(
        url, data=json.dumps(body).encode(), headers={"Content-Type": "application/json"}
    )
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read())


def test_robots_in_namespaces_search_one_trial_together(start_node, house, ferret_serve):
    # Each robot's own simulation, slow enough (20 m/s) that their searches overlap.
    sims = []
    for ns in TEAM:
        sims += [SimNav2(house, speed=20.0, namespace=ns), SimDetector(house, namespace=ns)]
    spin = Spinner(*sims, threads=6)
    try:
        dep = post(ferret_serve + "/deployments", {"strategies": ["model/prior"]})["id"]
        clients = []
        for ns in TEAM:
            _, c = start_node(
                "ferret",
                namespace=ns,
                backend="serve",
                serve_url=ferret_serve,
                serve_scene="apartment",
                serve_team=[f"/{r}" for r in TEAM],
                robot_pose_topic="amcl_pose",
            )
            clients.append(c)
        visits = {f"/{ns}": 0 for ns in TEAM}
        for target in ["Wallet", "CellPhone"]:
            results = {}

            def search(ns, c, target=target):
                goal = SearchObject.Goal(target_type=target, deployment_id=dep)
                results[ns] = c.send(goal)

            threads = [
                threading.Thread(target=search, args=(ns, c)) for ns, c in zip(TEAM, clients)
            ]
            for t in threads:
                t.start()
            for t in threads:
                t.join(90)
            assert set(results) == set(TEAM), results
            for ns, (_, result, _) in results.items():
                assert result.status == SearchObject.Result.FOUND, (ns, result.message)
                assert result.found
            # The server's trial: the three robots by their namespaces, no container twice,
            # each robot's searches driven by its own Nav2.
            trial = get(f"{ferret_serve}/deployments/{dep}")["trials"][-1]
            state = get(f"{ferret_serve}/trials/{trial['trial']}")
            assert state["status"] == "done" and state["target"] == target, state
            assert [r["id"] for r in state["robots"]] == [f"/{r}" for r in TEAM]
            searched = state["searched"]
            assert len(set(searched)) == len(searched), state
            assert target in house.contents(searched[-1])
            # (A robot on its way when a teammate found the target gets there, and reports
            # nothing: its drive is in its Nav2's visits, not in the trial.)
            for r, nav in zip(state["robots"], sims[::2]):
                assert set(r["searched"]) <= set(nav.visited[visits[r["id"]] :]), (r, nav.visited)
            for r, nav in zip(state["robots"], sims[::2]):
                visits[r["id"]] = len(nav.visited)
            # Every node reports the team's searches and where the target was found.
            for _, result, _ in results.values():
                assert list(result.searched_containers) == searched
                assert result.container == searched[-1]
        # Over the two trials, more than one robot searched.
        busy = set()
        for t in get(f"{ferret_serve}/deployments/{dep}")["trials"]:
            for r in get(f"{ferret_serve}/trials/{t['trial']}")["robots"]:
                if r["searched"]:
                    busy.add(r["id"])
        assert len(busy) >= 2, busy
    finally:
        spin.close()


def test_a_node_left_out_of_its_team_refuses_to_start(ros, tmp_path, ferret_serve):
    """The team must name the robot: a node whose `serve_team` leaves it out stops at once,
    saying which parameter and which id."""
    p = FerretProcess(
        tmp_path,
        "ferret",
        {
            "scene": str(SCENE),
            "backend": "serve",
            "serve_url": ferret_serve,
            "serve_scene": "apartment",
            "serve_team": ["/r1", "/r2"],
        },
        namespace="r9",
    )
    try:
        p.proc.wait(30)
    finally:
        p.stop()
    assert p.proc.returncode != 0
    assert "parameter `serve_team`: ['/r1', '/r2'] does not name this robot ('/r9'" in p.text()
