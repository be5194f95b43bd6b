"""Properties of the distance matrices on generated houses (hypothesis-drawn seeds)."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

import ferret


@settings(max_examples=12)
@given(seed=st.integers(min_value=0, max_value=2**32 - 1))
def test_distances_are_a_metric(seed):
    for house in ferret.generate_houses(2, seed):
        d = house.distances()
        n = len(house.containers) + 1
        assert d.shape == (n, n)
        assert np.all(np.isfinite(d)) and np.all(d >= 0.0)
        assert np.array_equal(d, d.T)
        assert np.all(np.diag(d) == 0.0)
        # d[i, k] <= d[i, j] + d[j, k] for every i, j, k.
        via = d[:, :, None] + d[None, :, :]
        assert np.all(d[:, None, :] <= via + 1e-9)


@settings(max_examples=6)
@given(
    seed=st.integers(min_value=0, max_value=2**32 - 1),
    resolution=st.sampled_from([0.05, 0.08, 0.1]),
)
def test_a_search_travels_the_legs_of_the_matrix(seed, resolution):
    [house] = ferret.generate_houses(1, seed)
    d = house.distances(resolution=resolution)
    target = house.target_types()[0]
    s = ferret.Search(house, target, "model/uniform", resolution=resolution)
    at, total = 0, 0.0
    while (c := s.next_container()) is not None:
        leg = s.record(c, target in house.contents(c))
        assert leg == d[at, c.index + 1]
        total += leg
        assert total == s.cost
        at = c.index + 1
    assert s.found is not None and target in house.contents(s.found)
