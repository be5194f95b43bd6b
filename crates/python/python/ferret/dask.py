"""Sharded evaluation on a Dask cluster: one ``ferret.evaluate(..., shard=(i, n))`` per task,
then :func:`ferret.merge` into the run one machine writes.

Dask is an optional extra (``pip install "dask[distributed]"``); ferret does not depend on it.
Houses are Rust objects that do not travel between processes, so each task loads its houses
itself with ``load`` (a picklable callable, e.g. ``functools.partial(ferret.load_houses, path)``
or ``functools.partial(ferret.generate_houses, 100)``), keeps its shard's houses and writes its
run directory (with its own LLM cache) under ``out``: workers and client must share that file
system (a ``LocalCluster``, or a cluster on a shared disk).

Example::

    from dask.distributed import Client, LocalCluster
    from functools import partial
    import ferret, ferret.dask

    with LocalCluster(n_workers=4, threads_per_worker=1) as cluster, Client(cluster) as client:
        result = ferret.dask.evaluate_sharded(
            client, partial(ferret.generate_houses, 100), "runs/eval", shards=4,
            trials_per_house="all")
    print(result["merged"])  # runs/eval/merged: trials.csv, summary.csv, paired.csv, ...
"""

from __future__ import annotations

import os
from typing import Any, Callable, Dict, Optional, Sequence

import ferret

__all__ = ["evaluate_shard", "evaluate_sharded"]


def evaluate_shard(
    load: Callable[[], Sequence[Any]],
    out: str,
    index: int,
    count: int,
    paired_against: Optional[Sequence[str]] = None,
    **evaluate_kwargs: Any,
) -> str:
    """Runs shard ``index`` of ``count`` and saves it to ``out/shard-<index>``; returns that
    directory. The shard's LLM cache is ``out/shard-<index>/llm-cache.sqlite`` unless
    ``llm_cache`` is given."""
    directory = os.path.join(out, f"shard-{index}")
    os.makedirs(directory, exist_ok=True)
    evaluate_kwargs.setdefault("llm_cache", os.path.join(directory, "llm-cache.sqlite"))
    evaluation = ferret.evaluate(load(), shard=(index, count), **evaluate_kwargs)
    evaluation.save(directory, paired_against=paired_against)
    return directory


def evaluate_sharded(
    client: Any,
    load: Callable[[], Sequence[Any]],
    out: str,
    shards: int,
    *,
    paired_against: Optional[Sequence[str]] = None,
    **evaluate_kwargs: Any,
) -> Dict[str, Any]:
    """Evaluates the houses ``load()`` returns in ``shards`` shards on the Dask ``client`` (one
    task per shard, ``shard=(i, shards)``; the trials are those of one machine) and merges them
    into ``out/merged``. Other keyword arguments go to :func:`ferret.evaluate`.

    Returns :func:`ferret.merge`'s dict with ``merged`` (the merged run directory) and
    ``shards`` (the shards' directories). Raises what a failed task raised; a cache conflict
    (two shards given different answers to one question) is in ``conflicts``."""
    if shards < 1:
        raise ValueError(f"shards={shards}: at least 1")
    out = os.path.abspath(out)
    futures = [
        client.submit(
            evaluate_shard,
            load,
            out,
            i,
            shards,
            paired_against,
            key=f"ferret-shard-{i}-of-{shards}-{out}",
            pure=False,
            **evaluate_kwargs,
        )
        for i in range(shards)
    ]
    directories = client.gather(futures)
    merged = os.path.join(out, "merged")
    result = ferret.merge(directories, merged)
    result["merged"] = merged
    result["shards"] = directories
    return result
