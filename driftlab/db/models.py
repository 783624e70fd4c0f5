"""SQLAlchemy 2.x tables: jobs, their evaluations, each evaluation's compressed trajectory, and studies (a
seeds study's jobs point at it; a robustness study's cells are rows of their own). The schema
changes only through a revision in driftlab/db/migrations (see driftlab.db.schema)."""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from sqlalchemy import JSON, Float, ForeignKey, Integer, LargeBinary, String, Text, UniqueConstraint
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column, relationship

from driftlab.core.statuses import EpisodeStatus, WorkStatus


def utcnow() -> datetime:
    return datetime.now(UTC)


class Base(DeclarativeBase):
    pass


class LeasedWork:
    """The columns every kind of leased work shares (jobs, robustness studies, rescores, calibrations): its status
    (driftlab.core.statuses.WorkStatus), the error it failed with, and the lease, the runner that holds it and its
    last heartbeat (driftlab.db.lease keeps the contract)."""

    status: Mapped[str] = mapped_column(String(20), default=WorkStatus.QUEUED)
    error: Mapped[str | None] = mapped_column(String(2000), default=None)
    runner_id: Mapped[str | None] = mapped_column(String(100), default=None)
    heartbeat_at: Mapped[datetime | None] = mapped_column(default=None)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(default=utcnow, onupdate=utcnow)


class Job(LeasedWork, Base):
    __tablename__ = "jobs"
    __table_args__ = {"sqlite_autoincrement": True}  # a deleted job's id is never handed out again

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)  # TuningSpec.to_dict()
    seed: Mapped[int] = mapped_column(Integer)
    started_at: Mapped[datetime | None] = mapped_column(default=None)  # when its current (or last) runner claimed it
    run_s: Mapped[float] = mapped_column(Float, default=0.0)  # its runs' wall time before the current one, in all
    stop_reason: Mapped[str | None] = mapped_column(String(500), default=None)  # a stop rule that finished it
    study_id: Mapped[int | None] = mapped_column(Integer, default=None, index=True)  # a seeds study's job
    notes: Mapped[str] = mapped_column(Text, default="", server_default="")  # a researcher's, free text
    profile_id: Mapped[int | None] = mapped_column(Integer, default=None)  # the car profile its weights came from

    evaluations: Mapped[list[Evaluation]] = relationship(back_populates="job", order_by="Evaluation.index")


class Evaluation(Base):
    __tablename__ = "evaluations"
    __table_args__ = (UniqueConstraint("job_id", "index"), {"sqlite_autoincrement": True})

    id: Mapped[int] = mapped_column(primary_key=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id"), index=True)
    index: Mapped[int] = mapped_column(Integer)  # 0-based, in order of completion
    theta: Mapped[dict[str, float]] = mapped_column(JSON)
    # Mean over its episodes of the paper's J (a failed episode at its failure penalty), driftlab.core.robust.
    J: Mapped[float] = mapped_column(Float)
    status: Mapped[str] = mapped_column(String(20))
    metrics: Mapped[dict[str, Any]] = mapped_column(JSON)
    trigger_points: Mapped[list[dict[str, float]]] = mapped_column(JSON)
    wall_ms: Mapped[float] = mapped_column(Float)  # CPU time of all its episodes
    # One entry per episode: {seed, status, J, completed_fraction}; J above is their aggregate.
    seeds: Mapped[list[dict[str, Any]] | None] = mapped_column(JSON, default=None)
    trajectory_seed: Mapped[int | None] = mapped_column(Integer, default=None)  # the stored episode's seed
    created_at: Mapped[datetime] = mapped_column(default=utcnow)
    enqueued: Mapped[bool] = mapped_column(default=False)  # a theta someone picked (EnqueuedTheta), not the optimizer

    job: Mapped[Job] = relationship(back_populates="evaluations")
    trajectory: Mapped[Trajectory] = relationship(back_populates="evaluation", cascade="all, delete-orphan")

    @property
    def completed(self) -> bool:
        return self.status == EpisodeStatus.COMPLETED

    @property
    def shown_seed(self) -> int:
        """The seed of the episode kept as its trajectory (an evaluation stored before ``trajectory_seed`` existed
        kept its first seed's)."""
        if self.trajectory_seed is not None:
            return self.trajectory_seed
        return int(self.seeds[0]["seed"]) if self.seeds else 0

    @property
    def shown_episode(self) -> dict[str, Any]:
        """That episode's entry of ``seeds`` ({seed, status, J, ...}); the evaluation's own for one seed."""
        seed = self.shown_seed
        return next((s for s in self.seeds or () if s["seed"] == seed), {"seed": seed, "J": self.J,
                                                                          "status": self.status})


class EnqueuedTheta(Base):
    """A theta someone picked for a job (a what-if, a colleague's): evaluated before the optimizer's next proposal,
    and removed in the transaction that stores its evaluation (a runner that dies first leaves it for the next)."""

    __tablename__ = "enqueued_thetas"
    __table_args__ = {"sqlite_autoincrement": True}

    id: Mapped[int] = mapped_column(primary_key=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id"), index=True)
    theta: Mapped[dict[str, float]] = mapped_column(JSON)
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Trajectory(Base):
    __tablename__ = "trajectories"

    evaluation_id: Mapped[int] = mapped_column(ForeignKey("evaluations.id"), primary_key=True)
    columns: Mapped[list[str]] = mapped_column(JSON)
    rows: Mapped[int] = mapped_column(Integer)
    data: Mapped[bytes] = mapped_column(LargeBinary)  # compressed float64 (driftlab.db.trajectory_bytes)

    evaluation: Mapped[Evaluation] = relationship(back_populates="trajectory")


class Meta(Base):
    __tablename__ = "meta"

    key: Mapped[str] = mapped_column(String(50), primary_key=True)
    value: Mapped[str] = mapped_column(String(200))


class Study(LeasedWork, Base):
    """A seeds study (its jobs carry its id) or a robustness study (its cells below). A robustness study is run
    like a job: queued, claimed with a lease, paused, resumed (driftlab.db.studies). A seeds study's own status is
    not used: its status is its jobs' (driftlab.db.studies.study_status)."""

    __tablename__ = "studies"
    __table_args__ = {"sqlite_autoincrement": True}

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(String(200), unique=True)
    kind: Mapped[str] = mapped_column(String(20))  # "seeds" | "robustness"
    spec: Mapped[dict[str, Any]] = mapped_column(JSON)  # SeedsStudySpec / RobustnessStudySpec .to_dict()

    cells: Mapped[list[StudyCell]] = relationship(back_populates="study", order_by="StudyCell.index")


class StudyCell(Base):
    """One cell of a robustness study's grid: its settings and, once its episodes are back, its result."""

    __tablename__ = "study_cells"
    __table_args__ = (UniqueConstraint("study_id", "index"), {"sqlite_autoincrement": True})

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id"), index=True)
    index: Mapped[int] = mapped_column(Integer)  # position in the grid's cartesian product
    settings: Mapped[dict[str, Any]] = mapped_column(JSON)  # {dotted config key: value}
    status: Mapped[str] = mapped_column(String(20), default="pending")  # pending, or the aggregate's status
    J: Mapped[float | None] = mapped_column(Float, default=None)  # mean over seeds, failed at their penalty
    n_completed: Mapped[int | None] = mapped_column(Integer, default=None)
    seeds: Mapped[list[dict[str, Any]] | None] = mapped_column(JSON, default=None)  # {seed, status, J, ...}
    wall_ms: Mapped[float | None] = mapped_column(Float, default=None)
    completed_at: Mapped[datetime | None] = mapped_column(default=None)

    study: Mapped[Study] = relationship(back_populates="cells")


class Rescore(LeasedWork, Base):
    """A job's stored theta under fresh seeds (POST /api/jobs/{id}/rescore): queued, run by a runner under a lease
    like a job, each seed's result stored as it comes back, so that a restart resumes it where it stopped."""

    __tablename__ = "rescores"
    __table_args__ = {"sqlite_autoincrement": True}

    id: Mapped[int] = mapped_column(primary_key=True)
    job_id: Mapped[int] = mapped_column(ForeignKey("jobs.id"), index=True)
    evaluation_id: Mapped[int] = mapped_column(Integer)  # the evaluation whose theta is rescored
    theta: Mapped[dict[str, float]] = mapped_column(JSON)
    config: Mapped[dict[str, Any]] = mapped_column(JSON)  # the job's config document, as the episodes run it
    seeds: Mapped[list[int]] = mapped_column(JSON)  # driftlab.core.robust.rescore_seeds(samples)
    samples: Mapped[list[dict[str, Any]]] = mapped_column(JSON, default=list)  # one per seed back, in any order
    result: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)


class CarProfile(Base):
    """A car's calibration (``driftlab calibrate``): the MPC weights found for one plant and parameter set, with
    the points and figures they were found on and the command that found them. A new calibration adds a version;
    jobs of that car take the newest unless their config gives ``mpc.*`` keys, and record which they took."""

    __tablename__ = "car_profiles"
    __table_args__ = {"sqlite_autoincrement": True}

    id: Mapped[int] = mapped_column(primary_key=True)
    plant_model: Mapped[str] = mapped_column(String(100), index=True)
    vehicle_id: Mapped[int] = mapped_column(Integer)  # plant.commonroad_vehicle (a CommonRoad parameter set)
    document: Mapped[dict[str, Any]] = mapped_column(JSON)  # driftlab.core.calibration's profile document
    created_at: Mapped[datetime] = mapped_column(default=utcnow)


class Calibration(LeasedWork, Base):
    """A calibration asked for through the API (``POST /api/calibrations``; driftlab.core.calibration_run): queued,
    run by a runner under a lease like a job, its progress and the profiles it stored so far kept as it runs. A
    calibration whose runner died starts over when another takes it (the profiles stored stay)."""

    __tablename__ = "calibrations"
    __table_args__ = {"sqlite_autoincrement": True}

    id: Mapped[int] = mapped_column(primary_key=True)
    request: Mapped[dict[str, Any]] = mapped_column(JSON)  # CalibrationRequest.as_dict()
    progress: Mapped[dict[str, Any] | None] = mapped_column(JSON, default=None)  # the latest progress event
    messages: Mapped[list[str]] = mapped_column(JSON, default=list)  # what the CLI would print, newest last
    profile_ids: Mapped[list[int]] = mapped_column(JSON, default=list)
