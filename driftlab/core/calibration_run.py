"""A calibration run end to end (``driftlab calibrate`` and ``POST /api/calibrations`` both run it,
driftlab.services.calibration): the points of the car's drift window, a weight search per point or group
(driftlab.core.calibration) for each candidate model of the car, rounds that learn the theta a job would learn
there, and each result handed to ``store`` as a car profile's document (driftlab.core.car_profile), which the jobs at
that drift then take.

What it reports goes to ``on_event``: ``{"message": ...}`` lines (what a CLI prints), ``{"progress": ...}`` after
every weight set or theta tried, and ``{"profile": ...}`` when a profile is stored.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from importlib.metadata import version
from typing import Any

from driftlab.core.calibration import (
    CalibrationPoint,
    RunBatch,
    calibrate,
    default_points,
    learn_theta,
    point_config,
    split_drivable,
    unfittable,
)
from driftlab.core.calibration_checks import checked_around
from driftlab.core.calibration_request import LIMITS, CalibrationRequest, parse_points
from driftlab.core.car_profile import calibrated_window, drift_distance, limits_of, window_text
from driftlab.core.config import EpisodeConfig, Theta, config_to_dict
from driftlab.core.configure import apply_overrides
from driftlab.core.drivability import drift_window
from driftlab.core.errors import ConfigError
from driftlab.core.mpc_config import MpcConfig
from driftlab.core.plants import entry_of

Event = Callable[[dict[str, Any]], None]
Store = Callable[[dict[str, Any]], dict[str, Any]]  # a profile's document -> it stored, with its ``profile_id``
MAX_ROUNDS = LIMITS["rounds"][1]


class CalibrationStopped(Exception):
    """Raised from ``on_event`` to stop a calibration (cancelled, or its runner shuts down)."""


def _model_candidates(base: EpisodeConfig, sets: dict[str, Any]) -> list[dict[str, Any]]:
    """The controllers to calibrate, the weights searched for each and the best kept: for a car with its own tyres
    (a CommonRoad car) both the paper's independent rear forces and the rear friction circle matched to the car's
    drive answer; for a car whose steering reach is known (``PlantType.steering_reach_rad``), the controller's own
    steering limit (the paper's car's 0.6 rad, which the shipped weights were found with) and the car's whole reach
    (the VW Vanagon holds its drift at 0.62 rad, 44 m with 0.5 rad of countersteer and needs the rest for its
    flick: docs/results.md). What the request sets itself is not varied."""
    couplings: list[dict[str, Any]] = [{}]
    if entry_of(base.plant).own_car and "plant.model_drive_coupling" not in sets:
        couplings.append({"plant.model_drive_coupling": not base.plant.model_drive_coupling})
    limits: list[dict[str, Any]] = [{}]
    reach_rad = entry_of(base.plant).steering_reach_rad(base.plant)
    if reach_rad is not None and reach_rad != base.mpc.steer_limit_rad and "mpc.steer_limit_rad" not in sets:
        limits.append({"mpc.steer_limit_rad": reach_rad})
    return [{**coupling, **limit} for limit in limits for coupling in couplings]


# A point this many steps or more from the scenario's drift (driftlab.core.car_profile.drift_distance: the default
# points tiling the window, beyond the scenario's neighbours) searches only the model the nearest calibrated point
# chose: the model's structure and steering limit are the car's, the weights the point's. With every candidate at
# every point the BMW's default calibration (10 points, 4 candidates each) took 10.5 min for its first 5 points.
ALL_MODELS_WITHIN_STEPS = 2.0


def _models_for(run: _Run, group: Sequence[CalibrationPoint], documents: list[dict[str, Any]]
                ) -> tuple[list[dict[str, Any]], list[dict[str, Any]]]:
    """The candidate models a group searches (:data:`ALL_MODELS_WITHIN_STEPS`), and those it searches where none of
    them can be fitted at its points (the nearest point's model may have no fit further out)."""
    models = _model_candidates(run.given, run.request.sets)
    scenario = run.given.scenario
    if len(group) != 1 or len(models) == 1 or not documents or drift_distance(
            scenario.sideslip_rad, scenario.left_radius_m, asdict(group[0])) < ALL_MODELS_WITHIN_STEPS:
        return models, []
    point = asdict(group[0])
    nearest = min(documents, key=lambda d: (drift_distance(point["sideslip_rad"], point["radius_m"],
                                                           d["points"][0]), -d["completed"]))
    chosen = {"plant.model_drive_coupling": nearest["plant"]["model_drive_coupling"],
              "mpc.steer_limit_rad": nearest["mpc"]["steer_limit_rad"]}
    first = {k: v for k, v in chosen.items() if k not in run.request.sets}
    return [first], [model for model in models if apply_overrides(run.given, model) != apply_overrides(
        run.given, first)]


def _summary(result, points) -> dict[str, Any]:
    return {"weights": result.weights, "score": result.score, "completed": result.completed,
            "episodes": len(result.episodes), "per_point": result.per_point(points)}


def _groups(given: EpisodeConfig, points: list[CalibrationPoint], one_set: bool) -> list[list[CalibrationPoint]]:
    """The searches to run: all the points together (``one_set``), or each point on its own, from the scenario's
    own drift outwards, so that each search knows what the nearer ones found."""
    if one_set:
        return [points]
    scenario = given.scenario
    return [[p] for p in sorted(points, key=lambda p: drift_distance(scenario.sideslip_rad, scenario.left_radius_m,
                                                                     asdict(p)))]


def _needs_a_learned_theta(request: CalibrationRequest, last: dict[str, Any]) -> bool:
    """A point where no weight set completed anything with the untuned theta gets one round more than asked for: at
    the edge of a car's window the untuned flick fails whatever the weights (the BMW at 0.55 rad), and the weights
    are searched again for the theta a job learns there."""
    return (not request.one_set and last["round"] == 1 and request.rounds == 1 and not request.theta
            and not last["completed"])


def _round_centre(given: EpisodeConfig, last: dict[str, Any]) -> EpisodeConfig:
    """Where a round after the first searches: around the last round's weights where they completed something at
    the point (a round may so reach a decade further than the one before it), else around the car's own."""
    if not last["per_point"][0]["completed"]:
        return given
    return replace(given, mpc=replace(given.mpc, **last["weights"]))


@dataclass
class _Run:
    """One calibration's context while it runs. A group's candidate models are searched side by side, each in a
    thread of its own (:func:`_side_by_side`): what they share is safe to use from several threads."""

    request: CalibrationRequest
    given: EpisodeConfig
    executor_batch: RunBatch
    on_event: Event
    known: list[tuple[str, Any]]
    stage: dict[str, Any] = field(default_factory=dict)
    # Why a candidate model had no fit at a point (by its plant section, which holds the model's settings): a later
    # round or steering limit of the same model is not sent to the workers there again.
    unfitted: dict[tuple[Any, CalibrationPoint], str] = field(default_factory=dict)
    # Set when one search failed or was stopped: the searches beside it stop before their next batch.
    stopping: threading.Event = field(default_factory=threading.Event)

    def run_batch(self, batch: list[tuple[dict[str, float], dict[str, Any], int]]
                  ) -> list[tuple[str, float, float, float | None]]:
        if self.stopping.is_set():
            raise CalibrationStopped
        return self.executor_batch(batch)

    def say(self, message: str) -> None:
        self.on_event({"message": message})

    def progress(self, **values: Any) -> None:
        self.on_event({"progress": {**self.stage, **values}})


class _GroupProgress:
    """The weight searches of a group's candidate models, running side by side, reported as one: every set any of
    them tried, of ``iterations`` for each, the best score among them."""

    def __init__(self, run: _Run, searches: int) -> None:
        self.run, self.of = run, run.request.iterations * searches
        self.lock = threading.Lock()
        self.tried: dict[int, Any] = {}  # the search's number -> its Calibration

    def __call__(self, number: int, calibration) -> None:
        with self.lock:
            self.tried[number] = calibration
            best = min((c.best for c in self.tried.values()), key=lambda r: (r.score, -r.completed))
            last = calibration.tried[-1]
            self.run.progress(tried=sum(len(c.tried) for c in self.tried.values()), of=self.of,
                              best_score=best.score, best_completed=best.completed,
                              best_episodes=len(best.episodes), last_score=last.score,
                              last_completed=last.completed, episodes=len(last.episodes))


def _side_by_side(run: _Run, calls: Sequence[Callable[[], Any]]) -> list[Any]:
    """Each of ``calls``' results, in order, the calls running at once in threads of their own: one search asks for
    its next weight set while the others' episodes run, so the workers do not wait on the asks. The first
    exception (a failed batch, CalibrationStopped) stops the others before their next batch and is raised."""
    if len(calls) <= 1:
        return [call() for call in calls]
    pool = ThreadPoolExecutor(max_workers=len(calls), thread_name_prefix="calibration-search")
    futures = [pool.submit(call) for call in calls]
    try:
        wait(futures, return_when=FIRST_EXCEPTION)
        if any(f.done() and f.exception() is not None for f in futures):
            run.stopping.set()
        wait(futures)
    except BaseException:  # KeyboardInterrupt while waiting: the searches stop at their next batch
        run.stopping.set()
        raise
    finally:
        pool.shutdown(wait=False)
    errors = [f.exception() for f in futures]
    # What stopped the first search, not the CalibrationStopped it then caused in the others.
    cause = [e for e in errors if e is not None and not isinstance(e, CalibrationStopped)]
    raised = cause or [e for e in errors if e is not None]
    if raised:
        raise raised[0]
    return [f.result() for f in futures]


def _model_text(config: EpisodeConfig) -> str:
    return (f"plant.model_drive_coupling={str(config.plant.model_drive_coupling).lower()}, "
            f"mpc.steer_limit_rad={config.mpc.steer_limit_rad:g}")


def _search_candidate(run: _Run, base: EpisodeConfig, inside: list[tuple[CalibrationPoint, EpisodeConfig]],
                      outside: list[tuple[CalibrationPoint, str]], theta: Theta,
                      on_progress: Callable[[Any], None]):
    """The weights searched for one candidate model at the points ``inside`` (the calibration, or None where the
    model cannot be fitted at any of them). The workers fit each point's model with its first episode
    (driftlab.core.calibration.point_config): where a point has no fit of this model, the first batch raises; that
    point is set aside for this model (into ``outside``, one line saying why) and the others searched again."""
    request = run.request
    unfit = [(p, run.unfitted[base.plant, p]) for p, _ in inside if (base.plant, p) in run.unfitted]
    while inside:
        for point, reason in unfit:
            run.say(f"skipped the model with {_model_text(base)} at {point.label()}: {reason}")
            run.unfitted[base.plant, point] = reason
        outside.extend(unfit)
        inside[:] = [(p, c) for p, c in inside if all(p != q for q, _ in unfit)]
        if not inside:
            break
        run.say(f"calibrating {', '.join(p.label() for p, _ in inside)} with {_model_text(base)}")
        try:
            return calibrate(base, inside, run.run_batch, iterations=request.iterations, seeds=request.seeds,
                             seed=request.seed, known=[mpc for _, mpc in run.known], theta=theta,
                             on_progress=on_progress, prune=request.prune_rule())
        except ConfigError:
            unfit = unfittable(inside)  # which point's fit failed: found only after a failure
            if not unfit:
                raise
    return None


def _calibrate_group(run: _Run, centre: EpisodeConfig, points: Sequence[CalibrationPoint], theta: Theta,
                     models: list[dict[str, Any]], others: Sequence[dict[str, Any]] = ()) -> dict[str, Any] | None:
    """The weights for ``points``, each candidate model (``models``, :func:`_model_candidates`) searched and the
    better one kept: the profile's document. Where none of ``models`` can be fitted at the points, ``others`` are
    tried; None where no candidate can."""
    candidates: list[tuple[EpisodeConfig, Any, Any, Any]] = []
    unfit_models: list[dict[str, Any]] = []
    for stage in (models, others):
        if candidates:
            break
        if stage is others and stage:
            run.say(f"the nearest calibrated point's model has no fit at {', '.join(p.label() for p in points)}: "
                    "the other candidates")
        searches = []
        for change in stage:
            # Fitted at each point, not at the scenario's drift: a model that has no fit there may fit the points.
            base = apply_overrides(centre, change) if change else centre
            inside, outside = split_drivable(base, points)
            if not inside:  # this model fits none of the points: the other candidates run
                run.say(f"skipped the model with {change}: {'; '.join(reason for _, reason in outside)}")
                continue
            searches.append((base, inside, outside))
        run.stage.update(step="weights", candidates=len(searches))
        progress = _GroupProgress(run, len(searches))
        found = _side_by_side(run, [partial(_search_candidate, run, base, inside, outside, theta,
                                            partial(progress, number)) for number, (base, inside, outside)
                                    in enumerate(searches)])
        for (base, inside, outside), calibration in zip(searches, found, strict=True):
            if calibration is None:
                unfit_models.append({"model_drive_coupling": base.plant.model_drive_coupling,
                                     "steer_limit_rad": base.mpc.steer_limit_rad,
                                     "skipped": [{**asdict(p), "reason": reason} for p, reason in outside]})
                continue
            candidates.append((base, calibration, inside, outside))
    if not candidates:
        return None
    request = run.request
    base, calibration, inside, outside = min(candidates, key=lambda c: (c[1].best.score, -c[1].best.completed))
    best, start = calibration.best, calibration.tried[0]
    run.stage.update(step="verify")
    checked, around = checked_around(base, inside, best.weights, theta, run.run_batch, run.say)
    radii = sorted({p.radius_m for p, _ in inside})
    window = [drift_window(config, config.scenario.left_radius_m).as_dict()
              for config in (next(c for p, c in inside if p.radius_m == r) for r in radii)]
    summary = _summary(best, calibration.points)
    for record, verified, near in zip(summary["per_point"], checked, around, strict=True):
        record["verified"], record["verified_around"] = verified, near
    return {
        "plant_model": base.plant.model, "vehicle_id": base.plant.commonroad_vehicle,
        "plant": config_to_dict(base)["plant"], "mpc": {**config_to_dict(base)["mpc"], **best.weights},
        **summary, "start": _summary(start, calibration.points),
        "candidates": [{"model_drive_coupling": b.plant.model_drive_coupling,
                        "steer_limit_rad": b.mpc.steer_limit_rad, **_summary(c.best, c.points)}
                       for b, c, _, _ in candidates],
        "unfitted_candidates": unfit_models,
        "known": [{"from": label, **_summary(result, calibration.points)}
                  for (label, _), result in zip(run.known, calibration.known_results(), strict=True) if result],
        "points": [asdict(p) for p in calibration.points],
        "skipped": [{**asdict(p), "reason": reason} for p, reason in outside],
        "window": window, "seeds": calibration.seeds, "iterations": request.iterations,
        # What the candidates' searches ran: the weight sets the prune rule stopped early, and every episode.
        "pruned_sets": sum(r.pruned for _, c, _, _ in candidates for r in c.tried),
        "search_episodes": sum(len(r.episodes) for _, c, _, _ in candidates for r in c.tried),
        "theta": "untuned" if theta == Theta() else theta.as_dict(),
        "command": request.command, "driftlab_version": version("driftlab")}


def _learned_theta(run: _Run, point: CalibrationPoint, last: dict[str, Any]) -> Theta:
    """The theta a job at ``point`` would learn with the weights it would take now: the last round's, if they
    completed anything there, else the car's own (driftlab.core.car_profile.profile_for)."""
    request = run.request
    record = last["per_point"][0]
    weights = last["weights"] if record["completed"] else {}
    config = point_config(run.given, point)
    coupling = last["plant"].get("model_drive_coupling", False)
    if record["completed"] and coupling != config.plant.model_drive_coupling:  # the model those weights were for
        config = apply_overrides(config, {"plant.model_drive_coupling": coupling})
    config = replace(config, mpc=replace(config.mpc, **weights, **(limits_of(last) if record["completed"] else {})))
    run.stage.update(step="theta")
    theta, score = learn_theta(config, run.run_batch, iterations=request.iterations, seeds=request.seeds,
                               seed=request.seed,
                               on_progress=lambda n, best: run.progress(tried=n, of=request.iterations,
                                                                        best_score=best))
    run.say(f"learned at {point.label()}: {theta.as_dict()} (score {score:.3f})")
    return theta


def run_calibration(request: CalibrationRequest, run_batch: RunBatch, *,
                    known: Callable[[MpcConfig], list[tuple[str, MpcConfig]]], store: Store,
                    on_event: Event = lambda event: None) -> list[dict[str, Any]]:
    """Runs ``request`` on ``run_batch`` (the caller's executor), handing each profile to ``store`` as it is found;
    returns the profiles' documents, each with its ``profile_id``. ``known`` gives the weight sets known to drive
    other cars (tried after the car's own). Raises ConfigError (a bad request, no point inside the car's window)
    before any episode runs, and whatever ``on_event`` raises (CalibrationStopped) as it comes."""
    given = request.validate()
    points = parse_points(request.points) or default_points(given)
    inside, outside = split_drivable(given, points)
    for point, reason in outside:
        on_event({"message": f"skipped {point.label()}: {reason}"})
    if not inside:
        raise ConfigError("points: none of the points is inside the car's drift window (`driftlab equilibrium "
                          f"--window --plant {request.plant}` prints it)", field="points")
    run = _Run(request, given, run_batch, on_event, known(given.mpc))
    groups = _groups(given, [p for p, _ in inside], request.one_set)
    documents: list[dict[str, Any]] = []
    for number, group in enumerate(groups, 1):
        run.say(f"after the car's own weights, {len(run.known)} weight sets known to drive other cars or drifts: "
                f"{'; '.join(label for label, _ in run.known)}")
        theta, centre, rounds = Theta.from_mapping(request.theta), given, request.rounds
        mine: list[dict[str, Any]] = []  # this group's rounds
        for round_number in range(1, MAX_ROUNDS + 1):
            if round_number > rounds:
                if not _needs_a_learned_theta(request, mine[-1]):
                    break
                rounds = round_number
                run.say(f"no weight set completed {group[0].label()} with {mine[-1]['theta']} theta: one "
                        "more round learns the theta a job would learn there")
            run.stage = {"group": number, "groups": len(groups), "round": round_number, "rounds": rounds,
                         "points": [p.label() for p in group]}
            started = time.perf_counter()
            if round_number > 1:
                theta = _learned_theta(run, group[0], mine[-1])
                centre = _round_centre(given, mine[-1])
            document = _calibrate_group(run, centre, group, theta, *_models_for(run, group, documents))
            if document is None:  # no candidate model can be fitted at these points: the other groups run
                run.say(f"skipped {', '.join(p.label() for p in group)}: no candidate model can be fitted there")
                break
            document["skipped"] += [{**asdict(p), "reason": reason} for p, reason in outside]
            document["round"] = round_number
            document["wall_s"] = round(time.perf_counter() - started, 1)
            mine.append(_store(store, run, document))
            documents.append(mine[-1])
    if not documents:
        reasons = dict.fromkeys(f"{point.label()}: {reason}" for (_, point), reason in run.unfitted.items())
        raise ConfigError("points: no candidate model of the controller can be fitted at any of the points ("
                          f"{'; '.join(reasons) or 'none was drivable'})", field="points")
    run.say(window_text(calibrated_window(documents)))
    return documents


def _store(store: Store, run: _Run, document: dict[str, Any]) -> dict[str, Any]:
    """Stores a profile; its weights become known to the searches after it."""
    stored = store(document)
    found = replace(run.given.mpc, **document["weights"])
    if found != run.given.mpc and all(found != mpc for _, mpc in run.known):
        points_text = ", ".join(CalibrationPoint(**p).label() for p in document["points"])
        run.known = [(f"profile {stored['profile_id']} ({points_text})", found), *run.known]
    run.on_event({"profile": stored})
    return stored
