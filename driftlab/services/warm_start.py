"""A new job's warm start from stored jobs (``warm_start_from``: the REST API, `driftlab tune --warm-start-from`):
their evaluations read here, the choice made by driftlab.core.warm_start, the result stored in the job's spec."""

from __future__ import annotations

from dataclasses import replace

from sqlalchemy.orm import Session

from driftlab.core.config import config_to_dict, without_keys
from driftlab.core.errors import ConfigError
from driftlab.core.tuning import TuningSpec
from driftlab.core.warm_start import SourceJob, warm_start
from driftlab.db import storage


def with_warm_start(session: Session, spec: TuningSpec, job_ids: list[int]) -> TuningSpec:
    """``spec`` started from the stored jobs ``job_ids`` (ConfigError naming ``warm_start_from`` for an unknown
    id). Call it after the job's config is final (a car profile's weights applied): a source counts as the same
    problem only if its stored config equals this one."""
    sources = []
    for job_id in dict.fromkeys(job_ids):
        try:
            job = storage.get_job(session, job_id=job_id)
        except storage.NotFound:
            raise ConfigError(f"warm_start_from: no job with id {job_id}", field="warm_start_from") from None
        evaluations = [(e.theta, e.J, e.completed) for e in storage.evaluations(session, job_id=job_id)]
        # A config still to be fitted (parsing does no physics) is the same problem as a fitted one of its settings.
        stored = without_keys(job.spec.get("config", {}), spec.config.to_fit)
        sources.append(SourceJob(job_id, stored, evaluations))
    start = warm_start(sources, config_to_dict(spec.config), spec.bounds)
    return replace(spec, warm_start=start if spec.warm_start is None else start.joined(spec.warm_start))
