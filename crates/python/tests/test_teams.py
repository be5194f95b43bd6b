"""Teams from Python: `ferret.evaluate(robots=N)` runs the trials `ferret eval --robots N` runs
(the same makespans, total travel and robots per container), one robot is the evaluation without
a team, and bad teams raise ConfigError naming the keyword."""

import pytest

import ferret
from conftest import HOUSE_SEED, HOUSES, read_trials, run_cli

TEAM = ["model/prior", "independent/model/prior", "split/model/prior", "oracle"]


@pytest.mark.parametrize("robots,starts,task", [(2, "together", None), (3, "spread", "all:2")])
def test_evaluate_with_a_team_is_ferret_eval_robots(
    houses, ferret_bin, tmp_path, robots, starts, task
):
    ev = ferret.evaluate(houses, TEAM, seed=5, robots=robots, starts=starts, task=task)
    args = ["--task", task] if task else []
    run_cli(
        ferret_bin,
        "eval",
        "--generate",
        str(HOUSES),
        "--house-seed",
        str(HOUSE_SEED),
        "--seed",
        "5",
        "--robots",
        str(robots),
        "--starts",
        starts,
        "--strategies",
        ",".join(TEAM),
        *args,
        "--out",
        str(tmp_path),
    )
    cli = read_trials(tmp_path / "trials.csv")
    assert len(ev.rows) == len(cli) == HOUSES * len(TEAM)
    for mine, theirs in zip(ev.rows, cli):
        assert mine["robots"] == robots
        for k in ["strategy", "target", "searched", "searched_by", "found_container"]:
            assert str(mine[k]) == theirs[k], k
        assert mine["cost_m"] == pytest.approx(float(theirs["cost_m"]), abs=1e-9)
        assert mine["total_travel_m"] == pytest.approx(float(theirs["total_travel_m"]), abs=1e-9)
        assert mine["total_travel_m"] + 1e-9 >= mine["cost_m"]
        assert len(mine["searched_by"].split()) == mine["searches"]


def test_one_robot_is_the_evaluation_without_a_team(houses):
    alone = ferret.evaluate(houses, ["model/prior", "oracle"], seed=2)
    one = ferret.evaluate(houses, ["model/prior", "oracle"], seed=2, robots=1)
    for a, b in zip(alone.rows, one.rows):
        assert a["cost_m"] == b["cost_m"] and a["searched"] == b["searched"]
        assert "robots" not in a and b["robots"] == 1


@pytest.mark.parametrize(
    "kw,says",
    [
        ({"robots": 5}, r"robots=5: 5 robots: a team has 1 to 4"),
        ({"robots": 0}, r"robots=0: 0 robots"),
        ({"starts": "spread"}, r"starts=\"spread\": only with robots="),
        ({"robots": 2, "starts": "scattered"}, r"starts=\"scattered\""),
        ({"robots": 2, "protocol": "paper"}, r"plain metres"),
    ],
)
def test_bad_teams_raise_config_error_naming_the_keyword(houses, kw, says):
    with pytest.raises(ferret.ConfigError, match=says):
        ferret.evaluate(houses[:2], ["model/prior"], **kw)


def team_loop(house, target, robots, strategy="model/prior"):
    """A team of `robots` searches driven from Python, as robots sharing a trial drive it: each
    robot in turn searches the container it is heading to, every teammate `observe`s what it
    saw, and a robot with nothing to do is sent to a container no teammate is heading to
    (`next_container(leaving=...)`). Returns the searches and who searched what, in order."""
    team = [ferret.Search(house, target, strategy) for _ in range(robots)]
    heading = [None] * robots
    order = []
    turn = 0
    while not team[0].goal_holds:
        for r, s in enumerate(team):
            if heading[r] is None:
                others = [h for o, h in enumerate(heading) if o != r and h is not None]
                heading[r] = s.next_container(leaving=others)
        movers = [r for r in range(robots) if heading[r] is not None]
        if not movers:
            break
        r = movers[turn % len(movers)]
        turn += 1
        c, heading[r] = heading[r], None
        seen = house.contents(c)
        team[r].record(c, target in seen, seen)
        for o, s in enumerate(team):
            if o != r:
                s.observe(c, target in seen, seen)
        order.append((r, c.id))
    return team, order


def test_a_team_driven_from_python_never_sends_two_robots_to_one_container(houses):
    for house in houses:
        for target in house.target_types()[:2]:
            team, order = team_loop(house, target, 3)
            searched = [c for _, c in order]
            assert len(set(searched)) == len(searched), (house.name, target, order)
            # Everyone knows the goal holds once one robot found it, and where.
            assert all(s.goal_holds for s in team)
            assert len({s.found.id for s in team}) == 1
            assert target in house.contents(team[0].found)
            # Each robot's own searches are its `searched`, and it moved only for them.
            for r, s in enumerate(team):
                mine = [c for who, c in order if who == r]
                assert s.searched == mine
                assert (s.cost > 0) == bool(mine)


def test_leaving_and_observe_change_the_plan_as_a_teammate_would(houses):
    # A house and target whose first proposal holds no target (so that a teammate's search
    # there is in vain).
    house, target, first = next(
        (h, t, f)
        for h in houses
        for t in h.target_types()
        if t not in h.contents(f := ferret.Search(h, t, "model/prior").next_container())
    )
    # Never the container a teammate is heading to.
    s = ferret.Search(house, target, "model/prior")
    second = s.next_container(leaving=[first])
    assert second is not None and second.id != first.id
    assert s.next_container(leaving=[first.id]) == second
    # A teammate's search in vain there: this robot plans as if it had been told so, without
    # moving (no cost), and the container is never proposed again.
    s.observe(first, False, house.contents(first))
    assert s.cost == 0.0 and s.searched == []
    assert s.next_container() is not None and s.next_container().id != first.id
    # Only the teammates' containers left: nothing to do.
    everything = [c for c in house.containers if c.id not in s.searched]
    assert s.next_container(leaving=everything) is None
    # A teammate found it: the goal holds for this robot too.
    holder = next(c for c in house.containers if target in house.contents(c))
    s.observe(holder, True, house.contents(holder))
    assert s.goal_holds and s.found.id == holder.id and s.next_container() is None
    with pytest.raises(ferret.SearchError, match="already searched"):
        s.observe(holder, True)
