"""The names a result is stored under: how an episode ended, where a job is, what kind a study is. Strings
(StrEnum) as the database, the API and the CLI show them; imported by every layer, so nothing here imports anything
of DriftLab."""

from __future__ import annotations

from enum import StrEnum


class EpisodeStatus(StrEnum):
    """How an episode (and an evaluation: its worst seed's) ended; the kernel's status codes index it in order."""

    COMPLETED = "completed"
    SPUN_OUT = "spun_out"
    LEFT_TRACK = "left_track"
    STALLED = "stalled"
    GRIPPED_UP = "gripped_up"
    SOLVER_FAILED = "solver_failed"
    DIVERGED = "diverged"
    # Never run: theta's model corrections leave the controller's model without a drift to hold (the kernel never
    # returns it; stored jobs of earlier releases have such evaluations as "diverged").
    REFUSED = "refused"
    # Ran, but outside the plant's model for longer than the failure limits allow (FailureLimits.max_invalid_s):
    # CommonRoad's MB with a wheel pulling the road, or, with wheel lift-off, two wheels of one side in the air.
    INVALID = "invalid"


class StudyKind(StrEnum):
    """A seeds study (one tuning job per seed) or a robustness study (a theta scored on a grid of configs)."""

    SEEDS = "seeds"
    ROBUSTNESS = "robustness"


class WorkStatus(StrEnum):
    """The status of every kind of leased work (a job, a robustness study, a rescore, a calibration): queued until a
    runner takes its lease, running while it holds it, then finished, paused (a job or a study asked to stop),
    failed, or cancelled (a rescore or a calibration asked to stop). The transitions are driftlab.db.lease's and
    driftlab.db.lifecycle's."""

    QUEUED = "queued"
    RUNNING = "running"
    PAUSED = "paused"
    FINISHED = "finished"
    FAILED = "failed"
    CANCELLED = "cancelled"
