"""What a calibration is asked to do (``driftlab calibrate``'s arguments, ``POST /api/calibrations``' body, what
the database stores of it), validated once at the edge; driftlab.core.calibration_run runs it."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from typing import Any

from driftlab.core.calibration import CalibrationPoint
from driftlab.core.config import EpisodeConfig, Theta
from driftlab.core.configure import apply_overrides, overrides_inside_window, preset_config
from driftlab.core.errors import ConfigError, OutsideDriftWindowError
from driftlab.core.limits import check_int
from driftlab.core.pruning import PruneRule

LIMITS = {"iterations": (1, 5000), "seeds": (1, 64), "rounds": (1, 5)}


def parse_points(text: str | None, field_name: str = "points") -> list[CalibrationPoint] | None:
    """'0.45@44,0.5@30' -> points (sideslip rad @ radius m)."""
    if not text:
        return None
    points = []
    for item in text.split(","):
        beta, _, radius = item.partition("@")
        try:
            points.append(CalibrationPoint(abs(float(beta)), float(radius)))
        except ValueError:
            raise ConfigError(f"{field_name}: {item.strip()!r} is not SIDESLIP@RADIUS (e.g. 0.5@44)",
                              field=field_name) from None
    return points


@dataclass(frozen=True)
class CalibrationRequest:
    """What to calibrate: the car (``plant`` preset and ``sets``, dotted config keys), the points
    (``points``: 'SIDESLIP@RADIUS,...'; default :func:`driftlab.core.calibration.default_points`), the search
    (``iterations`` weight sets per search, ``seeds`` episodes per point, the optimizer's ``seed``), ``rounds``
    per point, ``one_set`` (one weight set for all the points), the ``theta`` every set drives (default the
    untuned one) and ``prune``, the early stop of a losing weight set (driftlab.core.pruning.PruneRule's fields; the
    ones not given take its defaults, on). ``command`` is how it was asked for, stored in every profile."""

    plant: str
    sets: dict[str, Any] = field(default_factory=dict)
    points: str | None = None
    iterations: int = 150
    seeds: int = 3
    seed: int = 0
    rounds: int = 1
    one_set: bool = False
    theta: dict[str, float] = field(default_factory=dict)
    prune: dict[str, Any] = field(default_factory=dict)
    command: str = ""

    def validate(self) -> EpisodeConfig:
        """The car's config; raises ConfigError naming the field of anything out of range."""
        for name, (lo, hi) in LIMITS.items():
            check_int(name, getattr(self, name), lo, hi)
        check_int("seed", self.seed)
        if self.rounds > 1 and self.one_set:
            raise ConfigError("rounds: a round learns a theta at one point; with one_set there are several (use "
                              "rounds 1)", field="rounds")
        Theta.from_mapping(self.theta)
        self.prune_rule()
        # A car that cannot drift at its preset's sideslip is calibrated around the middle of its window.
        try:
            config = overrides_inside_window(preset_config(self.plant), self.sets)
        except OutsideDriftWindowError as exc:
            if not self.points:
                raise ConfigError(f"{exc}; --points SIDESLIP@RADIUS calibrates it where it drifts",
                                  field=exc.field) from None
            # The points given are checked one by one (split_drivable): the scenario's own drift need not exist
            # (a car with no drift on the scenario's circle is calibrated on the circles where it has one).
            config = apply_overrides(preset_config(self.plant), self.sets)
        for point in parse_points(self.points) or []:  # in the scenario's ranges (ScenarioConfig checks them)
            try:
                replace(config.scenario, sideslip_rad=point.sideslip_rad, left_radius_m=point.radius_m,
                        right_radius_m=point.radius_m)
            except ConfigError as exc:
                raise ConfigError(f"points: {point.label()}: {exc}", field="points") from None
        return config

    def prune_rule(self) -> PruneRule:
        return PruneRule.from_dict(self.prune)

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)
