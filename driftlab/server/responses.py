"""What the REST API answers: the response bodies of its routes and of its errors, for the OpenAPI document
(clients and schemathesis read it) and as the routes' ``response_model`` (FastAPI checks a route's answer
against it). The bodies themselves are built in driftlab.server.serialize and driftlab.services.studies."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import BaseModel, Field

JobStatusName = Literal["queued", "running", "paused", "finished", "failed"]  # driftlab.db.lifecycle.WorkStatus
Timestamp = Annotated[str, Field(description="ISO 8601, UTC")]


class FieldError(BaseModel):
    field: str = Field(description="the request field, dotted (e.g. iterations, config.plant.mass_scale, body)")
    message: str


class ErrorBody(BaseModel):
    """Every error: what went wrong in ``detail`` (it starts with the field for a bad request); a 422 about a
    request field also lists the fields in ``errors``."""

    detail: str
    errors: list[FieldError] | None = None


ERROR_DESCRIPTIONS = {
    400: "The Host header names another server than this one (127.0.0.1, localhost or DRIFTLAB_ALLOWED_HOSTS).",
    401: "A token is set (DRIFTLAB_TOKEN) and the request does not carry 'Authorization: Bearer <token>'.",
    403: "No token is set and a browser on another origin sent the request.",
    404: "No such job, evaluation or study (or nothing of it yet).",
    408: "The request body paused longer than DRIFTLAB_BODY_TIMEOUT_S between two chunks.",
    409: "Not in this state: the resource's status does not allow it, or the name is taken.",
    413: "The body is larger than DRIFTLAB_MAX_BODY_BYTES.",
    422: "The request is invalid: ``detail`` says why, naming the field.",
    503: "The storage is unavailable (read-only, full, locked past the timeout), or, for a heavy read, as many are "
         "running as DRIFTLAB_MAX_HEAVY_READS allows (Retry-After says when to ask again); nothing was changed.",
}


def errors(*codes: int) -> dict[int | str, dict[str, Any]]:
    """The ``responses=`` of a route that can answer with these error codes."""
    return {code: {"model": ErrorBody, "description": ERROR_DESCRIPTIONS[code]} for code in codes}


def media(content_type: str, schema: dict[str, Any], description: str) -> dict[int | str, dict[str, Any]]:
    """The 200 of a route that answers with another content type than JSON (too)."""
    return {200: {"description": description, "content": {content_type: {"schema": schema}}}}


class Health(BaseModel):
    status: Literal["ok"]


class ViewStatus(BaseModel):
    clients: int = Field(description="open browser tabs of the 3D view")


class Evaluation(BaseModel):
    id: int
    job_id: int
    index: int = Field(description="0-based, in order of completion")
    theta: dict[str, float]
    J: float = Field(description="mean over its seeded episodes, a failed one at its failure penalty")
    status: str
    completed: bool
    metrics: dict[str, Any]
    trigger_points: list[dict[str, Any]]
    wall_ms: float
    seeds: list[dict[str, Any]] | None = Field(description="one entry per episode: seed, status, J, ...")
    trajectory_seed: int | None
    created_at: Timestamp
    enqueued: bool = Field(default=False, description="a theta someone enqueued (POST /api/jobs/{id}/enqueue), "
                                                      "not the optimizer's proposal")


class BestSummary(BaseModel):
    """The best evaluation so far, as a job shows it (``id`` is the evaluation's)."""

    id: int
    index: int
    theta: dict[str, float]
    J: float
    status: str
    seeds: list[dict[str, Any]] | None
    trajectory_seed: int | None


class BestTold(BaseModel):
    """The best completed evaluation a warm start told the job (from jobs of its own config: the job continues
    them); its J is the source's, on the source's seeds."""

    theta: dict[str, float]
    J: float
    from_jobs: list[int]


class Job(BaseModel):
    id: int
    name: str
    status: JobStatusName
    detail: str | None = Field(description="what a running job does when its status alone does not say")
    seed: int
    n_done: int
    iterations: int
    progress: float
    eta_s: float | None
    error: str | None
    best: BestSummary | None
    best_told: BestTold | None = Field(default=None, description="where a warm start continued jobs of the same "
                                       "config: the best of their evaluations it told, the job's start")
    runner_id: str | None
    study_id: int | None
    profile_id: int | None = Field(default=None, description="the car profile (driftlab calibrate) whose MPC weights "
                                                             "the job took, if any")
    spec: dict[str, Any] = Field(description=(
        "the validated job document (POST /api/jobs), config in full; a car whose controller's model is fitted to "
        "its own drift (a CommonRoad car) lacks config.vehicle and config.plant.initial_rear_slip until a runner "
        "claims the job and stores them fitted"))
    run_s: float = Field(default=0.0, description="wall time of its finished runs, in all (what a time budget "
                                                  "counts, with the current run's)")
    stop_reason: str | None = Field(default=None, description="the stop rule that finished it, if one did")
    notes: str = Field(description="free text kept with the job (PATCH /api/jobs/{id} with notes)")
    created_at: Timestamp
    warning: str | None = Field(default=None, description=(
        "in the answer to the POST that created the job: its car has calibrated weights (driftlab calibrate), none "
        "for its drift; names the nearest calibrated drift and the command that calibrates this one"))


class EnqueuedTheta(BaseModel):
    id: int
    theta: dict[str, float]


class Enqueued(BaseModel):
    """The thetas a request enqueued (their ids), how many wait for the job in all, and a page of them, next first
    (at most 100; ``GET .../enqueue?after=<last id>`` reads the next page)."""

    job_id: int
    enqueued: list[int]
    n_waiting: int
    waiting: list[EnqueuedTheta]


class TrajectoryDocument(BaseModel):
    """``format=json`` of a trajectory: one row per control step."""

    metadata: dict[str, Any]
    columns: list[str]
    rows: list[list[Any]]


class JobBrief(BaseModel):
    """A job as a study or the comparison shows it."""

    id: int
    name: str
    status: JobStatusName
    seed: int
    study_id: int | None
    iterations: int
    n_done: int
    best: BestSummary | None


class Convergence(BaseModel):
    index: list[int]
    J: list[float]
    completed: list[bool]
    best_so_far: list[float | None] = Field(description="the lowest completed J so far (null before the first)")


class ComparedJob(JobBrief):
    convergence: Convergence
    best_phases: list[dict[str, Any]] = Field(description="the best evaluation's shown episode phase by phase: "
                                                          "each drift and flick (metrics.phases)")


class Band(BaseModel):
    """Median and quartiles of the jobs' best-so-far curves, at the iterations where any has a value."""

    iterations: list[int]
    median: list[float]
    q25: list[float]
    q75: list[float]
    n: list[int]


class StudyListItem(BaseModel):
    id: int
    name: str
    kind: Literal["seeds", "robustness"]
    status: str


class _StudyCommon(BaseModel):
    id: int
    name: str
    status: str
    error: str | None
    spec: dict[str, Any]
    created_at: Timestamp
    job_ids: list[int]


class SeedsStudy(_StudyCommon):
    kind: Literal["seeds"]
    jobs: list[JobBrief]
    band: Band
    final_best_J: list[float]


class Cell(BaseModel):
    index: int
    settings: dict[str, Any] = Field(description="dotted config key -> value")
    status: str
    J: float | None
    n_completed: int | None
    seeds: list[dict[str, Any]] | None
    wall_ms: float | None


class RobustnessStudy(_StudyCommon):
    kind: Literal["robustness"]
    theta: dict[str, float]
    grid: dict[str, list[Any]]
    n_cells: int
    n_done: int
    cells: list[Cell]


Study = Annotated[SeedsStudy | RobustnessStudy, Field(discriminator="kind")]


class SearchSpace(BaseModel):
    """A job's models over two of its parameters (driftlab.core.search_space): rows of the grids follow
    ``y_values``, columns ``x_values``; the other parameters are held at ``held`` (the best theta)."""

    job_id: int
    n_evaluations: int = Field(description="evaluations the models were fitted to")
    parameters: list[str]
    bounds: dict[str, list[float]]
    importance: dict[str, float] | None = Field(description="null before 2 completed evaluations")
    length_scales: dict[str, float] | None = Field(description="the GP's, in each parameter's own units")
    importance_method: str
    best_theta: dict[str, float] | None
    x: str
    y: str
    x_values: list[float]
    y_values: list[float]
    held: dict[str, float]
    mean_J: list[list[float]] | None = Field(description="GP posterior mean of J; null before 2 completions")
    std_J: list[list[float]] | None = Field(description="GP posterior standard deviation of J")
    p_failure: list[list[float]] | None = Field(description="learned probability that an evaluation fails; null "
                                                "unless some completed and some failed")


class Rescore(BaseModel):
    """A job's rescore: its best theta on ``samples`` fresh seeds (as ``driftlab rescore``)."""

    job_id: int
    id: int | None = Field(default=None, description="the rescore's id (none before the first)")
    status: Literal["none", "queued", "running", "finished", "failed", "cancelled"]
    samples: int | None = None
    done: int | None = Field(default=None, description="episodes finished so far")
    theta: dict[str, float] | None = None
    evaluation_id: int | None = None
    J_stored: float | None = None
    status_stored: str | None = None
    result: dict[str, Any] | None = Field(default=None, description="samples, completed, completion_rate, J_mean, "
                                          "J_std, J_worst, J_mean_completed, mean_abs_e_m, by_phase (drift, flick: "
                                          "mean_abs_e_m, max_abs_e_m, rms_beta_err_rad, episodes), statuses, seeds")
    error: str | None = None


class Calibration(BaseModel):
    """A calibration asked for through the API (as ``driftlab calibrate``), run by the server's job runner."""

    id: int
    status: Literal["queued", "running", "finished", "failed", "cancelled"]
    request: dict[str, Any] = Field(description="plant, sets (dotted config keys), points, iterations, seeds, seed, "
                                    "rounds, one_set, theta, prune, command")
    progress: dict[str, Any] | None = Field(default=None, description="the latest: group of groups, round of rounds, "
                                            "step (weights or theta), tried of of (every candidate model's, searched "
                                            "side by side), best_score, best_completed of best_episodes")
    messages: list[str] = Field(description="what `driftlab calibrate` prints, newest last")
    profile_ids: list[int] = Field(description="the profiles it stored so far (GET /api/profiles/{id})")
    error: str | None = None
    created_at: str
    updated_at: str


class ProfileSummary(BaseModel):
    """A stored car profile: the car, the points it was calibrated at with what its weights did there."""

    id: int
    plant_model: str
    vehicle_id: int
    created_at: str
    per_point: list[dict[str, Any]] | None = None
    round: int | None = None
    command: str | None = None
    shipped: str | None = Field(default=None, description="the shipped file and index it was copied from, if any")
