"""ferret.Deployment (the selector between a robot's trials) against `ferret deploy`, and
Search.likelihoods()."""

from pathlib import Path

import pytest

import ferret
from conftest import read_trials, run_cli

SCENE = Path(__file__).resolve().parents[3] / "examples" / "apartment" / "scene.yaml"
CANDIDATES = ["model/prior", "model/uniform", "optimistic+greedy"]


def drive(house, target, strategy):
    """A search answered from the scene's contents, as a simulated robot would."""
    s = ferret.Search(house, target, strategy)
    while (c := s.next_container()) is not None:
        seen = house.contents(c)
        s.record(c, target in seen, seen)
    return s


@pytest.mark.parametrize("method,seed", [("replay", 0), ("ucb", 7)])
def test_deployment_makes_ferret_deploys_choices(ferret_bin, tmp_path, method, seed):
    house = ferret.load_houses(str(SCENE))[0]
    targets = house.target_types()
    run_cli(
        ferret_bin,
        "deploy",
        "--houses",
        str(SCENE),
        "--find",
        ",".join(targets),
        "--strategies",
        ",".join(CANDIDATES),
        "--method",
        method,
        "--seed",
        str(seed),
        "--out",
        str(tmp_path),
    )
    rows = read_trials(tmp_path / "deploy.csv")
    d = ferret.Deployment(CANDIDATES, method=method, seed=seed)
    for k, (target, row) in enumerate(zip(targets, rows), start=1):
        chosen = d.choose()
        assert d.choose() == chosen  # the same until the trial ends
        s = drive(house, target, chosen)
        replays = d.finish(s)
        assert (chosen, s.found.id) == (row["chosen"], row["found_container"]), row
        assert s.cost == float(row["cost_m"])
        assert list(replays) == CANDIDATES
        assert replays[chosen] == s.cost
        assert " ".join(f"{n}={v:.2f}" for n, v in replays.items()) == row["replays"]
        assert d.trials == k
    stats = d.stats()
    assert [s["strategy"] for s in stats] == CANDIDATES
    assert sum(s["deployed"] for s in stats) == len(targets)


def test_abandoned_trials_teach_nothing():
    house = ferret.load_houses(str(SCENE))[0]
    a = ferret.Deployment(CANDIDATES, seed=3)
    b = ferret.Deployment(CANDIDATES, seed=3)
    first = a.choose()
    assert b.choose() == first
    a.abandon()  # a failed trial: its choice was made (and drew a tie-break), nothing learned
    b.abandon()
    for target in ["Wallet", "Apple", "Book"]:
        ca, cb = a.choose(), b.choose()
        assert ca == cb
        a.finish(drive(house, target, ca))
        b.finish(drive(house, target, cb))
    assert a.stats() == b.stats()
    assert a.trials == 4
    assert sum(s["deployed"] for s in a.stats()) == 3


def test_deployment_refuses_what_it_cannot_run():
    house = ferret.load_houses(str(SCENE))[0]
    with pytest.raises(ferret.ConfigError, match="at least two"):
        ferret.Deployment(["model/prior"])
    with pytest.raises(ferret.StrategyError, match="oracle"):
        ferret.Deployment(["model/prior", "oracle"])
    with pytest.raises(ferret.ConfigError, match="method"):
        ferret.Deployment(CANDIDATES, method="best")
    with pytest.raises(ferret.StrategyError):
        ferret.Deployment(["model/prior", "model/bogus"])
    with pytest.raises(ferret.FerretError, match="strategies"):
        ferret.Deployment(["model/prior", "model/prior"])
    d = ferret.Deployment(CANDIDATES)
    with pytest.raises(ferret.SearchError, match="choose"):
        d.abandon()
    chosen = d.choose()
    other = next(s for s in CANDIDATES if s != chosen)
    with pytest.raises(ferret.SearchError, match="strategy is"):
        d.finish(drive(house, "Wallet", other))
    unfinished = ferret.Search(house, "Wallet", chosen)
    with pytest.raises(ferret.SearchError, match="not found its target"):
        d.finish(unfinished)
    # The robot's detector never sees the wallet: every container searched, nothing found.
    nowhere = ferret.Search(house, "Wallet", chosen)
    while (c := nowhere.next_container()) is not None:
        nowhere.record(c, False)
    assert nowhere.found is None
    with pytest.raises(ferret.SearchError, match="abandon"):
        d.finish(nowhere)
    d.abandon()
    assert d.trials == 1


def test_likelihoods_are_the_strategys_source():
    house = ferret.load_houses(str(SCENE))[0]
    n = len(house.containers)
    assert ferret.Search(house, "Wallet", "model/uniform").likelihoods() == [0.1] * n
    assert ferret.Search(house, "Wallet", "optimistic+greedy").likelihoods() is None
    prior = ferret.Search(house, "Apple", "model/prior").likelihoods()
    assert len(prior) == n and all(0.0 <= p <= 1.0 for p in prior)
    by_id = dict(zip((c.id for c in house.containers), prior))
    # The prior knows where apples are kept better than where remotes are.
    assert by_id["fridge"] > by_id["bed"]
