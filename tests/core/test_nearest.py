"""The optimizer's compiled nearest distances give NumPy's broadcast results to the bit (so the optimizer proposes
what it proposed before them), on random points with ties, below, at and above 8 dimensions."""

import numpy as np
import pytest

from driftlab.core.nearest import farthest_point_order, nearest_squared_distances


def _numpy_spread(candidates, chosen, count):
    dist = (np.min(np.linalg.norm(candidates[:, None, :] - chosen[None, :, :], axis=2), axis=1) if len(chosen)
            else np.full(len(candidates), np.inf))
    picked = []
    for _ in range(min(count, len(candidates))):
        j = int(np.argmax(dist))
        picked.append(j)
        dist = np.minimum(dist, np.linalg.norm(candidates - candidates[j], axis=1))
        dist[j] = -1.0
    return picked


@pytest.mark.parametrize("dim", [1, 3, 6, 8, 13, 24])
def test_the_same_bits_as_numpys_broadcast(dim):
    rng = np.random.default_rng(dim)
    for trial in range(40):
        points, others = rng.random((int(rng.integers(1, 90)), dim)), rng.random((int(rng.integers(0, 60)), dim))
        if trial % 2:  # coarse values: equal distances, where the first of equals must win
            points, others = np.round(points, 1), np.round(others, 1)
        count = int(rng.integers(0, len(points) + 2))
        assert farthest_point_order(points, others, count).tolist() == _numpy_spread(points, others, count)
        expected = (np.min(((points[:, None, :] - others[None, :, :]) ** 2).sum(axis=2), axis=1) if len(others)
                    else np.full(len(points), np.inf))
        assert np.array_equal(nearest_squared_distances(points, others), expected)
