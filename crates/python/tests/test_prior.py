"""Priors: training, files, the default one, and identical evaluations after a round trip."""

import json

import pytest

import ferret
from conftest import run_cli


def test_train_save_load_round_trip(tmp_path, houses):
    training = ferret.generate_houses(25, 100)
    prior = ferret.Prior.train(training, smoothing=3.0)
    assert prior.houses == 25 and prior.smoothing == 3.0
    assert prior.containers == sum(len(h.containers) for h in training)
    path = tmp_path / "prior.json"
    prior.save(path)
    back = ferret.Prior.load(path)
    assert back == prior and back is not prior
    assert json.loads(path.read_text())["houses"] == 25
    specs = ["model/prior", "model/prior/exact"]
    a = ferret.evaluate(houses, specs, prior=prior, seed=8)
    b = ferret.evaluate(houses, specs, prior=back, seed=8)
    assert [r["cost_m"] for r in a.rows] == [r["cost_m"] for r in b.rows]
    assert a.rows == b.rows


def test_probabilities_follow_the_training_houses():
    training = ferret.generate_houses(40, 3)
    prior = ferret.Prior.train(training)
    held = {(o.type, c.type) for h in training for c in h.containers for o in h.objects
            if o.container == c.id}
    target, container = sorted(held)[0]
    p = prior.probability(target, container)
    assert 0.0 < p <= 1.0
    assert prior.probability("NeverSeenThing", container) < p
    room = next(c.room_type for h in training for c in h.containers if c.type == container)
    assert 0.0 < prior.probability(target, container, room) <= 1.0


def test_default_prior_is_the_one_ferret_eval_uses(tmp_path, houses, ferret_bin):
    default = ferret.Prior.default()
    assert default.houses == 500 and default.smoothing == 2.0
    assert ferret.Prior.default() == default
    # ferret prior train on the same generated houses writes the same prior.
    path = tmp_path / "p.json"
    run_cli(ferret_bin, "prior", "train", "--generate", "500", "--house-seed", "1000003",
            "--out", str(path))
    assert ferret.Prior.load(path) == default
    assert ferret.evaluate(houses[:4], ["model/prior"], prior=default).rows == \
        ferret.evaluate(houses[:4], ["model/prior"]).rows
