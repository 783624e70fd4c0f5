"""`driftlab tune`, `rescore` and `report`: a tuning job in this process, fresh seeds for its best, the tables."""

from __future__ import annotations

import argparse
import json
import os
import sys
import time

from driftlab.cli.options import (
    dask_address,
    db_url,
    episode_config,
    finite,
    key_values,
    prune_rule,
    settings,
    stored_db_url,
)
from driftlab.cli.shutdown import raise_if_terminated, stop_on_sigterm
from driftlab.core.drivability import check_drivable
from driftlab.core.errors import ConfigError


def tuning_spec(args: argparse.Namespace):
    from driftlab.core.tuning import TuningSpec

    config = episode_config(args)
    check_drivable(config)
    bounds = {}
    for item in args.bound or []:
        name, _, pair = item.partition("=")
        lo, _, hi = pair.partition(":")
        bounds[name.strip()] = [lo, hi]
    from driftlab.core.tuning import DEFAULT_SEED_POINTS, PAPER_PRESET

    preset = PAPER_PRESET if args.preset == "paper" else {"iterations": 500, "seed_points": DEFAULT_SEED_POINTS,
                                                          "active_set": 400, "model_correction": True}
    iterations = preset["iterations"] if args.iterations is None else args.iterations
    seed_points = preset["seed_points"] if args.seed_points is None else args.seed_points
    active_set = preset["active_set"] if args.active_set is None else args.active_set
    correction = preset["model_correction"] if args.model_correction is None else args.model_correction == "on"
    return TuningSpec(iterations=iterations, seed_points=seed_points, active_set=active_set,
                      seed=args.seed, robust_samples=args.robust_samples, confirm_samples=args.confirm_samples,
                      bounds=bounds, config=config, model_correction=correction,
                      local_phase=None if args.local_phase is None else args.local_phase == "on",
                      deterministic=bool(args.deterministic), stop=stop_rules(args),
                      prune=prune_rule(getattr(args, "prune", None)))


def stop_rules(args: argparse.Namespace):
    """``--time-budget`` and ``--stop-after-no-improvement N[:BY]`` as the job's stop rules."""
    from driftlab.core.stopping import StopRules

    n, by = None, 0.0
    if args.stop_after_no_improvement:
        count, _, amount = args.stop_after_no_improvement.partition(":")
        try:
            n, by = int(count), float(amount or 0.0)
        except ValueError:
            raise ConfigError(f"--stop-after-no-improvement must be N or N:BY, e.g. 40:0.01; got "
                              f"{args.stop_after_no_improvement!r}", field="stop.no_improvement_evaluations") from None
    return StopRules(time_budget_s=args.time_budget, no_improvement_evaluations=n, no_improvement_by=by)


def job_ids(text: str) -> list[int]:
    """``--warm-start-from``'s job ids, e.g. "3,4"."""
    try:
        ids = [int(part) for part in text.split(",")]
    except ValueError:
        ids = []
    if not ids or min(ids) < 1:
        raise ConfigError(f"--warm-start-from must be job ids separated by commas, e.g. 3,4; got {text!r}",
                          field="warm_start_from")
    return ids


def enqueue_texts(session, job_id: int, texts: list[str]) -> None:
    """``--enqueue k=0.06,dV=0.1`` (repeated): hand-picked thetas the job evaluates next (driftlab.services.enqueue)."""
    from driftlab.services.enqueue import enqueue_thetas

    thetas = []
    for text in texts:
        pairs = key_values(text.split(","), "--enqueue")  # "expects key=value" first
        try:
            thetas.append({k: float(v) for k, v in pairs.items()})
        except ValueError:
            raise ConfigError(f"--enqueue {text!r}: each value must be a number", field="enqueue") from None
    enqueue_thetas(session, job_id=job_id, thetas=thetas, field="enqueue")


def open_tuning_job(factory, args: argparse.Namespace, runner: str) -> tuple[int, str, bool]:
    """Create the job, or take up the stored one of that name (its settings win; a given --iterations extends
    it); then claim its lease: (id, name, True). A job another live runner holds is refused (LeaseHeld: exit 2),
    unless only ``--enqueue`` is given: its thetas go to that runner's queue, evaluated next, and nothing runs
    here (id, name, False)."""
    from driftlab.db import lifecycle, storage
    from driftlab.db.lifecycle import WorkStatus

    with storage.transaction(factory) as session:
        job = storage.find_job(session, name=args.name) if args.name else None
        if job is None:
            from driftlab.services.profiles import gives_weights, uncalibrated_warning, with_profile

            spec = tuning_spec(args)
            name = args.name or storage.unique_job_name(session, "tune")
            profile_id = None
            if args.controller != "paper":
                sets = key_values(args.set or [], "--set")
                spec, profile_id = with_profile(session, spec, sets)
                warning = None if profile_id is not None or gives_weights(sets) else uncalibrated_warning(session,
                                                                                                           spec)
                if warning:
                    sys.stderr.write(f"warning: {warning}\n")
            if args.warm_start_from:
                from driftlab.services.warm_start import with_warm_start

                spec = with_warm_start(session, spec, job_ids(args.warm_start_from))
            job = storage.create_job(session, name=name, spec=spec.to_dict(), seed=spec.seed, profile_id=profile_id)
            message = f"job {job.name} (id {job.id}): {spec.iterations} iterations"
        else:
            if lifecycle.lease_is_live(job) and args.enqueue and args.iterations is None:
                # the runner that holds it (a server's) evaluates them next: this process runs nothing
                enqueue_texts(session, job.id, args.enqueue)
                sys.stderr.write(f"{len(args.enqueue)} theta(s) enqueued to job {job.name} (id {job.id}), which "
                                 f"{job.runner_id} runs: evaluated next\n")
                return job.id, job.name, False
            if lifecycle.lease_is_live(job):  # refuse before changing anything
                lifecycle.claim(session, job_id=job.id, runner=runner)
            if args.iterations is not None and args.iterations != job.spec["iterations"]:
                lifecycle.extend(session, job_id=job.id, iterations=args.iterations)
            done = storage.count_evaluations(session, job_id=job.id)
            message = f"resuming job {job.name} (id {job.id}) at {done} of {job.spec['iterations']}"
        job_id, name, status = job.id, job.name, job.status
        if args.enqueue:
            enqueue_texts(session, job.id, args.enqueue)
            message += f"; {len(args.enqueue)} theta(s) enqueued (evaluated next when it runs)"
    if status != WorkStatus.FINISHED:
        with storage.transaction(factory) as session:
            lifecycle.claim(session, job_id=job_id, runner=runner,
                            from_statuses=(WorkStatus.QUEUED, WorkStatus.PAUSED, WorkStatus.FAILED))
    sys.stderr.write(message + "\n")
    return job_id, name, True


def cmd_tune(args: argparse.Namespace) -> int:
    from driftlab.core.compiled import episode_kernels_cached
    from driftlab.db import lifecycle, storage
    from driftlab.worker.executors import open_executor
    from driftlab.worker.job_loop import Progress, run_job
    from driftlab.worker.slots import EpisodeSlots, capacity_of

    stop_on_sigterm()
    factory = storage.open_database(db_url(args.db))
    runner = lifecycle.new_runner_id("tune")
    job_id, name, ours = open_tuning_job(factory, args, runner)
    if not ours:
        return 0

    def progress(p: Progress) -> None:
        raise_if_terminated()
        best = f"{p.best_J:.3f}" if p.best_J is not None else "-"
        eta = f"{p.eta_s:.0f} s" if p.eta_s is not None else "-"
        line = f"[{p.n_done}/{p.iterations}] best J {best}  last {p.last.status} J {p.last.J:.3f}  ETA {eta}"
        if sys.stderr.isatty():
            sys.stderr.write(f"\r{line}    ")
        elif p.n_done % 25 == 0 or p.n_done == p.iterations:  # logs: a line now and then, not a blob
            sys.stderr.write(line + "\n")
        sys.stderr.flush()

    started = time.perf_counter()
    with storage.transaction(factory) as session:
        status = storage.get_job(session, job_id=job_id).status
    if status == lifecycle.WorkStatus.RUNNING and episode_kernels_cached() is False:
        sys.stderr.write("compiling the simulation (numba, once after an install); the first evaluation follows\n")
    if status == lifecycle.WorkStatus.RUNNING:  # ours now
        executor, workers = open_executor(args.workers, dask_address(args))
        try:
            slots = EpisodeSlots(capacity_of(executor, args.workers, workers))  # a Dask cluster's as it grows
            status = run_job(factory, job_id, executor, runner=runner, slots=slots, on_progress=progress,
                             max_trajectories=settings().max_trajectories_per_job)
        except KeyboardInterrupt:
            with storage.transaction(factory) as session:
                lifecycle.release(session, job_id=job_id, runner=runner, status=lifecycle.WorkStatus.PAUSED)
            sys.stderr.write(f"\njob {name} paused; run the same command to continue\n")
            return 130
        finally:
            executor.shutdown()
    with storage.transaction(factory) as session:
        job = storage.get_job(session, job_id=job_id)
        if status == lifecycle.WorkStatus.PAUSED and job.error:
            sys.stderr.write(f"\ndriftlab: job {name} paused: {job.error}; run the same command to continue\n")
        best = storage.best_evaluation(session, job_id=job_id)
        if job.stop_reason:
            sys.stderr.write(f"\njob {name} finished early: {job.stop_reason}\n")
        warm = job.spec.get("warm_start")
        out = {"job": name, "id": job_id, "status": str(status), "wall_s": round(time.perf_counter() - started, 2),
               "n_done": storage.count_evaluations(session, job_id=job_id), "stop_reason": job.stop_reason,
               "warm_start_from": None if warm is None else warm["from_jobs"], "best": storage.best_summary(best)}
    storage.close_database(factory)
    sys.stderr.write("\n")
    print(json.dumps(out))
    return 0 if status != lifecycle.WorkStatus.FAILED else 1


def cmd_rescore(args: argparse.Namespace) -> int:
    from driftlab.worker.scoring import rescore_job

    print(json.dumps(finite(rescore_job(db_url=stored_db_url(args.db), name=args.name, samples=args.samples,
                                         workers=args.workers, dask_address=dask_address(args)))))
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from driftlab.reports.job import write_report

    if os.path.exists(args.out) and not os.path.isdir(args.out):
        raise ConfigError(f"--out {args.out}: is a file; give a folder (created if missing)")
    if args.study:
        from driftlab.reports.study import write_study_report

        print(json.dumps({"report": str(write_study_report(db_url=stored_db_url(args.db), name=args.study,
                                                           out_dir=args.out))}))
        return 0
    path = write_report(db_url=stored_db_url(args.db), name=args.name, out_dir=args.out,
                        baseline_samples=args.baselines, rescore_samples=args.rescore_samples,
                        dask_address=dask_address(args))
    print(json.dumps({"report": str(path)}))
    return 0
