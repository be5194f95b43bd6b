"""ferret.calibrate, Evaluation.save and ferret.select against the real `ferret calibrate`,
`ferret eval` and `ferret select`: the same inputs give the same files' rows."""

import csv
import json

import pytest

import ferret
from conftest import HOUSE_SEED, HOUSES, run_cli

STRATEGIES = "optimistic+greedy,model/uniform,model/prior,oracle"


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def same_numbers(py_rows, cli_rows):
    """The rows of a Python result equal the CSV rows (numbers read back exactly)."""
    assert len(py_rows) == len(cli_rows) > 0
    for p, c in zip(py_rows, cli_rows):
        assert list(p) == list(c)
        for k, v in p.items():
            if v is None:
                assert c[k] == "", k
            elif isinstance(v, bool):
                assert str(v).lower() == c[k].lower(), k
            elif isinstance(v, (int, float)):
                assert v == float(c[k]), (k, v, c[k])
            else:
                assert v == c[k], k


def test_calibrate_matches_ferret_calibrate(houses, ferret_bin, tmp_path):
    result = ferret.calibrate(houses, targets_per_house=2, seed=4)
    run_cli(
        ferret_bin,
        "calibrate",
        "--generate",
        str(HOUSES),
        "--house-seed",
        str(HOUSE_SEED),
        "--targets-per-house",
        "2",
        "--seed",
        "4",
        "--out",
        str(tmp_path),
    )
    same_numbers(result.rows, read_csv(tmp_path / "calibration.csv"))
    assert [r["source"] for r in result.rows] == ["model/uniform", "model/prior"]
    assert result.trials == sum(min(2, len(h.target_types())) for h in houses)
    # Holders are the pairs whose container holds the target; the prior ranks them higher.
    uniform, prior = result.rows
    assert uniform["pairs"] == prior["pairs"] and uniform["positives"] == prior["positives"]
    assert prior["brier"] < uniform["brier"] and prior["auroc"] > 0.6
    bins = result.reliability["model/prior"]
    assert sum(b["count"] for b in bins) == prior["pairs"]
    assert all(b["lo"] <= b["mean_p"] <= b["hi"] for b in bins if b["count"])
    assert result.fusion is None and result.errors == []
    # The Markdown is the file's, but for where the houses came from.
    md = (tmp_path / "calibration.md").read_text()
    assert result.markdown.split("\n")[4:] == md.split("\n")[4:]


def test_calibrate_refuses_what_it_cannot_score(houses):
    with pytest.raises(ferret.ConfigError, match="plans over no likelihood source"):
        ferret.calibrate(houses[:2], "optimistic+greedy")
    with pytest.raises(ferret.ConfigError, match=r"fit_fusion=True: sources names no llm\+model"):
        ferret.calibrate(houses[:2], "model/prior", fit_fusion=True)
    with pytest.raises(ferret.ConfigError, match="bins=0"):
        ferret.calibrate(houses[:2], bins=0)
    with pytest.raises(ferret.ConfigError, match="targets_per_house=none"):
        ferret.calibrate(houses[:2], targets_per_house="none")
    with pytest.raises(ferret.StrategyError, match="no/such"):
        ferret.calibrate(houses[:2], "no/such")


@pytest.fixture(scope="module")
def cli_run(ferret_bin, tmp_path_factory):
    out = tmp_path_factory.mktemp("cli-eval")
    run_cli(
        ferret_bin,
        "eval",
        "--generate",
        str(HOUSES),
        "--house-seed",
        str(HOUSE_SEED),
        "--strategies",
        STRATEGIES,
        "--seed",
        "1",
        "--out",
        str(out),
    )
    return out


def test_a_saved_evaluation_is_the_run_ferret_eval_writes(houses, cli_run, tmp_path):
    ferret.evaluate(houses, STRATEGIES, seed=1).save(tmp_path / "run")
    for name in ["trials.csv", "run.json", "summary.csv", "paired.csv", "summary.md"]:
        assert (tmp_path / "run" / name).read_bytes() == (cli_run / name).read_bytes(), name


def test_a_saved_evaluation_compares_what_paired_against_names(ferret_bin, houses, tmp_path):
    cli = tmp_path / "cli"
    run_cli(
        ferret_bin,
        "eval",
        "--generate",
        str(HOUSES),
        "--house-seed",
        str(HOUSE_SEED),
        "--strategies",
        STRATEGIES,
        "--seed",
        "1",
        "--cells",
        "--paired-against",
        "model/uniform",
        "--out",
        str(cli),
    )
    evaluation = ferret.evaluate(houses, STRATEGIES, seed=1, cells=True)
    evaluation.save(tmp_path / "py", paired_against="model/uniform")
    for name in ["trials.csv", "summary.csv", "paired.csv", "summary.md"]:
        assert (tmp_path / "py" / name).read_bytes() == (cli / name).read_bytes(), name
    against = {r["reference"] for r in read_csv(tmp_path / "py" / "paired.csv")}
    assert "model/uniform" in against, against
    with pytest.raises(ferret.ConfigError, match="paired_against"):
        evaluation.save(tmp_path / "bad", paired_against="no/such")


def test_select_over_a_saved_evaluation_matches_ferret_select(
    houses, ferret_bin, cli_run, tmp_path
):
    run = tmp_path / "run"
    ferret.evaluate(houses, STRATEGIES, seed=1).save(run)
    sel = ferret.select(run, deployments=40, trials_per_deployment=8, seed=2)
    assert (run / "replay.csv").is_file()
    out = tmp_path / "select"
    run_cli(
        ferret_bin,
        "select",
        "--trials",
        str(cli_run),
        "--deployments",
        "40",
        "--trials-per-deployment",
        "8",
        "--seed",
        "2",
        "--out",
        str(out),
    )
    same_numbers(sel.rows, read_csv(out / "selection.csv"))
    same_numbers(sel.choices, read_csv(out / "choices.csv"))
    assert sel.markdown == (out / "selection.md").read_text()
    # The oracle is never a candidate; the best single strategy has the lowest mean cost.
    assert sel.strategies == STRATEGIES.split(",")[:3]
    assert sel.best_strategy == min(sel.mean_costs, key=sel.mean_costs.get)
    assert sel.methods == ["ucb", "replay"]
    curves = sel.curves
    assert len(curves["replay"]["avg_cost"]) == 8 == len(curves["best"]["avg_cost"])
    # Cumulative regret sums per-trial regrets against the best strategy on the same houses.
    assert sel.deployments == 40 and sel.trials_per_deployment == 8
    # A second selection reads every replay from the cache and gives the same result.
    again = ferret.select(run, deployments=40, trials_per_deployment=8, seed=2)
    assert again.rows == sel.rows


def test_select_names_the_keyword_it_cannot_use(houses, tmp_path):
    run = tmp_path / "run"
    ferret.evaluate(houses[:4], STRATEGIES, seed=1).save(run)
    with pytest.raises(ferret.ConfigError, match="trials_per_deployment=5: only 4 houses"):
        ferret.select(run, deployments=3, trials_per_deployment=5)
    with pytest.raises(ferret.ConfigError, match="c=-1"):
        ferret.select(run, c=-1.0)
    with pytest.raises(ferret.ConfigError, match='draw="sometimes"'):
        ferret.select(run, draw="sometimes")
    with pytest.raises(ferret.FerretError, match="not a `ferret eval` output directory"):
        ferret.select(tmp_path / "nothing")
    # With replacement, deployments may be longer than the run has houses.
    sel = ferret.select(run, deployments=3, trials_per_deployment=6, draw="replacement")
    assert sel.trials_per_deployment == 6


def test_save_refuses_what_run_json_cannot_name(houses, tmp_path):
    mixed = ferret.generate_houses(2, 1) + ferret.generate_houses(2, 2)
    with pytest.raises(ferret.ConfigError, match="several load_houses or generate_houses calls"):
        ferret.evaluate(mixed, "model/uniform").save(tmp_path / "a")
    prior = ferret.Prior.train(houses[:4])
    with pytest.raises(ferret.ConfigError, match=r"prior.save\(path\)"):
        ferret.evaluate(houses[:2], "model/prior", prior=prior).save(tmp_path / "b")
    # A prior file is named by its absolute path, so the run can be replayed from elsewhere.
    prior.save(tmp_path / "prior.json")
    ferret.evaluate(houses[:2], "model/prior", prior=str(tmp_path / "prior.json")).save(
        tmp_path / "c"
    )
    info = json.loads((tmp_path / "c" / "run.json").read_text())
    assert info["planning"]["prior"] == str(tmp_path / "prior.json")
