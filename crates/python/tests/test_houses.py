"""Houses: loading, generating, their parts and their distance matrices."""

import json

import numpy as np
import pytest

import ferret
from conftest import run_cli


def test_generate_houses_is_deterministic_and_indexed():
    a = ferret.generate_houses(3, 11)
    b = ferret.generate_houses(3, 11)
    assert [h.index for h in a] == [0, 1, 2]
    assert [h.name for h in a] == [h.name for h in b]
    assert [[c.id for c in h.containers] for h in a] == [[c.id for c in h.containers] for h in b]
    other = ferret.generate_houses(3, 12)
    assert [[c.type for c in h.containers] for h in other] != [
        [c.type for c in h.containers] for h in a
    ]


def test_house_parts(houses):
    h = houses[0]
    assert isinstance(h, ferret.House)
    assert h.rooms and h.containers and h.objects
    room_ids = {r.id for r in h.rooms}
    for r in h.rooms:
        assert len(r.polygon) >= 3 and isinstance(r.type, str) and r.type
    for i, c in enumerate(h.containers):
        assert c.index == i
        assert c.room in room_ids
        assert c.room_type in {r.type for r in h.rooms}
        assert c.access is not None and len(c.access) == 2
        assert h.container_by_id(c.id) == c
    ids = {c.id for c in h.containers}
    for o in h.objects:
        assert o.container in ids
        assert o.type in h.contents(o.container)
    assert h.target_types() == sorted({o.type for o in h.objects})
    assert repr(h).startswith(f"House(name={h.name!r}, index=0,")
    c = h.containers[0]
    assert repr(c) == f"Container(id={c.id!r}, type={c.type!r}, room={c.room!r})"
    assert repr(h.rooms[0]) == f"Room(id={h.rooms[0].id!r}, type={h.rooms[0].type!r})"


def test_distances_are_the_matrix_over_start_and_containers(houses):
    h = houses[1]
    d = h.distances()
    n = len(h.containers)
    assert isinstance(d, np.ndarray) and d.dtype == np.float64 and d.shape == (n + 1, n + 1)
    assert np.all(np.diag(d) == 0.0)
    assert np.all(d[0, 1:] > 0.0)
    # Built once per options: the same numbers again, and other options give other numbers.
    assert np.array_equal(h.distances(), d)
    coarse = h.distances(resolution=0.1)
    assert coarse.shape == d.shape and not np.array_equal(coarse, d)


def test_load_houses_reads_what_ferret_generate_writes(tmp_path, ferret_bin):
    path = tmp_path / "houses.jsonl"
    run_cli(ferret_bin, "generate", "--count", "4", "--seed", "9", "--out", str(path))
    loaded = ferret.load_houses(path)
    assert [h.index for h in loaded] == [0, 1, 2, 3]
    assert all(h.name.startswith("houses.jsonl") for h in loaded)
    some = ferret.load_houses(str(path), range="1..3")
    assert [h.index for h in some] == [1, 2]
    assert [h.index for h in ferret.load_houses(path, range=range(2, 4))] == [2, 3]
    assert [c.id for c in some[0].containers] == [c.id for c in loaded[1].containers]
    # A gzip file reads the same.
    import gzip

    gz = tmp_path / "houses.jsonl.gz"
    gz.write_bytes(gzip.compress(path.read_bytes()))
    assert [h.name.split("#")[1] for h in ferret.load_houses(gz)] == ["0", "1", "2", "3"]


def test_skip_invalid_warns_and_keeps_the_rest(tmp_path, ferret_bin):
    path = tmp_path / "houses.jsonl"
    run_cli(ferret_bin, "generate", "--count", "3", "--seed", "2", "--out", str(path))
    lines = path.read_text().splitlines()
    lines[1] = "{not json"
    path.write_text("\n".join(lines) + "\n")
    with pytest.warns(UserWarning, match=r"skipped: .*house 1"):
        kept = ferret.load_houses(path, skip_invalid=True)
    assert [h.index for h in kept] == [0, 2]


def test_scene_files_load(tmp_path):
    scene = {
        "ferret_scene": 1,
        "name": "flat",
        "rooms": [
            {"name": "living", "type": "LivingRoom", "polygon": [[0, 0], [6, 0], [6, 4], [0, 4]]}
        ],
        "containers": [
            {
                "id": "table",
                "type": "DiningTable",
                "room": "living",
                "pose": [4, 2, 0],
                "contents": ["Apple"],
            },
            {
                "id": "shelf",
                "type": "Shelf",
                "room": "living",
                "pose": [1, 3, 0],
                "contents": ["Book"],
            },
        ],
        "start": [0.5, 0.5, 0],
    }
    path = tmp_path / "flat.json"
    path.write_text(json.dumps(scene))
    [h] = ferret.load_houses(path)
    assert [c.id for c in h.containers] == ["table", "shelf"]
    assert h.contents("table") == ["Apple"]
    assert h.distances().shape == (3, 3)
