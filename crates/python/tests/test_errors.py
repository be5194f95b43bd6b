"""Bad input raises the right exception class, with the file, house and field named."""

import json

import pytest

import ferret
from conftest import run_cli


@pytest.fixture()
def house_file(tmp_path, ferret_bin):
    path = tmp_path / "houses.jsonl"
    run_cli(ferret_bin, "generate", "--count", "3", "--seed", "1", "--out", str(path))
    return path


def test_hierarchy():
    for cls in (
        ferret.HouseError,
        ferret.StrategyError,
        ferret.PriorError,
        ferret.ConfigError,
        ferret.LlmError,
        ferret.SearchError,
    ):
        assert issubclass(cls, ferret.FerretError) and issubclass(cls, Exception)
    assert ferret.HouseError.__module__ == "ferret"


def test_bad_json_line_names_file_and_house(house_file):
    lines = house_file.read_text().splitlines()
    lines[2] = '{"rooms": [1, 2'
    house_file.write_text("\n".join(lines) + "\n")
    with pytest.raises(ferret.HouseError, match=r"houses\.jsonl, house 2: malformed JSON"):
        ferret.load_houses(house_file)


def test_missing_field_names_file_house_and_field(house_file):
    lines = house_file.read_text().splitlines()
    house = json.loads(lines[1])
    del house["rooms"]
    lines[1] = json.dumps(house)
    house_file.write_text("\n".join(lines) + "\n")
    with pytest.raises(ferret.HouseError, match=r"houses\.jsonl, house 1: .*rooms") as e:
        ferret.load_houses(house_file)
    assert str(house_file) in str(e.value)


def test_bad_field_value_names_the_field(house_file):
    lines = house_file.read_text().splitlines()
    house = json.loads(lines[0])
    house["rooms"][0]["floorPolygon"] = []
    lines[0] = json.dumps(house)
    house_file.write_text("\n".join(lines) + "\n")
    with pytest.raises(ferret.HouseError, match=r"house 0: rooms\[0\]\.floorPolygon"):
        ferret.load_houses(house_file)


def test_nonexistent_path(tmp_path):
    missing = tmp_path / "nowhere.jsonl.gz"
    with pytest.raises(ferret.HouseError, match="nowhere.jsonl.gz"):
        ferret.load_houses(missing)


def test_empty_file_and_range_outside_it(tmp_path, house_file):
    empty = tmp_path / "empty.jsonl"
    empty.write_text("\n\n")
    with pytest.raises(ferret.HouseError, match="holds no houses"):
        ferret.load_houses(empty)
    with pytest.raises(ferret.ConfigError, match="invalid house range"):
        ferret.load_houses(house_file, range="5..3")
    with pytest.raises(ferret.ConfigError, match="containers="):
        ferret.load_houses(house_file, containers="chairs")


def test_unknown_strategy(houses):
    with pytest.raises(ferret.StrategyError, match="unknown strategy `model/bogus`"):
        ferret.evaluate(houses[:2], ["model/bogus"])
    with pytest.raises(ferret.StrategyError, match="unknown strategy `teleport`"):
        ferret.Search(houses[0], "Apple", "teleport")


def test_a_target_the_house_does_not_hold_is_refused_with_the_name_meant(houses):
    house = houses[0]
    held = house.target_types()[0]
    with pytest.raises(ferret.ConfigError, match=f'did you mean "{held}"'):
        ferret.Search(house, held.lower(), "model/uniform")
    with pytest.raises(ferret.ConfigError, match="the scene holds"):
        ferret.Search(house, "Xylophone", "model/uniform")
    assert ferret.Search(house, held, "model/uniform").next_container() is not None


def test_bad_prior_file(tmp_path, houses):
    bad = tmp_path / "prior.json"
    bad.write_text('{"smoothing": "a lot"}')
    with pytest.raises(ferret.PriorError, match=r"prior .*prior\.json"):
        ferret.Prior.load(bad)
    with pytest.raises(ferret.PriorError, match=r"prior .*prior\.json"):
        ferret.evaluate(houses[:2], ["model/prior"], prior=bad)
    with pytest.raises(ferret.PriorError, match="missing.json"):
        ferret.Prior.load(tmp_path / "missing.json")
    # A strategy that does not plan over the prior never reads it.
    assert len(ferret.evaluate(houses[:2], ["model/uniform"], prior=bad)) == 2


def test_bad_settings_name_the_keyword(houses):
    h = houses[:2]
    cases = [
        (dict(protocol="mine"), "protocol="),
        (dict(reveal_fraction=1.5), "reveal_fraction=1.5"),
        (dict(resolution=0.001), "resolution=0.001"),
        (dict(robot_radius=-1.0), "robot_radius=-1"),
        (dict(max_containers=0), "max_containers=0"),
        (dict(exact_max=40), "exact_max=40"),
        (dict(search_cost=float("nan")), "search_cost=NaN"),
        (dict(trials_per_house=0), "trials_per_house=0"),
        (dict(trials_per_house="some"), "trials_per_house=some"),
        (dict(strategies=["model/uniform", "model/uniform"]), "`model/uniform` is given twice"),
        (dict(prior=3), "prior: expected"),
    ]
    for kw, message in cases:
        with pytest.raises(ferret.ConfigError, match=message.replace("(", r"\(")):
            ferret.evaluate(h, **{"strategies": ["model/uniform"], **kw})
    with pytest.raises(ferret.ConfigError, match="no houses"):
        ferret.evaluate([], ["model/uniform"])
    with pytest.raises(ferret.ConfigError, match="smoothing"):
        ferret.Prior.train(h, smoothing=-1)


def test_protocol_paper_needs_houses_read_with_its_container_set(house_file):
    houses = ferret.load_houses(house_file)
    with pytest.raises(ferret.ConfigError, match='containers="furniture"'):
        ferret.evaluate(houses, ["model/uniform"], protocol="paper")


def test_llm_configuration_errors(tmp_path, houses):
    config = tmp_path / "ferret.toml"
    config.write_text("[llm.x\nmodel = 1\n")
    with pytest.raises(ferret.ConfigError, match=r"ferret\.toml"):
        ferret.evaluate(houses[:1], ["model/uniform"], config=config)
    with pytest.raises(ferret.ConfigError, match="nowhere.toml"):
        ferret.Search(houses[0], "Apple", "model/uniform", config=tmp_path / "nowhere.toml")


def test_an_unanswered_llm_question_offline_is_an_llm_error(tmp_path, houses):
    config = tmp_path / "ferret.toml"
    config.write_text('[llm.local]\nbase_url = "http://127.0.0.1:9/v1"\nmodel = "m"\n')
    cache = tmp_path / "cache.sqlite"
    house = houses[0]
    target = house.target_types()[0]
    s = None
    with pytest.raises(ferret.LlmError, match="cache"):
        s = ferret.Search(
            house, target, "llm+model/p-yesno/local", config=config, llm_cache=cache, offline=True
        )
        s.next_container()
