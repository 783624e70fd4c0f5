"""Request bodies and path/query types of the REST API. Integers are strict (no booleans, no numeric strings)
and their ranges come from the one table in :mod:`driftlab.core.limits`."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from fastapi import Path, Query
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, model_validator

from driftlab.core.config import THETA_KEYS, check_json_types
from driftlab.core.errors import ConfigError
from driftlab.core.limits import JOB_LIMITS
from driftlab.core.pruning import CONFIDENCE_LIMITS, DEFAULT_CONFIDENCE, DEFAULT_MIN_SEEDS, MIN_SEEDS_LIMITS
from driftlab.core.stopping import NO_IMPROVEMENT_BY, NO_IMPROVEMENT_EVALUATIONS, TIME_BUDGET_LIMITS_S
from driftlab.core.tuning import DEFAULT_CONFIRM_SAMPLES, DEFAULT_ROBUST_SAMPLES, DEFAULT_SEED_POINTS
from driftlab.core.warm_start import MAX_WARM_JOBS
from driftlab.names import MAX_NAME_LENGTH, name_problem

MAX_ENQUEUED = 100  # thetas one request may enqueue
MAX_ID = 2**63 - 1  # SQLite's INTEGER; larger ids cannot exist (and used to overflow into a 500)
MAX_PAGE = 1000

JobId = Annotated[int, Path(ge=1, le=MAX_ID, description="a job's id")]
EvaluationId = Annotated[int, Path(ge=1, le=MAX_ID, description="an evaluation's id (global, as in the API)")]
After = Annotated[int, Query(ge=-1, le=MAX_ID, description="only evaluations with index > after")]
Limit = Annotated[int, Query(ge=1, le=MAX_PAGE, description="at most this many evaluations")]
JOBS_PAGE = 100  # a job's summary carries its spec (~12 kB): 100 of them are ~1 MB
JobsAfter = Annotated[int, Query(ge=0, le=MAX_ID, description="only jobs with a larger id")]
JobsLimit = Annotated[int, Query(ge=1, le=MAX_PAGE, description="at most this many jobs")]
WaitingAfter = Annotated[int, Query(ge=0, le=MAX_ID, description="only enqueued thetas with a larger id")]
WaitingLimit = Annotated[int, Query(ge=1, le=MAX_PAGE, description="at most this many enqueued thetas")]


def _checked_name(name: str) -> str:
    problem = name_problem(name)
    if problem is not None:
        raise ValueError(problem)
    return name


# A job's or a study's name: printable text that reads as typed (driftlab.names).
Name = Annotated[str, Field(min_length=1, max_length=MAX_NAME_LENGTH), AfterValidator(_checked_name)]


def _limited(name: str, default: int | None = None, description: str = "") -> Any:
    lo, hi = JOB_LIMITS[name]
    if default is None:
        return Field(ge=lo, le=hi, strict=True, description=description)
    return Field(default=default, ge=lo, le=hi, strict=True, description=description)


# A JSON number (an integer is a number; text and true/false are not).
StrictNumber = Annotated[float, Field(strict=True)]


def check_document_types(doc: dict[str, Any]) -> None:
    """Numbers are strict inside a posted document's ``config``, ``grid`` and a seeds study's job ``spec`` too,
    as they are at its top level (pydantic checks those): "0.03" is not 0.03.

    Raises:
        ConfigError: naming the key.
    """
    check_json_types(doc.get("config") or {})
    for key, values in (doc.get("grid") or {}).items():
        for value in values if isinstance(values, list) else []:
            check_json_types({key: value})
    spec = doc.get("spec")
    if isinstance(spec, dict):
        check_json_types(spec.get("config") or {})
        for name, pair in (spec.get("bounds") or {}).items():
            if not isinstance(pair, list) or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in pair):
                raise ConfigError(f"spec.bounds.{name} must be [lo, hi], two JSON numbers, got {pair!r}",
                                  field=f"spec.bounds.{name}")


class StopCreate(BaseModel):
    """A job's stop rules besides its budget (driftlab.core.stopping)."""

    model_config = ConfigDict(extra="forbid")

    time_budget_s: StrictNumber | None = Field(default=None, ge=TIME_BUDGET_LIMITS_S[0], le=TIME_BUDGET_LIMITS_S[1],
                                               description="finish once the job has run this long in all (s)")
    no_improvement_evaluations: int | None = Field(
        default=None, ge=NO_IMPROVEMENT_EVALUATIONS[0], le=NO_IMPROVEMENT_EVALUATIONS[1], strict=True,
        description="finish once the best J has not fallen by more than no_improvement_by in this many evaluations")
    no_improvement_by: StrictNumber = Field(default=0.0, ge=NO_IMPROVEMENT_BY[0], le=NO_IMPROVEMENT_BY[1])

    @model_validator(mode="after")
    def _can_fire(self) -> StopCreate:
        # "by" alone is a rule with no window: it could never finish the job (a stored job keeps what it has).
        if "no_improvement_by" in self.model_fields_set and self.no_improvement_evaluations is None:
            raise ValueError("stop.no_improvement_evaluations: give it with stop.no_improvement_by (the "
                             f"evaluations, {NO_IMPROVEMENT_EVALUATIONS[0]}-{NO_IMPROVEMENT_EVALUATIONS[1]}, over "
                             "which the best J must fall by more than that); alone the rule can never fire")
        return self


class PruneCreate(BaseModel):
    """A job's early stop of a losing theta (driftlab.core.pruning)."""

    model_config = ConfigDict(extra="forbid")

    enabled: bool = Field(default=True, strict=True, description="false: every evaluation runs every seed")
    confidence: StrictNumber = Field(default=DEFAULT_CONFIDENCE, ge=CONFIDENCE_LIMITS[0], le=CONFIDENCE_LIMITS[1],
                                     description="how sure the paired test must be that a theta is worse than the "
                                                 "best on the same seeds before it stops")
    min_seeds: int = Field(default=DEFAULT_MIN_SEEDS, ge=MIN_SEEDS_LIMITS[0], le=MIN_SEEDS_LIMITS[1], strict=True,
                           description="paired seeds before a theta may stop")


class JobCreate(BaseModel):
    model_config = ConfigDict(extra="forbid")

    name: Name | None = None
    iterations: int = _limited("iterations", description="evaluations in total")
    seed_points: int = _limited("seed_points", DEFAULT_SEED_POINTS)
    active_set: int = _limited("active_set", 400)
    seed: int = _limited("seed", 0)
    robust_samples: int = _limited("robust_samples", DEFAULT_ROBUST_SAMPLES,
                                   "seeded episodes per evaluation; J is their mean, and the evaluation "
                                   "completes only if every episode does")
    confirm_samples: int = _limited("confirm_samples", DEFAULT_CONFIRM_SAMPLES,
                                    "more seeds an evaluation must also complete before it counts as the best "
                                    "so far (robust_samples + confirm_samples <= 64)")
    bounds: dict[str, tuple[StrictNumber, StrictNumber]] | None = Field(default=None, max_length=len(THETA_KEYS))
    model_correction: bool = Field(default=True, strict=True,
                                   description="also learn the controller model's friction and tyre-C scales "
                                               "(theta.model_mu_scale, theta.model_c_scale)")
    local_phase: bool | None = Field(default=None, strict=True,
                                     description="with model_correction: start near the uncorrected model (most of "
                                                 "the corrections' box fails) and widen the search as the models "
                                                 "learn; default: on for DriftLab's plants, off for others")
    deterministic: bool = Field(default=False, strict=True,
                                description="ask the next theta only when every earlier evaluation is stored: the "
                                            "thetas then depend on the seed and settings only, not on how many "
                                            "workers there are or which episode finishes first")
    config: dict[str, Any] | None = Field(default=None, description="dotted keys as `driftlab --set`, "
                                          "e.g. {\"plant.steer_lag_s\": 0.02}, or nested sections")
    stop: StopCreate | None = Field(default=None, description="stop rules besides the budget: a time budget, no "
                                                          "improvement")
    prune: PruneCreate | None = Field(default=None, description="stop a theta whose first seeds are worse than the "
                                      "best's on the same seeds with confidence (default: on, 0.95, 2 seeds)")
    warm_start_from: list[Annotated[int, Field(ge=1, le=MAX_ID, strict=True)]] | None = Field(
        default=None, min_length=1, max_length=MAX_WARM_JOBS,
        description="start from these stored jobs' evaluations: told to the optimizer where a job ran the same "
                    "config, else its best thetas asked first (the job's spec records which, warm_start)")


MAX_NOTES_CHARS = 10_000


class EnqueueRequest(BaseModel):
    """Thetas to evaluate next, in order (each: any of the keys the job learns, inside its box; the rest untuned)."""

    model_config = ConfigDict(extra="forbid")

    # Each theta names at least one of theta's keys; which keys this job learns and its box, the job checks (422).
    thetas: list[Annotated[dict[str, StrictNumber], Field(
        min_length=1, json_schema_extra={"propertyNames": {"enum": list(THETA_KEYS)}})]] = Field(
        min_length=1, max_length=MAX_ENQUEUED, description='e.g. [{"k": 0.06, "dV": 0.1}]')


class JobPatch(BaseModel):
    """A new budget (at least the evaluations stored; a finished job with a larger budget is queued again), new
    notes, or both; at least one of them."""

    model_config = ConfigDict(extra="forbid", json_schema_extra={"minProperties": 1})

    iterations: int | None = Field(default=None, ge=JOB_LIMITS["iterations"][0], le=JOB_LIMITS["iterations"][1],
                                   strict=True, description="a new budget: at least the evaluations stored")
    notes: str | None = Field(default=None, max_length=MAX_NOTES_CHARS,
                              description=f"free text kept with the job (at most {MAX_NOTES_CHARS} characters); "
                                          "replaces the notes stored")

    @model_validator(mode="after")
    def _something(self) -> JobPatch:
        if self.iterations is None and self.notes is None:
            raise ValueError("give iterations, notes or both")
        return self


StudyId = Annotated[int, Path(ge=1, le=MAX_ID, description="a study's id")]


class StudyCreate(BaseModel):
    """A seeds study (``seeds`` and a job ``spec``) or a robustness study (``theta`` or ``evaluation_id``, and
    a ``grid`` of config values); driftlab.core.study validates the rest and names the field it refuses."""

    model_config = ConfigDict(extra="forbid")

    kind: Literal["seeds", "robustness"]
    name: Name | None = None
    seeds: list[Annotated[int, Field(strict=True)]] | None = Field(
        default=None, description="seeds study: one job per seed, distinct, 1 to 32 of them")
    spec: dict[str, Any] | None = Field(default=None, description="seeds study: a job spec as POST /api/jobs takes")
    theta: dict[str, StrictNumber] | None = Field(default=None, description="robustness study: the theta scored")
    evaluation_id: int | None = Field(default=None, ge=1, le=MAX_ID, strict=True,
                                      description="robustness study: score this stored evaluation's theta, with "
                                                  "its job's config, seed and robust_samples")
    grid: dict[str, list[Any]] | None = Field(default=None, description="robustness study: config key -> values; "
                                              "at most 400 cells in their cartesian product")
    config: dict[str, Any] | None = Field(default=None, description="robustness study: the base config")
    robust_samples: int | None = Field(default=None, ge=1, le=JOB_LIMITS["robust_samples"][1], strict=True)
    seed: int | None = Field(default=None, ge=0, le=JOB_LIMITS["seed"][1], strict=True)
