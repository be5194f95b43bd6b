"""ferret.Search step by step: the same decisions and costs as ferret.evaluate's simulator."""

import threading

import pytest

import ferret

STRATEGIES = [
    "optimistic+greedy",
    "model/uniform",
    "model/prior",
    "model/prior/exact",
    "model/prior/k3",
]


def simulate(house, target, strategy, **kw):
    """A robot loop whose perception answers from the house's ground truth."""
    s = ferret.Search(house, target, strategy, **kw)
    while (c := s.next_container()) is not None:
        seen = house.contents(c)
        s.record(c, target in seen, seen)
    return s


def test_search_gives_evaluates_costs(houses):
    ev = ferret.evaluate(houses, STRATEGIES, seed=4)
    assert len(ev.rows) == len(houses) * len(STRATEGIES)
    for row in ev.rows:
        house = houses[row["house_index"]]
        s = simulate(house, row["target"], row["strategy"])
        assert s.cost == row["cost_m"], row
        assert " ".join(s.searched) == row["searched"]
        assert s.found is not None and s.found.id == row["found_container"]
        assert s.done


def test_step_semantics(houses):
    house = houses[2]
    target = house.target_types()[0]
    s = ferret.Search(house, target, "model/prior")
    assert (s.target, s.strategy, s.cost, s.searched, s.found, s.done) == (
        target,
        "model/prior",
        0.0,
        [],
        None,
        False,
    )
    first = s.next_container()
    assert isinstance(first, ferret.Container)
    # Asking again without a search proposes the same container.
    assert s.next_container() == first
    # The robot may search another container than the one proposed; the leg is what it cost.
    other = next(
        c for c in house.containers if c.id != first.id and target not in house.contents(c)
    )
    d = house.distances()
    leg = s.record(other.id, False, house.contents(other))
    assert leg == s.cost == d[0, other.index + 1]
    assert s.searched == [other.id]
    nxt = s.next_container()
    assert s.distance_to(nxt) == d[other.index + 1, nxt.index + 1]
    path = s.path_to(nxt)
    assert len(path) >= 2 and path[-1] == pytest.approx(nxt.access)
    with pytest.raises(ferret.SearchError, match="already searched"):
        s.record(other, False)
    with pytest.raises(ferret.SearchError, match="is not a container of house"):
        s.record("no-such-container", False)
    goal = next(c for c in house.containers if target in house.contents(c))
    if goal.id not in s.searched:
        s.record(goal, True)
    assert s.found == goal and s.done
    assert s.next_container() is None
    with pytest.raises(ferret.SearchError, match="already found"):
        s.record(nxt, False)


def test_exhausted_search_ends_with_none(houses):
    house = houses[0]
    # A held type that the robot never sees (its detector misses it): every container searched.
    s = ferret.Search(house, house.target_types()[0], "optimistic+greedy")
    steps = 0
    while (c := s.next_container()) is not None:
        s.record(c, False)
        steps += 1
    assert steps == len(house.containers) and s.done and s.found is None
    assert sorted(s.searched) == sorted(c.id for c in house.containers)


def test_a_prior_object_is_used(houses):
    house = houses[5]
    target = house.target_types()[-1]
    trained = ferret.Prior.train(ferret.generate_houses(20, 5))
    a = simulate(house, target, "model/prior", prior=trained)
    b = simulate(house, target, "model/prior", prior=ferret.Prior.default())
    c = simulate(house, target, "model/prior")
    assert b.searched == c.searched and b.cost == c.cost
    assert a.found is not None


def test_the_oracle_cannot_be_driven(houses):
    with pytest.raises(ferret.StrategyError, match="ground truth"):
        ferret.Search(houses[0], "Apple", "oracle")


def test_searches_run_on_other_threads(houses):
    house = houses[3]
    target = house.target_types()[0]
    costs = {}

    def run(i):
        costs[i] = simulate(house, target, "model/prior/exact").cost

    threads = [threading.Thread(target=run, args=(i,)) for i in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(set(costs.values())) == 1 and len(costs) == 3
    # A search made on one thread and stepped on another.
    s = ferret.Search(house, target, "model/uniform")
    out = []
    t = threading.Thread(target=lambda: out.append(s.next_container()))
    t.start()
    t.join()
    assert isinstance(out[0], ferret.Container)


def test_the_robot_loop_example_runs():
    import subprocess
    import sys
    from pathlib import Path

    example = Path(__file__).resolve().parents[3] / "examples" / "python_robot_loop.py"
    out = subprocess.run(
        [sys.executable, str(example), "--seed", "4"], capture_output=True, text=True
    )
    assert out.returncode == 0, out.stderr
    last = out.stdout.strip().splitlines()[-1]
    assert last.startswith("found the ")
    # The example's search is the one ferret.evaluate's simulator runs on the same trial.
    [house] = ferret.generate_houses(1, 4)
    target = house.target_types()[0]
    s = simulate(house, target, "model/prior")
    assert last.endswith(f"after {len(s.searched)} searches, {s.cost:.2f} m")


def test_a_container_of_another_house_is_refused(houses):
    # Generated houses number their containers alike, so ids coincide across houses.
    home = houses[0]
    ids = {c.id for c in home.containers}
    other = next(h for h in houses[1:] if any(c.id in ids for c in h.containers))
    foreign = next(c for c in other.containers if c.id in ids)
    s = ferret.Search(home, home.target_types()[0], "optimistic+greedy")
    for call in (
        lambda: s.record(foreign, False, []),
        lambda: s.distance_to(foreign),
        lambda: s.path_to(foreign),
    ):
        with pytest.raises(ferret.SearchError, match="another house"):
            call()
    assert s.searched == [] and s.cost == 0.0
    assert foreign.house == other.name
    # The house's own container with that id, and the id itself, are its own.
    own = next(c for c in home.containers if c.id == foreign.id)
    assert own.house == home.name and own != foreign
    assert s.distance_to(own) == s.distance_to(own.id)
    s.record(own, False, [])
    assert s.searched == [own.id]
