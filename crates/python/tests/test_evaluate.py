"""ferret.evaluate against the real `ferret eval`: the same houses, strategies and seed give the
very same trials and costs."""

import sys

import pytest

import ferret
from conftest import HOUSE_SEED, HOUSES, read_trials, run_cli

STRATEGIES = ["optimistic+greedy", "model/uniform", "model/prior", "model/prior/exact", "oracle"]


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
    return read_trials(out / "trials.csv")


def key(row):
    return (int(row["house_index"]), row["target"], row["strategy"])


def assert_same_trials(py_rows, cli_rows):
    assert len(py_rows) == len(cli_rows) > 0
    cli = {key(r): r for r in cli_rows}
    assert len(cli) == len(cli_rows)
    for r in py_rows:
        c = cli[key(r)]
        # Exactly: the CSV holds the shortest text that reads back as the same f64.
        assert r["cost_m"] == float(c["cost_m"]), key(r)
        assert r["searched"] == c["searched"], key(r)
        assert r["found_container"] == c["found_container"]
        assert r["searches"] == int(c["searches"])
        assert r["goal_containers"] == int(c["goal_containers"])
        assert r["house"] == c["house"]


def test_default_strategies_match_ferret_eval(houses, ferret_bin, tmp_path):
    ev = ferret.evaluate(houses, seed=5)
    assert ev.strategies == ferret.DEFAULT_STRATEGIES.split(",")
    cli = cli_eval(ferret_bin, tmp_path, "--seed", "5")
    assert_same_trials(ev.rows, cli)
    # Exactly the columns of trials.csv, in order.
    assert list(ev.rows[0]) == list(cli[0]) == ev.columns
    assert ev.houses_run == HOUSES and ev.trials_run == HOUSES and ev.errors == []
    assert len(ev) == HOUSES * len(ev.strategies)


def test_options_and_protocol_paper_match_ferret_eval(houses, ferret_bin, tmp_path):
    args = dict(
        seed=2,
        trials_per_house=2,
        reveal_fraction=0.25,
        protocol="paper",
        max_containers=5,
        search_cost=0.5,
        cells=True,
    )
    ev = ferret.evaluate(houses, "model/prior,model/uniform/exact,optimistic+greedy", **args)
    cli = cli_eval(
        ferret_bin,
        tmp_path,
        "--strategies",
        "model/prior,model/uniform/exact,optimistic+greedy",
        "--seed",
        "2",
        "--trials-per-house",
        "2",
        "--reveal-fraction",
        "0.25",
        "--protocol",
        "paper",
        "--max-containers",
        "5",
        "--search-cost",
        "0.5",
        "--cells",
    )
    assert_same_trials(ev.rows, cli)
    assert ev.columns[-1] == "cost_cells"
    for r, c in zip(sorted(ev.rows, key=key), sorted(cli, key=key)):
        assert r["cost_cells"] == float(c["cost_cells"])
    assert ev.trials_run == 2 * HOUSES


def test_a_prior_object_and_its_file_match_ferret_eval_with_the_file(houses, ferret_bin, tmp_path):
    prior = ferret.Prior.train(ferret.generate_houses(30, 77), smoothing=1.0)
    path = tmp_path / "prior.json"
    prior.save(path)
    cli = cli_eval(
        ferret_bin,
        tmp_path / "out",
        "--strategies",
        "model/prior,model/prior/k4",
        "--prior",
        str(path),
        "--seed",
        "1",
    )
    by_object = ferret.evaluate(houses, ["model/prior", "model/prior/k4"], prior=prior, seed=1)
    by_path = ferret.evaluate(houses, ["model/prior", "model/prior/k4"], prior=str(path), seed=1)
    assert_same_trials(by_object.rows, cli)
    assert by_object.rows == by_path.rows
    # A different prior plans differently somewhere: the prior is really used.
    default = ferret.evaluate(houses, ["model/prior"], seed=1)
    assert [r["searched"] for r in default.rows] != [
        r["searched"] for r in by_object.rows if r["strategy"] == "model/prior"
    ]


def test_summary_and_strategies_as_one_string(houses):
    ev = ferret.evaluate(houses[:4], "optimistic+greedy, oracle", seed=3)
    assert ev.strategies == ["optimistic+greedy", "oracle"]
    summary = ev.summary()
    assert [s["strategy"] for s in summary] == ev.strategies
    for s in summary:
        costs = [r["cost_m"] for r in ev.rows if r["strategy"] == s["strategy"]]
        assert s["trials"] == len(costs) == 4
        assert s["mean_m"] == pytest.approx(sum(costs) / len(costs))
    oracle = {r["house_index"]: r["cost_m"] for r in ev.rows if r["strategy"] == "oracle"}
    greedy = {
        r["house_index"]: r["cost_m"] for r in ev.rows if r["strategy"] == "optimistic+greedy"
    }
    assert all(oracle[h] <= greedy[h] + 1e-9 for h in oracle)


def test_to_pandas(houses, monkeypatch):
    ev = ferret.evaluate(houses[:3], ["model/uniform"], seed=0)
    pd = pytest.importorskip("pandas")
    df = ev.to_pandas()
    assert isinstance(df, pd.DataFrame)
    assert list(df.columns) == ev.columns
    assert df["cost_m"].tolist() == [r["cost_m"] for r in ev.rows]
    # Without pandas: an ImportError that says what to install.
    monkeypatch.setitem(sys.modules, "pandas", None)
    with pytest.raises(ImportError, match="pip install pandas"):
        ev.to_pandas()


def test_progress_goes_to_stderr_only_when_asked(houses, capfd):
    ferret.evaluate(houses[:2], ["model/uniform"])
    assert capfd.readouterr().err == ""
    ferret.evaluate(houses[:2], ["model/uniform"], progress=True)
    err = capfd.readouterr().err
    # Each house is mapped with its trials, a batch at a time: one step, "houses".
    assert "houses: 2/2" in err


def test_evaluate_releases_the_gil(houses):
    import threading

    started, done = threading.Event(), threading.Event()
    ticks = 0

    def work():
        started.set()
        ferret.evaluate(houses, ["model/prior/exact", "model/uniform/exact"], seed=9)
        done.set()

    t = threading.Thread(target=work)
    t.start()
    started.wait()
    # While evaluate runs (about a second), this thread keeps running Python; were the GIL
    # held, it would get one switch interval (5 ms, some ten thousand ticks) at most.
    while not done.is_set():
        ticks += 1
    t.join()
    assert ticks > 1_000_000


def test_ctrl_c_stops_a_long_evaluation_between_batches():
    """Ctrl-C (here `_thread.interrupt_main`, what SIGINT does) raises KeyboardInterrupt at the
    next batch of houses: before, it was seen only when every house had run. The run is sized
    to take minutes; the interrupt must come back in seconds. It is sent once the first house
    has run (from the progress callable), so that a loaded machine, slower to start the work,
    cannot make it arrive before the evaluation does. Python's own Ctrl-C handler is put in
    place for it: a process started in the background of a script inherits SIGINT ignored, and
    then Python installs none and `interrupt_main` does nothing."""
    import _thread
    import signal
    import time

    houses = ferret.generate_houses(4000, 11)
    sent = []

    def progress(what, done, total):
        if done > 0 and not sent:
            sent.append(time.monotonic())
            _thread.interrupt_main()

    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        with pytest.raises(KeyboardInterrupt):
            ferret.evaluate(houses, ["model/uniform/exact"], seed=0, progress=progress)
    finally:
        signal.signal(signal.SIGINT, before)
    assert sent, "the evaluation reported no progress"
    assert time.monotonic() - sent[0] < 15
