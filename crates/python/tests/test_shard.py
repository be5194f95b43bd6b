"""Sharded evaluation from Python: shards saved and merged are the one-machine run byte for
byte, with ferret.merge directly and through ferret.dask on a Dask LocalCluster."""

import functools
from pathlib import Path

import pytest

import ferret
from conftest import HOUSE_SEED, HOUSES

FILES = ("trials.csv", "summary.csv", "paired.csv", "summary.md")
OPTIONS = dict(
    strategies="optimistic+greedy,model/uniform,model/prior,oracle", trials_per_house="all"
)


def one_machine(houses, directory: Path) -> Path:
    ferret.evaluate(houses, **OPTIONS).save(directory)
    return directory


def assert_same(a: Path, b: Path):
    for f in FILES:
        assert (a / f).read_bytes() == (b / f).read_bytes(), f"{f} differs"


def test_shard_evaluations_merge_into_the_one_machine_run(houses, tmp_path):
    one = one_machine(houses, tmp_path / "one")
    dirs = []
    for i in range(3):
        ev = ferret.evaluate(houses, shard=(i, 3), **OPTIONS)
        assert {r["house_index"] % 3 for r in ev.rows} == {i}
        ev.save(tmp_path / f"s{i}")
        dirs.append(tmp_path / f"s{i}")
    result = ferret.merge(dirs[::-1], tmp_path / "merged")
    assert result["conflicts"] == []
    assert result["houses"] == HOUSES
    assert_same(one, tmp_path / "merged")


def test_merge_refuses_overlaps_and_gaps_naming_them(houses, tmp_path):
    for i in range(2):
        ferret.evaluate(houses, shard=(i, 3), **OPTIONS).save(tmp_path / f"s{i}")
    with pytest.raises(ferret.ConfigError, match=r"shards missing: 2 of 3"):
        ferret.merge([tmp_path / "s0", tmp_path / "s1"], tmp_path / "m")
    with pytest.raises(ferret.ConfigError, match=r"s1.*overlap.*shard 1/3"):
        ferret.merge([tmp_path / "s0", tmp_path / "s1", tmp_path / "s1"], tmp_path / "m")
    with pytest.raises(ferret.ConfigError, match=r"shard"):
        ferret.evaluate(houses, shard=(3, 3), **OPTIONS)


def test_dask_local_cluster_shards_merge_into_the_one_machine_run(houses, tmp_path):
    distributed = pytest.importorskip("distributed")
    import ferret.dask

    one = one_machine(houses, tmp_path / "one")
    with (
        distributed.LocalCluster(
            n_workers=2,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
        ) as cluster,
        distributed.Client(cluster) as client,
    ):
        result = ferret.dask.evaluate_sharded(
            client,
            functools.partial(ferret.generate_houses, HOUSES, HOUSE_SEED),
            str(tmp_path / "dask"),
            shards=3,
            **OPTIONS,
        )
    assert len(result["shards"]) == 3
    assert result["conflicts"] == []
    assert_same(one, Path(result["merged"]))
