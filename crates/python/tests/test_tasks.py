"""Household tasks from Python: a Search over several targets and a destination travels what
`ferret.evaluate` reports for the same task, evaluate's drawn and listed tasks are `ferret eval
--task/--tasks`'s trials (saved runs replayed by `ferret.select` and `ferret select` alike), a
Deployment over task searches makes `ferret deploy --find`'s choices, and bad tasks raise the
error naming the keyword and the field."""

import csv
import json

import pytest

import ferret
from conftest import HOUSE_SEED, HOUSES, read_trials, run_cli

STRATEGIES = ["optimistic+greedy", "model/uniform", "model/prior", "sequential/model/prior"]


def drive(house, targets, strategy, **kw):
    """A robot loop whose perception answers from the house's contents (every object seen in
    a container is named), then brings what it found to the destination."""
    s = ferret.Search(house, targets, strategy, **kw)
    while (c := s.next_container()) is not None:
        s.record(c, objects=house.contents(c))
    s.finish()
    return s


def search_of_row(house, row):
    """The Search of an evaluation row's task: its targets, goal and destination columns."""
    sep = "+" if row["goal"] == "all" else "|"
    return drive(
        house,
        row["target"].split(sep),
        row["strategy"],
        goal=row["goal"],
        destination=row["destination"] or None,
    )


def found_each(search):
    """`found_each` as trials.csv writes it: the container of each target, `-` if none."""
    found = search.found_in
    return " ".join(found[t].id if t in found else "-" for t in search.targets)


def houses_without(houses, deliver):
    """The indices of the houses that have no room or container of the type `deliver` names."""
    kind, _, name = deliver.partition(":")
    if kind == "room":
        return [h.index for h in houses if name not in {r.type for r in h.rooms}]
    if kind == "container":
        return [h.index for h in houses if name not in {c.type for c in h.containers}]
    return []


@pytest.mark.parametrize(
    "task,deliver",
    [("all:2", "start"), ("any:2", None), ("all:3", "container:Sofa"), ("any:3", "room:Kitchen")],
)
def test_a_search_over_a_task_costs_what_evaluate_reports(houses, task, deliver):
    # A house without the room or container to deliver to fails alone, as in `ferret eval`.
    missing = houses_without(houses, deliver or "")
    if missing:
        with pytest.warns(UserWarning, match=r"trial\(s\) failed"):
            ev = ferret.evaluate(houses, STRATEGIES, seed=6, task=task, deliver=deliver)
    else:
        ev = ferret.evaluate(houses, STRATEGIES, seed=6, task=task, deliver=deliver)
    assert len(ev.errors) == len(missing)
    assert all("no room of type" in e or "no container of type" in e for e in ev.errors)
    assert len(ev.rows) == (len(houses) - len(missing)) * len(STRATEGIES)
    goal, n = task.split(":")
    for row in ev.rows:
        assert row["goal"] == goal
        assert len(row["target"].split("+" if goal == "all" else "|")) == int(n)
        s = search_of_row(houses[row["house_index"]], row)
        # Exactly: the same decisions, legs and way to the destination.
        assert s.cost == row["cost_m"], row
        assert " ".join(s.searched) == row["searched"], row
        assert found_each(s) == row["found_each"], row
        assert s.found is not None and s.found.id == row["found_container"], row
        assert s.finish() == row["delivery_m"], row
        assert s.goal_holds and s.done and row["found"]
        assert s.target == row["target"] and s.goal == goal
        assert (s.destination is None) == (deliver is None)
    if deliver is not None:
        assert all(r["destination"] for r in ev.rows)
        assert any(r["delivery_m"] > 0 for r in ev.rows)


def test_a_task_search_step_by_step(houses):
    house = houses[1]
    types = house.target_types()
    where = {t: [c for c in house.containers if t in house.contents(c)] for t in types}
    # Two targets that no container holds together, so that they are found one at a time.
    a, b = next(
        (x, y)
        for x in types
        for y in types
        if x < y and not {c.id for c in where[x]} & {c.id for c in where[y]}
    )
    s = ferret.Search(house, [a, b], "model/prior", destination="start")
    assert (s.targets, s.goal, s.target) == ([a, b], "all", f"{a}+{b}")
    assert s.found_in == {} and not s.goal_holds and s.found is None and not s.done
    start = house.start
    assert s.destination == pytest.approx(start, abs=0.05)
    assert isinstance(s.path_to_destination(), list)
    # A container holding b, searched while the robot looks for a: b is found there.
    first = where[b][0]
    s.record(first, objects=house.contents(first))
    assert s.found_in == {b: first} and not s.goal_holds and s.found is None
    assert s.next_container() is not None
    second = where[a][0]
    s.record(second, found_targets=[a])
    assert s.found_in == {b: first, a: second} and s.goal_holds and s.done
    assert s.found == second and s.next_container() is None
    unsearched = [c for c in house.containers if c.id not in s.searched]
    with pytest.raises(ferret.SearchError, match="already holds"):
        s.record(unsearched[0], objects=[a])
    d = house.distances()
    before = s.cost
    assert before == d[0, first.index + 1] + d[first.index + 1, second.index + 1]
    path = s.path_to_destination()
    assert path[0] == pytest.approx(second.access) and path[-1] == s.destination
    leg = s.finish()
    # The way back to the start is the distance the map measures, and it counts once.
    assert leg == d[second.index + 1, 0]
    assert s.cost == before + leg and s.finish() == leg and s.cost == before + leg
    assert "destination='start'" in repr(s)

    # Any one of them: the first found ends the search, here in the first container.
    s = ferret.Search(house, [a, b], "model/prior", goal="any", destination=first)
    s.record(first, objects=[b])
    assert s.goal_holds and s.found == first and s.next_container() is None
    assert s.destination == pytest.approx(first.access)
    assert s.finish() == 0.0 and s.target == f"{a}|{b}"
    # A finished search searches no more, whether or not its goal held.
    s = ferret.Search(house, [a, b], "model/prior", destination="start")
    assert s.finish() == 0.0 and s.done and s.next_container() is None
    with pytest.raises(ferret.SearchError, match="finished"):
        s.record(first, objects=[])


def test_one_target_with_a_destination_and_named_targets(houses):
    house = houses[2]
    target = house.target_types()[0]
    holder = next(c for c in house.containers if target in house.contents(c))
    # Naming the one target among the objects seen is finding it, as found=True is.
    for record in (
        lambda s: s.record(holder, True),
        lambda s: s.record(holder, objects=house.contents(holder)),
        lambda s: s.record(holder, found_targets=[target]),
    ):
        s = ferret.Search(house, target, "model/prior", destination="start")
        record(s)
        assert s.found == holder and s.done and s.next_container() is None
        assert s.found_in == {target: holder}
        assert s.finish() == house.distances()[holder.index + 1, 0]
    # A point of the floor as the destination: where the robot stands there, and the way.
    s = ferret.Search(house, target, "model/prior", destination=holder.access)
    assert s.destination == pytest.approx(holder.access, abs=0.05)
    assert ferret.Search(house, target, "model/prior").destination is None
    assert ferret.Search(house, target, "model/prior").path_to_destination() is None


def test_a_deployment_over_tasks_makes_ferret_deploys_choices(ferret_bin, tmp_path):
    houses = ferret.generate_houses(3, 11)
    find = []
    for k in range(6):
        h = houses[k % 3]
        t = h.target_types()
        room = h.rooms[-1].id
        container = h.containers[k % len(h.containers)].id
        find.append(
            [
                f"{t[0]}+{t[1]}@start",
                f"{t[1]}|{t[2]}",
                f"{t[-1]}@start",
                f"{t[0]}+{t[2]}+{t[-1]}@container:{container}",
                f"{t[-2]}|{t[0]}@room:{room}",
                f"{t[1]}+{t[-1]}",
            ][k]
        )
    candidates = ["model/prior", "sequential/model/prior", "optimistic+greedy"]
    run_cli(
        ferret_bin,
        "deploy",
        "--generate",
        "3",
        "--house-seed",
        "11",
        "--find",
        ",".join(find),
        "--strategies",
        ",".join(candidates),
        "--seed",
        "4",
        "--out",
        str(tmp_path),
    )
    rows = read_trials(tmp_path / "deploy.csv")
    assert len(rows) == len(find)
    d = ferret.Deployment(candidates, seed=4)
    for k, (text, row) in enumerate(zip(find, rows)):
        body, _, destination = text.partition("@")
        goal = "any" if "|" in body else "all"
        targets = body.split("|" if goal == "any" else "+")
        chosen = d.choose()
        s = ferret.Search(
            houses[k % 3], targets, chosen, goal=goal, destination=destination or None
        )
        house = houses[k % 3]
        while (c := s.next_container()) is not None:
            s.record(c, objects=house.contents(c))
        # Not finished: the deployment takes the robot to the destination itself.
        replays = d.finish(s)
        assert (row["target"], row["chosen"]) == (s.target, chosen), row
        assert s.found.id == row["found_container"], row
        assert s.cost == float(row["cost_m"]), row
        assert replays[chosen] == s.cost
        assert " ".join(f"{n}={v:.2f}" for n, v in replays.items()) == row["replays"]
    assert d.trials == len(find)


def test_a_deployment_refuses_a_task_search_whose_goal_does_not_hold(houses):
    house = houses[0]
    a, b = house.target_types()[:2]
    d = ferret.Deployment(["model/prior", "optimistic+greedy"])
    s = ferret.Search(house, [a, b], d.choose())
    c = s.next_container()
    s.record(c, objects=[x for x in house.contents(c) if x not in (a, b)])
    with pytest.raises(ferret.SearchError, match="goal .* does not hold"):
        d.finish(s)
    d.abandon()


def cli_eval(ferret_bin, out, *args):
    run_cli(
        ferret_bin,
        "eval",
        "--generate",
        str(HOUSES),
        "--house-seed",
        str(HOUSE_SEED),
        "--out",
        str(out),
        *args,
    )
    return out


def test_saved_task_runs_are_ferret_evals_and_select_replays_them(houses, ferret_bin, tmp_path):
    specs = "optimistic+greedy,model/prior,sequential/model/prior,oracle"
    ev = ferret.evaluate(houses, specs, seed=1, task="all:2", deliver="start", trials_per_house=2)
    assert ev.columns[-4:] == ["goal", "destination", "found_each", "delivery_m"]
    assert {r["destination"] for r in ev.rows} == {"start"}
    py = tmp_path / "py"
    ev.save(py)
    cli = cli_eval(
        ferret_bin,
        tmp_path / "cli",
        "--strategies",
        specs,
        "--seed",
        "1",
        "--task",
        "all:2",
        "--deliver",
        "start",
        "--trials-per-house",
        "2",
    )
    for name in ["trials.csv", "run.json", "summary.csv", "paired.csv", "summary.md"]:
        assert (py / name).read_bytes() == (cli / name).read_bytes(), name
    assert json.loads((py / "run.json").read_text())["tasks"] == {
        "drawn": {"shape": {"goal": "all", "targets": 2}, "deliver": "start"}
    }
    sel = ferret.select(py, deployments=20, trials_per_deployment=6, seed=3)
    run_cli(
        ferret_bin,
        "select",
        "--trials",
        str(cli),
        "--deployments",
        "20",
        "--trials-per-deployment",
        "6",
        "--seed",
        "3",
        "--out",
        str(tmp_path / "select"),
    )
    cli_rows = read_trials(tmp_path / "select" / "selection.csv")
    assert len(sel.rows) == len(cli_rows) > 0
    for p, c in zip(sel.rows, cli_rows):
        assert list(p) == list(c)
        for k, v in p.items():
            assert (v if isinstance(v, str) else float(v)) == (
                c[k] if isinstance(v, str) else float(c[k])
            ), k
    assert sel.markdown == (tmp_path / "select" / "selection.md").read_text()
    # Replays are of the same tasks: keyed by their targets.
    # (in the order the replays finished, which parallel work does not fix).
    replays = sorted((py / "replay.csv").read_text().splitlines())
    assert replays == sorted((cli / "replay.csv").read_text().splitlines())
    assert any("+" in line for line in replays)


def listed_tasks(houses):
    """Tasks of houses 0 and 2: both of two targets to a container, any of two to a room, one
    target to a point of the floor (a container's access point, which the robot reaches)."""
    h0, h2 = houses[0], houses[2]
    t0, t2 = h0.target_types(), h2.target_types()
    point = h2.containers[0].access
    return [
        {"house": 0, "targets": [t0[0], t0[1]], "destination": f"container:{h0.containers[1].id}"},
        {
            "house": 0,
            "targets": [t0[2], t0[3]],
            "goal": "any",
            "destination": f"room:{h0.rooms[0].id}",
        },
        {"house": 2, "targets": t2[-1], "goal": "all", "destination": point},
        {"house": 2, "targets": f"{t2[0]}+{t2[1]}", "destination": "start"},
    ]


def test_listed_tasks_from_dicts_and_a_file_are_ferret_evals(houses, ferret_bin, tmp_path):
    tasks = listed_tasks(houses)
    file = tmp_path / "tasks.csv"
    with open(file, "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["house", "targets", "goal", "destination"])
        for t in tasks:
            targets = t["targets"] if isinstance(t["targets"], str) else " ".join(t["targets"])
            d = t.get("destination")
            d = f"{d[0]},{d[1]}" if isinstance(d, tuple) else d
            w.writerow([t["house"], targets, t.get("goal", ""), d])
    specs = ["model/prior", "sequential/model/prior"]
    from_dicts = ferret.evaluate(houses, specs, tasks=tasks)
    from_file = ferret.evaluate(houses, specs, tasks=file)
    assert from_dicts.rows == from_file.rows
    assert [r["house_index"] for r in from_dicts.rows] == [0, 0, 0, 0, 2, 2, 2, 2]
    assert from_dicts.trials_run == len(tasks)
    rows = read_trials(
        cli_eval(
            ferret_bin, tmp_path / "cli", "--tasks", str(file), "--strategies", ",".join(specs)
        )
        / "trials.csv"
    )
    assert len(rows) == len(from_dicts.rows)
    for p, c in zip(from_dicts.rows, rows):
        assert (p["target"], p["goal"], p["destination"], p["found_each"]) == (
            c["target"],
            c["goal"],
            c["destination"],
            c["found_each"],
        )
        assert p["cost_m"] == float(c["cost_m"]) and p["delivery_m"] == float(c["delivery_m"])
    # Each row's task driven step by step travels the same.
    for row in from_dicts.rows:
        s = search_of_row(houses[row["house_index"]], row)
        assert s.cost == row["cost_m"] and found_each(s) == row["found_each"], row
    # The list is what run.json keeps, so that select replays the same tasks.
    from_dicts.save(tmp_path / "py")
    run = json.loads((tmp_path / "py" / "run.json").read_text())
    assert [line["house"] for line in run["tasks"]["listed"]["lines"]] == [0, 0, 2, 2]
    sel = ferret.select(tmp_path / "py", deployments=5, trials_per_deployment=2, seed=0)
    assert sel.strategies == specs


def test_bad_search_arguments_name_the_keyword(houses):
    house = houses[0]
    t = house.target_types()
    refused = [
        (dict(target=[t[0], t[0]]), r"target: .*twice"),
        (dict(target=t[:2] * 3), r"target: .*at most 4"),
        (dict(target=[]), r"target: .*at least one"),
        (dict(target=[t[0], ""]), r"target\[1\]: an empty object type"),
        (dict(target=[t[0], t[1].lower()]), rf'target\[1\]: .*did you mean "{t[1]}"'),
        (dict(target=[t[0], t[1]], goal="some"), r'goal="some": .*`all` or `any`'),
        (dict(target=t[0], destination="room:nowhere"), r"destination: .*no room `nowhere`"),
        (dict(target=t[0], destination="moon"), r"destination: `moon` is not a destination"),
        (dict(target=t[0], destination=(1000.0, 1000.0)), r"destination: .*not on floor"),
        (dict(target=t[0], destination=(float("nan"), 0.0)), r"destination: .*finite"),
        (dict(target=t[0], destination=3), r"destination: expected"),
        (dict(target=t[0], destination=houses[1].containers[0]), r"destination: .*another house"),
    ]
    for kw, says in refused:
        with pytest.raises(ferret.ConfigError, match=says):
            ferret.Search(house, strategy="model/prior", **kw)
    s = ferret.Search(house, [t[0], t[1]], "model/prior")
    c = s.next_container()
    with pytest.raises(ferret.ConfigError, match="found=True, but no target"):
        s.record(c, True, objects=["Nothing"])
    with pytest.raises(ferret.ConfigError, match=r"found_targets\[0\]: .* is not a target"):
        s.record(c, found_targets=["Xylophone"])
    assert s.searched == [] and s.cost == 0.0  # a refused record records nothing
    with pytest.raises(ferret.ConfigError, match="target: .* is not a target"):
        s.likelihoods("Xylophone")
    assert s.likelihoods(t[1]) != s.likelihoods() or t[0] == t[1]


def test_bad_evaluate_tasks_name_the_keyword_and_field(houses, tmp_path):
    t0 = houses[0].target_types()
    refused = [
        (dict(task="all:5"), r"task=\"all:5\": targets: 5 targets: a task asks for 1 to 4"),
        (dict(task="some:2"), r"task=\"some:2\": goal: `some` is not a goal"),
        (dict(deliver="start"), r"deliver=\"start\": only with task="),
        (dict(task="all:2", deliver="moon"), r"deliver=\"moon\": .*expected `start`"),
        (dict(task="all:2", tasks=[{"house": 0, "targets": [t0[0]]}]), r"task, tasks: give one"),
        (dict(task="all:2", trials_per_house="all"), r"trials_per_house=\"all\""),
        (dict(tasks=[]), r"tasks: no task"),
        (dict(tasks=42), r"tasks: expected the path"),
        (dict(tasks=[{"house": 0, "targets": [t0[0], t0[0]]}]), r"tasks\[0\]\.targets: .*twice"),
        (dict(tasks=[{"house": 0, "targets": t0[:5] * 2}]), r"tasks\[0\]\.targets: .*at most 4"),
        (dict(tasks=[{"house": 0, "targets": [t0[0]], "goal": "maybe"}]), r"tasks\[0\]\.goal: "),
        (dict(tasks=[{"house": 0, "targets": [t0[0]], "when": 1}]), r"tasks\[0\]: unknown key"),
        (dict(tasks=[{"targets": [t0[0]]}]), r"tasks\[0\]\.house: missing"),
        (dict(tasks=["Mug"]), r"tasks\[0\]: expected a dict"),
        (
            dict(tasks=[{"house": 0, "targets": [t0[0]], "destination": 5}]),
            r"tasks\[0\]\.destination: expected",
        ),
        (
            dict(tasks=[{"house": 0, "targets": [t0[0]], "destination": "room:nowhere"}]),
            r"tasks: task 1 \(house 0\): destination: .*no room `nowhere`",
        ),
        (
            dict(tasks=[{"house": 0, "targets": [t0[0]], "destination": (1000.0, 1000.0)}]),
            r"tasks: house 0, task 1: destination: .*not on floor",
        ),
        (dict(tasks=[{"house": 999, "targets": [t0[0]]}]), r"tasks: task 1: house: no house 999"),
        (
            dict(tasks=[{"house": 0, "targets": [t0[0], "Xylophone"]}]),
            r"tasks: task 1 \(house 0\): targets: .*no container holds Xylophone",
        ),
        (
            dict(tasks=[{"house": 0, "targets": [t0[0]]}, {"house": 0, "targets": t0[0]}]),
            r"tasks: task 2 \(house 0\): targets: the same task as task 1",
        ),
    ]
    for kw, says in refused:
        with pytest.raises(ferret.ConfigError, match=says):
            ferret.evaluate(houses, ["model/prior"], **kw)
    bad = tmp_path / "tasks.csv"
    bad.write_text("house,targets,goal,destination\n0,Apple Apple,all,\n")
    with pytest.raises(ferret.ConfigError, match=r"tasks: .*tasks\.csv: line 2: targets: .*twice"):
        ferret.evaluate(houses, ["model/prior"], tasks=bad)
    with pytest.raises(ferret.ConfigError, match=r"tasks: .*missing\.csv"):
        ferret.evaluate(houses, ["model/prior"], tasks=tmp_path / "missing.csv")


def test_a_shard_checks_the_tasks_of_every_house_given(houses):
    # House 1 is in another shard, yet its task is checked against it (and fits).
    tasks = [
        {"house": 0, "targets": houses[0].target_types()[:2]},
        {"house": 1, "targets": houses[1].target_types()[:2]},
    ]
    ev = ferret.evaluate(houses, ["model/prior"], tasks=tasks, shard=(0, 2))
    assert [r["house_index"] for r in ev.rows] == [0]
    with pytest.raises(ferret.ConfigError, match="no container holds Xylophone"):
        ferret.evaluate(
            houses,
            ["model/prior"],
            tasks=[tasks[0], {"house": 1, "targets": ["Xylophone"]}],
            shard=(0, 2),
        )


def test_tasks_on_real_houses(procthor_dir):
    path = procthor_dir / "multiroom-val150.jsonl.gz"
    db = procthor_dir / "databases" / "asset-database.json"
    houses = ferret.load_houses(path, asset_db=db, range="0..4")
    ev = ferret.evaluate(
        houses, ["model/prior", "sequential/model/prior"], task="all:2", deliver="start"
    )
    assert ev.errors == [] and len(ev.rows) == 8
    by_index = {h.index: h for h in houses}
    for row in ev.rows:
        s = search_of_row(by_index[row["house_index"]], row)
        assert s.cost == row["cost_m"] and " ".join(s.searched) == row["searched"], row
        assert s.finish() == row["delivery_m"]
