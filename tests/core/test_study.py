"""Study specifications, the convergence band and the grid table: pure functions, checked by hand."""

import math
import statistics

import numpy as np
import pytest

from driftlab.core.convergence import band, best_so_far
from driftlab.core.errors import ConfigError
from driftlab.core.study import MAX_GRID_CELLS, RobustnessStudySpec, SeedsStudySpec, grid_table, study_spec_from_dict


def test_best_so_far_counts_completed_evaluations_only():
    assert best_so_far([5.0, -0.2, 6.0, -0.5, -0.1], [False, True, False, True, True]) == [None, -0.2, -0.2, -0.5,
                                                                                          -0.5]


def test_band_is_the_median_and_quartiles_of_the_curves_that_have_a_value():
    curves = [[None, 1.0, 0.5], [2.0, 1.5, 1.5], [3.0, 0.0]]
    out = band(curves)
    assert out["iterations"] == [0, 1, 2] and out["n"] == [2, 3, 2]
    assert out["median"] == [2.5, 1.0, 1.0]
    q25, _, q75 = statistics.quantiles([1.0, 1.5, 0.0], n=4, method="inclusive")
    assert out["q25"][1] == pytest.approx(q25) and out["q75"][1] == pytest.approx(q75)
    assert band([[None, None]]) == {"iterations": [], "median": [], "q25": [], "q75": [], "n": []}


def test_a_seeds_study_gives_each_job_its_own_seed_and_nothing_else_changes():
    spec = study_spec_from_dict({"kind": "seeds", "seeds": [4, 1], "spec": {"iterations": 7, "seed": 99}})
    jobs = spec.job_specs()
    assert [j.seed for j in jobs] == [4, 1] and all(j.iterations == 7 for j in jobs)
    assert jobs[0].to_dict() | {"seed": 1} == jobs[1].to_dict()


@pytest.mark.parametrize(("seeds", "message"), [([], "got none"), ([1, 1], "repeated: 1"), ([-1], "seeds[0]"),
                                                 (list(range(33)), "got 33")])
def test_bad_seeds_name_the_field(seeds, message):
    with pytest.raises(ConfigError, match="seeds") as info:
        SeedsStudySpec.from_dict({"seeds": seeds, "spec": {}})
    assert message in str(info.value)


def test_robustness_cells_are_the_cartesian_product_first_key_slowest_and_validated_by_the_config():
    spec = RobustnessStudySpec.from_dict({"theta": {"k": 0.05}, "grid": {"plant.friction_scale": [1.0, 1.2],
                                                                         "plant.mass_scale": [0.9, 1.0, 1.1]},
                                          "robust_samples": 2, "seed": 3})
    cells = spec.cells()
    assert len(cells) == 6 and cells[1] == {"plant.friction_scale": 1.0, "plant.mass_scale": 1.0}
    assert spec.cell_config(cells[5])["plant"]["mass_scale"] == 1.1 and spec.episode_seeds == [192, 193]
    with pytest.raises(ConfigError, match=r"grid\.plant\.friction_scale: plant\.friction_scale must be"):
        RobustnessStudySpec.from_dict({"theta": {}, "grid": {"plant.friction_scale": [9.0]}})
    with pytest.raises(ConfigError, match="at most 400"):
        RobustnessStudySpec.from_dict({"theta": {}, "grid": {"plant.friction_scale": [0.6 + 0.001 * i for i in range(
            MAX_GRID_CELLS + 1)]}})


def test_grid_table_lays_cells_out_by_their_index():
    grid = {"a.x": [1, 2], "b.y": [10, 20, 30]}
    cells = [{"index": i, "status": "completed" if i != 4 else "spun_out", "J": float(i)} for i in range(5)]
    table = grid_table(grid, cells)
    assert table.row_key == "a.x" and table.column_key == "b.y" and table.column_labels == ("10", "20", "30")
    assert table.J[0] == (0.0, 1.0, 2.0) and table.J[1][:2] == (3.0, 4.0) and math.isnan(table.J[1][2])
    assert table.status[1] == ("completed", "spun_out", "pending")
    assert np.array(table.J).shape == (2, 3)
