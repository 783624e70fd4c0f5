"""Studies at the edge: starting one from a request document, and what a study or a comparison of jobs shows
(shared by the REST API, the CLI, the report and the view).

A seeds study stores one ordinary job per seed (the job runner runs them); a robustness study stores its cells
(the job runner runs them after the queued jobs, driftlab.worker.study_runner).
"""

from __future__ import annotations

from datetime import UTC
from typing import Any

from sqlalchemy import select
from sqlalchemy.orm import Session

from driftlab.core.config import dotted_config
from driftlab.core.convergence import band, best_so_far
from driftlab.core.drivability import check_drivable
from driftlab.core.errors import ConfigError
from driftlab.core.statuses import EpisodeStatus, StudyKind
from driftlab.core.study import RobustnessStudySpec, SeedsStudySpec
from driftlab.core.tuning import TuningSpec
from driftlab.db import storage, studies
from driftlab.db.models import Evaluation, Job, Study

MAX_COMPARED_JOBS = 20


def _robustness_doc(session: Session, doc: dict[str, Any]) -> dict[str, Any]:
    """The document of a robustness study: theta given, or taken from a stored evaluation, whose job then
    gives the config (``config`` overrides it), the seed and robust_samples (unless given)."""
    evaluation_id = doc.get("evaluation_id")
    if evaluation_id is None:
        if doc.get("theta") is None:
            raise ConfigError("theta: give theta {c_lr, c_rl, dV, k} or evaluation_id")
        return doc
    if doc.get("theta") is not None:
        raise ConfigError("theta: give theta or evaluation_id, not both")
    evaluation = storage.get_evaluation(session, evaluation_id=evaluation_id)  # NotFound -> 404
    job_spec = TuningSpec.from_dict(evaluation.job.spec)
    flat = {**dotted_config(job_spec.to_dict()["config"]), **dotted_config(doc.get("config") or {})}
    return {**doc, "theta": dict(evaluation.theta), "config": flat,
            "seed": doc.get("seed", job_spec.seed),
            "robust_samples": doc.get("robust_samples", job_spec.robust_samples)}


def _refuse_fields(doc: dict[str, Any], kind: str, fields: tuple[str, ...]) -> None:
    for name in fields:
        if doc.get(name) is not None:
            raise ConfigError(f"{name}: not a field of a {kind} study")


def start_study(session: Session, *, doc: dict[str, Any], name: str | None = None) -> Study:
    """Validates ``doc`` ({"kind": "seeds", ...} or {"kind": "robustness", ...}) and stores the study with its
    jobs or cells, queued.

    Raises:
        ConfigError: a field is missing, unknown or out of range (the message starts with the field).
        NotFound: ``evaluation_id`` names no evaluation.
    """
    kind = doc.get("kind")
    if name is not None and studies.find_study(session, name=name) is not None:
        raise ConfigError(f"name: a study named {name!r} exists")
    if kind == StudyKind.SEEDS:
        _refuse_fields(doc, kind, ("theta", "evaluation_id", "grid", "config", "robust_samples", "seed"))
        seeds_spec = SeedsStudySpec.from_dict(doc)
        check_drivable(seeds_spec.job.config)  # NotDrivableError (a ConfigError), as for a job
        study = studies.create_study(session, name=name or studies.unique_study_name(session, "study"), kind=kind,
                                     spec=seeds_spec.to_dict(), status="jobs")
        for seed, spec in zip(seeds_spec.seeds, seeds_spec.job_specs(), strict=True):
            job_name = storage.unique_job_name(session, f"{study.name}-seed{seed}")
            storage.create_job(session, name=job_name, spec=spec.to_dict(), seed=seed, study_id=study.id)
        return study
    if kind == StudyKind.ROBUSTNESS:
        _refuse_fields(doc, kind, ("seeds", "spec"))
        spec = RobustnessStudySpec.from_dict(_robustness_doc(session, doc))
        study = studies.create_study(session, name=name or studies.unique_study_name(session, "study"), kind=kind,
                                     spec=spec.to_dict())
        studies.add_cells(session, study_id=study.id, cells=spec.cells())
        return study
    raise ConfigError(f"kind: must be 'seeds' or 'robustness', got {kind!r}")


def job_convergence(session: Session, *, job_id: int) -> dict[str, list]:
    """Per evaluation, in order: index, J, completed, and the best completed J so far."""
    rows = session.execute(select(Evaluation.index, Evaluation.J, Evaluation.status)
                           .where(Evaluation.job_id == job_id).order_by(Evaluation.index)).all()
    values = [r.J for r in rows]
    completed = [r.status == EpisodeStatus.COMPLETED for r in rows]
    return {"index": [r.index for r in rows], "J": values, "completed": completed,
            "best_so_far": best_so_far(values, completed)}


def job_summary(session: Session, job: Job) -> dict[str, Any]:
    """A job as the compare view shows it: its best (theta, J), n_done and convergence."""
    best = storage.best_evaluation(session, job_id=job.id)
    convergence = job_convergence(session, job_id=job.id)
    return {"id": job.id, "name": job.name, "status": job.status, "seed": job.seed, "study_id": job.study_id,
            "iterations": job.spec["iterations"], "n_done": len(convergence["index"]),
            "best": storage.best_summary(best),
            "convergence": convergence}


def compare_jobs(session: Session, *, job_ids: list[int]) -> list[dict[str, Any]]:
    """Each job's summary, in the order given (NotFound for an unknown id), with its best evaluation's phases in
    numbers (driftlab.core.metrics.phase_segments: the drifts and the flicks side by side)."""
    if not job_ids or len(job_ids) > MAX_COMPARED_JOBS:
        raise ConfigError(f"jobs: give 1 to {MAX_COMPARED_JOBS} job ids, got {len(job_ids)}")
    summaries = [job_summary(session, storage.get_job(session, job_id=i)) for i in job_ids]
    return [{**s, "best_phases": _best_phases(session, s["best"])} for s in summaries]


def _best_phases(session: Session, best: dict[str, Any] | None) -> list[dict[str, Any]]:
    if best is None:
        return []
    return list((storage.get_evaluation(session, evaluation_id=best["id"]).metrics or {}).get("phases", []))


def _seeds_part(session: Session, study: Study) -> dict[str, Any]:
    jobs = [job_summary(session, j) for j in studies.study_jobs(session, study_id=study.id)]
    curves = [j["convergence"]["best_so_far"] for j in jobs]
    final = [c[-1] for c in curves if c and c[-1] is not None]
    return {"job_ids": [j["id"] for j in jobs], "jobs": [{k: v for k, v in j.items() if k != "convergence"}
                                                         for j in jobs],
            "band": band(curves), "final_best_J": final}


def _cell_dict(cell) -> dict[str, Any]:
    return {"index": cell.index, "settings": cell.settings, "status": cell.status, "J": cell.J,
            "n_completed": cell.n_completed, "seeds": cell.seeds, "wall_ms": cell.wall_ms}


def study_summary(session: Session, study: Study) -> dict[str, Any]:
    """GET /api/studies/{id}: status and job_ids; a seeds study's band, a robustness study's cells."""
    out = {"id": study.id, "name": study.name, "kind": study.kind, "status": studies.study_status(session, study),
           "error": study.error, "spec": study.spec, "created_at": study.created_at.replace(tzinfo=UTC).isoformat()}
    if study.kind == StudyKind.SEEDS:
        return {**out, **_seeds_part(session, study)}
    cells = [_cell_dict(c) for c in studies.cells(session, study_id=study.id)]
    return {**out, "job_ids": [], "theta": study.spec["theta"], "grid": study.spec["grid"],
            "n_cells": len(cells), "n_done": sum(c["status"] != studies.PENDING for c in cells), "cells": cells}
