"""The search space's display models: importance follows the coordinate J depends on, the surface's mean
follows J, and the failure probability is high where evaluations failed."""

import numpy as np
import pytest

from driftlab.core.errors import ConfigError
from driftlab.core.search_space import fit_models, surface

BOUNDS = {"c_lr": (0.0, 1.0), "c_rl": (0.0, 1.0), "k": (0.0, 1.0)}


def _history(n=60, seed=3):
    rng = np.random.default_rng(seed)
    thetas = [dict(zip(BOUNDS, rng.random(3), strict=True)) for _ in range(n)]
    completed = [t["k"] < 0.7 for t in thetas]  # a failure region at high k
    values = [(t["c_lr"] - 0.3) ** 2 * 10.0 if ok else 5.0 for t, ok in zip(thetas, completed, strict=True)]
    return thetas, values, completed


def test_importance_ranks_the_coordinate_that_moves_J_first():
    models = fit_models(BOUNDS, *_history())
    importance = models.importance()
    assert abs(sum(importance.values()) - 1.0) < 1e-9
    assert importance["c_lr"] > 0.8, importance  # J depends on c_lr only (among the completed evaluations)


def test_the_surface_follows_J_and_the_failure_region():
    models = fit_models(BOUNDS, *_history())
    s = surface(models, "c_lr", "k", n_grid=11)
    assert s.mean_J.shape == (11, 11) and s.std_J.shape == (11, 11)
    row = 3  # k = 0.3: inside the completed region
    assert int(np.argmin(s.mean_J[row])) == 3  # c_lr = 0.3, J's minimum
    assert s.mean_J[row, 10] > s.mean_J[row, 3] + 2.0
    assert s.p_failure[10].mean() > 0.7 and s.p_failure[1].mean() < 0.3  # k = 1.0 fails, k = 0.1 completes
    assert set(s.held) == {"c_rl"} and s.held["c_rl"] == pytest.approx(models.best_theta["c_rl"])


def test_no_completion_yet_gives_no_surface_but_no_error():
    thetas, values, _ = _history(5)
    models = fit_models(BOUNDS, thetas, values, [False] * 5)
    s = surface(models, "c_lr", "c_rl", n_grid=5)
    assert models.importance() is None and s.mean_J is None and s.p_failure is None


@pytest.mark.parametrize(("x", "y", "grid", "field"), [("nope", "k", 10, "x"), ("k", "k", 10, "y"),
                                                       ("c_lr", "k", 1, "grid"), ("c_lr", "k", 61, "grid")])
def test_bad_choices_name_the_field(x, y, grid, field):
    models = fit_models(BOUNDS, *_history(10))
    with pytest.raises(ConfigError) as info:
        surface(models, x, y, n_grid=grid)
    assert info.value.field == field and str(info.value).startswith(field)
