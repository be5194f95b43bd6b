"""Real ProcTHOR houses (multiroom-val150), when FERRET_PROCTHOR_DIR points at the data."""

import pytest

import ferret
from conftest import read_trials, run_cli

VAL = "multiroom-val150.jsonl.gz"


@pytest.fixture(scope="module")
def val(procthor_dir):
    return procthor_dir / VAL, procthor_dir / "databases" / "asset-database.json"


def test_load_a_range_with_the_asset_database(val):
    path, db = val
    houses = ferret.load_houses(path, asset_db=db, range="10..14")
    assert [h.index for h in houses] == [10, 11, 12, 13]
    assert all(h.name == f"{VAL}#{h.index}" for h in houses)
    for h in houses:
        assert len(h.containers) > 0 and len(h.rooms) > 0
        d = h.distances()
        assert d.shape == (len(h.containers) + 1,) * 2


def test_evaluate_matches_ferret_eval_on_real_houses(val, ferret_bin, tmp_path):
    path, db = val
    houses = ferret.load_houses(path, asset_db=db, range="0..6")
    specs = "optimistic+greedy,model/prior,model/prior/exact"
    ev = ferret.evaluate(houses, specs, seed=0)
    run_cli(
        ferret_bin,
        "eval",
        "--houses",
        str(path),
        "--asset-db",
        str(db),
        "--range",
        "0..6",
        "--strategies",
        specs,
        "--out",
        str(tmp_path),
    )
    cli = read_trials(tmp_path / "trials.csv")
    assert len(cli) == len(ev.rows) == 18
    for r, c in zip(ev.rows, cli):
        assert (r["house"], r["strategy"], r["target"]) == (c["house"], c["strategy"], c["target"])
        assert r["cost_m"] == float(c["cost_m"]) and r["searched"] == c["searched"]


def test_protocol_paper_on_real_houses(val, ferret_bin, tmp_path):
    path, db = val
    houses = ferret.load_houses(path, asset_db=db, range="3..6", containers="furniture")
    ev = ferret.evaluate(houses, ["model/prior", "optimistic+greedy"], protocol="paper")
    run_cli(
        ferret_bin,
        "eval",
        "--houses",
        str(path),
        "--asset-db",
        str(db),
        "--range",
        "3..6",
        "--strategies",
        "model/prior,optimistic+greedy",
        "--protocol",
        "paper",
        "--out",
        str(tmp_path),
    )
    cli = read_trials(tmp_path / "trials.csv")
    assert [r["cost_m"] for r in ev.rows] == [float(c["cost_m"]) for c in cli]
    # The paper's soft travel cost is reported, not the plain path length a Search travels.
    assert all(r["cost_m"] > 0 for r in ev.rows)


def test_search_on_a_real_house(val):
    path, db = val
    [house] = ferret.load_houses(path, asset_db=db, range="7")
    ev = ferret.evaluate([house], ["model/prior/exact"], seed=0)
    row = ev.rows[0]
    s = ferret.Search(house, row["target"], "model/prior/exact")
    while (c := s.next_container()) is not None:
        seen = house.contents(c)
        s.record(c, row["target"] in seen, seen)
    assert s.cost == row["cost_m"] and " ".join(s.searched) == row["searched"]
