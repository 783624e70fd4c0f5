"""Range checks shared by the frozen config dataclasses (validated once, at construction)."""

from __future__ import annotations

import math
from typing import Any

from driftlab.core.errors import ConfigError


def check_ranges(obj: Any, section: str, limits: dict[str, tuple[float, float]]) -> None:
    """Raise ConfigError naming ``section.field`` and its range for the first value outside it."""
    for name, (lo, hi) in limits.items():
        value = getattr(obj, name)
        if isinstance(value, bool) or not (isinstance(value, (int, float)) and math.isfinite(value)
                                           and lo <= value <= hi):
            raise ConfigError(f"{section}.{name} must be a number in [{lo}, {hi}], got {value!r}")
