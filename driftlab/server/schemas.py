"""Request bodies and responses of the REST API."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from driftlab.core.tuning import MAX_ITERATIONS


class JobCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: str | None = Field(default=None, min_length=1, max_length=200)
    iterations: int = Field(ge=1, le=MAX_ITERATIONS)
    seed_points: int = Field(default=20, ge=1, le=1000)
    active_set: int = Field(default=400, ge=10, le=5000)
    seed: int = Field(default=0, ge=0, le=2**31 - 1)
    bounds: dict[str, tuple[float, float]] | None = Field(default=None, max_length=4)
    config: dict[str, Any] | None = Field(default=None, description="dotted keys as `driftlab --set`, "
                                          "e.g. {\"plant.steer_lag_s\": 0.02}, or nested sections")
