"""The parameters BO learns (paper section III-C), their limits and the paper's learned values."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from driftlab.core.errors import ConfigError
from driftlab.core.validation import check_ranges
from driftlab.core.vehicle import VehicleParams

# What a model correction may be: beyond this the model is another car, not a corrected one.
MODEL_SCALE_LIMITS = (0.5, 2.0)
THETA_KEYS = ("c_lr", "c_rl", "dV", "k", "model_mu_scale", "model_c_scale")


# What each of theta's values may be (a job's bounds may span at most this, driftlab.core.tuning).
THETA_LIMITS: dict[str, tuple[float, float]] = {"c_lr": (0.0, 0.5), "c_rl": (0.0, 0.5), "dV": (-5.0, 5.0),
                                                "k": (-1.0, 1.0), "model_mu_scale": MODEL_SCALE_LIMITS,
                                                "model_c_scale": MODEL_SCALE_LIMITS}


@dataclass(frozen=True)
class Theta:
    """The parameters BO learns (paper section III-C).

    Attributes:
        c_lr: trigger fraction ending the left-hand drift [-].
        c_rl: trigger fraction ending the right-hand drift [-].
        dV: speed correction added to the equilibrium speed, V_hat = V_eq + dV [m/s] (paper eq. 10).
        k: look-ahead steering feedback gain, delta_f = delta + k e_la [rad/m] (paper eq. 11).
        model_mu_scale: the controller's model friction mu x this [-] (DriftLab's model correction, not in the
            paper): the drift equilibria the MPC is linearized about and steers to move with it.
        model_c_scale: the controller's model tyre shape factor C x this [-] (model correction, as above).

    The two model corrections learn what dV alone cannot: on a plant whose own drift at the scenario's radius
    and sideslip is 1-3 m/s off the model's, the additive disturbance estimate absorbs the linearization error
    and the offset-free target lands away from the plant's drift (benchmarks/envelope.py). 1.0 is the model
    as configured, so a theta stored without them means what it meant.
    """

    c_lr: float = 0.02
    c_rl: float = 0.02
    dV: float = 0.0
    k: float = 0.05
    model_mu_scale: float = 1.0
    model_c_scale: float = 1.0

    def __post_init__(self) -> None:
        check_ranges(self, "theta", THETA_LIMITS)

    @classmethod
    def from_mapping(cls, values: dict[str, Any]) -> Theta:
        unknown = set(values) - set(THETA_KEYS)
        if unknown:
            raise ConfigError(f"theta has no key {sorted(unknown)[0]!r}; allowed: {', '.join(THETA_KEYS)}")
        parsed = {}
        for key, raw in values.items():
            try:
                if isinstance(raw, bool):
                    raise ValueError
                parsed[key] = float(raw)
            except (TypeError, ValueError):
                raise ConfigError(f"theta.{key} must be a number, got {raw!r}") from None
        return cls(**parsed)

    def as_dict(self) -> dict[str, float]:
        return {k: float(getattr(self, k)) for k in THETA_KEYS}

    @staticmethod
    def filled(values: Mapping[str, float]) -> dict[str, float]:
        """A theta as a mapping with every key: the ones it lacks at their defaults (a theta stored before the
        model corrections existed has none of their scales: 1, the model as fitted). Not validated."""
        return {**Theta().as_dict(), **values}

    def model_vehicle(self, vehicle: VehicleParams) -> VehicleParams:
        """The car the controller's model assumes: ``vehicle`` with the model corrections applied (the plant
        keeps ``vehicle`` and its own scales).

        Raises:
            ConfigError: a corrected value outside the vehicle's own range (naming the theta key).
        """
        if self.model_mu_scale == 1.0 and self.model_c_scale == 1.0:
            return vehicle
        try:
            return vehicle.scaled(friction=self.model_mu_scale, tyre_c=self.model_c_scale)
        except ConfigError as exc:
            raise ConfigError(f"theta.model_mu_scale / theta.model_c_scale: {exc}", field="theta") from None


PAPER_THETA = Theta(c_lr=0.0273, c_rl=0.0215, dV=0.12, k=0.21)
