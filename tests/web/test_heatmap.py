"""The robustness heatmap's HTML: each cell as stored, coloured by J, failures named."""

from driftlab.core.study import grid_table
from driftlab.web.heatmap import FAILED_COLOR, heatmap_html, j_color


def test_the_lowest_j_is_yellow_and_the_highest_purple():
    assert j_color(-1.0, -1.0, 2.0) == "#fde725" and j_color(2.0, -1.0, 2.0) == "#440154"


def test_cells_show_j_or_how_they_failed():
    table = grid_table({"plant.mass_scale": [1.0, 1.1]}, [{"index": 0, "status": "completed", "J": -0.25},
                                                         {"index": 1, "status": "spun_out", "J": 6.5}])
    page = heatmap_html(table, "t")
    assert ">-0.25</td>" in page and ">spun_out</td>" in page and FAILED_COLOR in page
    assert "from -0.25 (yellow, best) to -0.25" in page and "1 failed" in page
