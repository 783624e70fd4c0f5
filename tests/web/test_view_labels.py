"""What the view writes beside the car: ids as the API has them, full-precision theta, labels that stay
readable, axes with ticks, and a replay that says what it replays."""

import math

import numpy as np
import zstandard

from driftlab.core.episode import COLUMNS
from driftlab.core.track import FigureEight
from driftlab.web.frames import EpisodeFrames
from driftlab.web.plots import padded_range
from driftlab.web.recording import EpisodeRecorder
from driftlab.web.scene import TRIGGER_LABEL_Z_M, trigger_label_position

THETA = {"c_lr": 0.021456711687249243, "c_rl": 0.02115249732809388, "dV": 0.027863441262698907, "k": 0.0}


def _frames():
    rows = np.zeros((40, len(COLUMNS)))
    rows[:, COLUMNS.index("t_s")] = np.arange(40) * 0.05
    rows[:, COLUMNS.index("x_m")] = np.linspace(0.0, 30.0, 40)
    rows[:, COLUMNS.index("y_m")] = 88.0
    return EpisodeFrames(COLUMNS, rows, evaluation_id=1234, index=7, theta=THETA, status="completed", J=-1.2345)


def test_caption_names_the_api_id_and_the_index_and_theta_to_4_significant_digits():
    caption = _frames().caption()
    assert "evaluation id 1234 (index 7 in its job)" in caption and "#" not in caption
    assert "c_lr 0.02146, c_rl 0.02115, dV 0.02786, k 0" in caption  # full precision: the downloads and the API
    assert repr(THETA["c_lr"]) not in caption
    assert "lower is better" in caption
    assert EpisodeFrames(COLUMNS, np.zeros((0, len(COLUMNS)))).name() == "what-if episode"


def test_trigger_labels_sit_low_beside_their_post_away_from_p0():
    for x, y in ((-3.0, 0.4), (-8.0, -1.0), (0.0, 0.0)):
        lx, ly, lz = trigger_label_position(x, y)
        assert lz == TRIGGER_LABEL_Z_M < 5.0
        assert math.hypot(lx, ly) >= math.hypot(x, y) + 4.9  # pushed away from the P0 label


def test_state_plot_ranges_are_wide_enough_for_several_ticks():
    lo, hi = padded_range(np.array([-0.27, -0.25, -0.26]), min_span=0.4)
    assert hi - lo >= 0.4 and lo <= -0.27 and hi >= -0.25
    lo, hi = padded_range(np.array([18.0, 19.5]), min_span=0.4)
    assert lo < 18.0 and hi > 19.5 and hi - lo < 2.0


def test_a_replay_shows_its_j_and_theta():
    recorder = EpisodeRecorder()
    try:
        data = recorder.viser_file(_frames(), FigureEight())
    finally:
        recorder.stop()
    raw = zstandard.ZstdDecompressor().decompressobj().decompress(data[8:])  # after viser's 8-byte size header
    assert b"evaluation id 1234" in raw and b"J -1.234" in raw and b"c_lr 0.02146" in raw
    # No environment map: a message with no HDRI turns viser's default one off (scene.set_world)
    environment = raw[:raw.index(b"\xb5EnvironmentMapMessage")]
    assert environment[environment.rindex(b"hdri_data"):].startswith(b"hdri_data\xc0")  # msgpack's nil


def test_two_triggers_by_p0_share_one_label_and_distant_ones_have_their_own():
    from driftlab.web.scene import trigger_labels

    by_p0 = [{"t_s": 7.0, "x_m": -5.215, "y_m": -0.325}, {"t_s": 21.5, "x_m": -5.555, "y_m": 0.085}]
    [(position, text)] = trigger_labels(by_p0)
    assert text == "trigger 1  t 7.00 s · trigger 2  t 21.50 s"
    assert position == trigger_label_position(-5.215, -0.325)
    apart = trigger_labels([by_p0[0], {"t_s": 12.0, "x_m": 40.0, "y_m": 44.0}])
    assert [t for _, t in apart] == ["trigger 1  t 7.00 s", "trigger 2  t 12.00 s"]


def test_the_config_diff_table_shows_each_differing_setting_to_4_significant_digits():
    from driftlab.web.compare import config_diff_markdown

    diff = {"jobs": [{"id": 1, "name": "a"}, {"id": 2, "name": "b"}],
            "differences": [{"key": "bounds.k", "values": [[0.0, 0.12], [0.0, 0.123456]]},
                            {"key": "config.plant.steer_lag_s", "values": [0.03, None]}]}
    from driftlab.markup import plain

    table = config_diff_markdown(diff)  # every cell escaped for markdown (driftlab.markup): it reads as below
    assert "| setting | a (id 1) | b (id 2) |" in table
    row = " | ".join(plain(cell) for cell in ("bounds.k", "[0, 0.12]", "[0, 0.1235]"))
    assert f"| {row} |" in table and f"| {plain('config.plant.steer_lag_s')} | 0\\.03 | \\- |" in table
    assert config_diff_markdown({"jobs": [{"id": 1, "name": "a"}], "differences": []}) == ""


def test_the_html_replay_has_a_caption_panel_and_the_state_plots_beside_the_view():
    recorder = EpisodeRecorder()
    try:
        page = recorder.html(_frames(), FigureEight())
    finally:
        recorder.stop()
    panel = page[page.index('<aside id="driftlab-panel">'):page.index("</aside>")]
    assert "evaluation id 1234 (index 7 in its job)" in panel and "J -1.234" in panel
    assert "<td>c_lr</td><td>0.02146</td>" in panel and repr(THETA["c_lr"]) not in panel
    assert panel.count("<svg") == 4 and all(label in panel for label in ("V [m/s]", "beta [rad]", "r [rad/s]",
                                                                          "delta [rad]"))
    assert page.index("</aside>") < page.index('<div id="root">')  # the 3D player beside it, in the same page
    assert "__VISER_EMBED_DATA__" in page
