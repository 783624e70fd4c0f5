"""Calibration (driftlab.core.calibration): the weight search's own parts, with the real optimizer; the episodes
of a whole calibration are in tests/test_calibrate_cli.py."""

import math
from dataclasses import asdict

import pytest

from driftlab.core.calibration import (
    CALIBRATION_SEED_BASE,
    CalibrationPoint,
    calibrate,
    default_points,
    search_bounds,
    search_point,
    split_drivable,
    weights_of,
)
from driftlab.core.config import EpisodeConfig
from driftlab.core.configure import apply_overrides, preset_config
from driftlab.core.mpc_config import MpcConfig
from driftlab.core.robust import RESCORE_SEED_BASE


def test_weights_go_to_the_search_space_and_back():
    mpc = MpcConfig()
    weights = weights_of(search_point(mpc))
    for name, value in weights.items():
        assert value == pytest.approx(getattr(mpc, name), rel=1e-12), name


def test_calibration_seeds_are_neither_tuning_nor_rescore_seeds():
    assert CALIBRATION_SEED_BASE > RESCORE_SEED_BASE + 10**6  # rescores draw 2^40 + j, tuning seed x 64 + j


def test_the_default_points_tile_the_cars_window_on_its_circle():
    """Every drift of the window a job of the BMW is checked against (0.44-0.80 rad at 44 m: both ways countersteer)
    lies less than one step from a default point, so some profile of a default calibration applies to it."""
    from driftlab.core.car_profile import drift_distance
    from driftlab.core.drivability import drivable_reason

    config = preset_config("commonroad_std")
    points = default_points(config)
    assert points[-2:] == [CalibrationPoint(0.5, 30.0), CalibrationPoint(0.5, 52.0)]
    on_circle = points[:-2]
    assert CalibrationPoint(0.5, 44.0) in on_circle and all(p.radius_m == 44.0 for p in on_circle)
    assert all(drivable_reason(apply_overrides(config, p.overrides())) is None for p in on_circle)
    inside = [b / 100 for b in range(20, 81)
              if drivable_reason(apply_overrides(config, {"scenario.sideslip_rad": b / 100})) is None]
    assert inside[0] == 0.44 and inside[-1] == 0.8
    for beta in inside:
        assert min(drift_distance(beta, 44.0, asdict(p)) for p in on_circle) < 1.0, beta
    assert [p.sideslip_rad for p in on_circle] == [0.45, 0.5, 0.55, 0.6, 0.65, 0.7, 0.75, 0.8]


def test_points_outside_the_cars_window_are_set_aside_with_the_reason():
    inside, outside = split_drivable(preset_config("commonroad_std"),
                                     [CalibrationPoint(0.5, 44.0), CalibrationPoint(0.2, 44.0)])
    assert [p for p, _ in inside] == [CalibrationPoint(0.5, 44.0)]
    assert inside[0][1].scenario.sideslip_rad == 0.5
    (point, reason), = outside
    assert point == CalibrationPoint(0.2, 44.0) and "0.2" in reason


def test_the_search_starts_from_the_cars_weights_and_improves_on_them():
    """Episodes replaced by a known landscape: every episode completes where the sideslip weight is in a band, with
    J the squared distance of its log to 2.2; the start (the default weights, log 2.79) fails half of them."""
    base = EpisodeConfig()
    points = [(CalibrationPoint(0.4, 44.0), base), (CalibrationPoint(0.4, 30.0), base)]
    calls = []

    def run_batch(batch):
        calls.append(len(batch))
        out = []
        for _, doc, seed in batch:
            x = math.log10(doc["mpc"]["q_sideslip"])
            ok = 1.6 < x < 2.6 or seed % 2 == 0
            out.append(("completed" if ok else "spun_out", (x - 2.2) ** 2 - 1.0, 1.0 if ok else 0.4, 0.1))
        return out

    calibration = calibrate(base, points, run_batch, iterations=40, seeds=2, seed=1)
    assert calls == [4] * 40  # two points x two seeds per weight set
    assert calibration.tried[0].weights["q_sideslip"] == pytest.approx(base.mpc.q_sideslip)
    start, best = calibration.tried[0], calibration.best
    assert start.completed == 2 and best.completed == 4 and best.score < start.score
    assert 1.6 < math.log10(best.weights["q_sideslip"]) < 2.6
    assert best.per_point([p for p, _ in points])[0]["completed"] == 2


def test_weight_sets_known_to_drive_other_cars_are_tried_right_after_the_cars_own():
    """The landscape of the test above: a known set inside the band completes everywhere from the second set on,
    and a known set outside the search box is clipped into it."""
    from dataclasses import replace

    base = EpisodeConfig()
    points = [(CalibrationPoint(0.4, 44.0), base)]

    def run_batch(batch):
        out = []
        for _, doc, _ in batch:
            x = math.log10(doc["mpc"]["q_sideslip"])
            ok = 1.6 < x < 2.6
            out.append(("completed" if ok else "spun_out", (x - 2.2) ** 2 - 1.0, 1.0 if ok else 0.4, 0.1))
        return out

    good, far = replace(base.mpc, q_sideslip=10 ** 2.2), replace(base.mpc, q_sideslip=1e-6)
    calibration = calibrate(base, points, run_batch, iterations=5, seeds=1, known=[good, far])
    sideslip = [math.log10(result.weights["q_sideslip"]) for result in calibration.tried]
    assert sideslip[1] == pytest.approx(2.2) and calibration.tried[1].completed == 1
    lo, _ = search_bounds(base.mpc)["log10_q_sideslip"]
    assert sideslip[2] == pytest.approx(lo)
    assert calibration.best.weights["q_sideslip"] == pytest.approx(10 ** 2.2)


def test_a_round_learns_the_theta_a_job_would_learn_at_the_point():
    """Episodes replaced by a landscape in theta: every episode completes where dV > 0.1, J lowest at dV 0.2; the
    untuned theta (dV 0) fails, as it does at the edge of a car's window."""
    from driftlab.core.calibration import learn_theta

    def run_batch(batch):
        out = []
        for theta, _, _ in batch:
            ok = theta["dV"] > 0.1
            out.append(("completed" if ok else "gripped_up", (theta["dV"] - 0.2) ** 2 - 1.0, 1.0 if ok else 0.3, 0.2))
        return out

    progress = []
    theta, score = learn_theta(EpisodeConfig(), run_batch, iterations=30, seeds=2,
                               on_progress=lambda n, best: progress.append(n))
    assert theta.dV > 0.1 and score < 0.0 and progress == list(range(1, 31))


def test_a_weight_set_clearly_worse_on_its_first_seeds_stops_there_and_one_that_may_be_best_runs_them_all():
    """The landscape above, three seeds a point, the job's prune rule (0.95, 2 seeds): a set worse than the best one
    on the same seeds (failing where it completes, or completing further from the optimum) stops after the first two
    seeds at each point, scored on them; the best ran every seed."""
    from driftlab.core.pruning import PruneRule

    base = EpisodeConfig()
    points = [(CalibrationPoint(0.4, 44.0), base), (CalibrationPoint(0.4, 30.0), base)]

    def run_batch(batch):
        out = []
        for _, doc, seed in batch:
            x = math.log10(doc["mpc"]["q_sideslip"])
            ok = 1.6 < x < 2.6
            out.append(("completed" if ok else "spun_out", (x - 2.2) ** 2 - 1.0 + 0.01 * (seed % 3),
                        1.0 if ok else 0.4 + 0.01 * (seed % 5), 0.1))
        return out

    pruned_run = calibrate(base, points, run_batch, iterations=40, seeds=3, seed=1, prune=PruneRule())
    first_two = set(pruned_run.seeds[:2])
    best, pruned = pruned_run.best, [r for r in pruned_run.tried if r.pruned]
    assert not best.pruned and len(best.episodes) == 2 * 3
    assert pruned and all(len(r.episodes) == 2 * 2 and {e.seed for e in r.episodes} == first_two for r in pruned)
    assert all(r.score > best.score for r in pruned) and any(r.completed == 0 for r in pruned)
    assert all(len(r.episodes) == 6 for r in pruned_run.tried if not r.pruned)
    everything = calibrate(base, points, run_batch, iterations=40, seeds=3, seed=1, prune=PruneRule(enabled=False))
    assert not any(r.pruned for r in everything.tried) and all(len(r.episodes) == 6 for r in everything.tried)
    assert 1.6 < math.log10(best.weights["q_sideslip"]) < 2.6
