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
