"""`driftlab study seeds|robustness|show`: a study headless, stored in the same database the server uses.

Running it again with the same ``--name`` continues the study where it stopped (the stored study's settings
win). A seeds study's jobs run one after another, each as `driftlab tune` runs a job (with its lease); a
robustness study's cells run on the executor, each stored as it completes.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from driftlab.cli.options import key_values, name_text, settings
from driftlab.cli.shutdown import raise_if_terminated, stop_if_terminated, stop_on_sigterm
from driftlab.core.errors import ConfigError
from driftlab.core.statuses import StudyKind


def _grid(items: list[str]) -> dict[str, list[float]]:
    """--grid KEY=V1,V2,... (repeatable) -> {KEY: [V1, V2, ...]}."""
    grid: dict[str, list[float]] = {}
    for key, values in key_values(items, "--grid").items():
        try:
            grid[key] = [float(v) for v in values.split(",") if v.strip()]
        except ValueError:
            raise ConfigError(f"grid.{key}: values must be numbers, got {values!r}") from None
    return grid


def _seeds(text: str) -> list[int]:
    try:
        return [int(s) for s in text.split(",") if s.strip()]
    except ValueError:
        raise ConfigError(f"seeds must be comma-separated integers, got {text!r}") from None


def study_doc(args: argparse.Namespace, tuning_spec) -> dict[str, Any]:
    """The request document (as POST /api/studies takes) from the command line."""
    if args.kind == StudyKind.SEEDS:
        return {"kind": "seeds", "seeds": _seeds(args.seeds), "spec": tuning_spec(args).to_dict()}
    doc: dict[str, Any] = {"kind": "robustness", "grid": _grid(args.grid or [])}
    if args.theta:
        doc["theta"] = key_values(args.theta.split(","), "--theta")
    if args.evaluation is not None:
        doc["evaluation_id"] = args.evaluation
    if args.set:
        doc["config"] = key_values(args.set, "--set")
    for name in ("robust_samples", "seed"):
        if getattr(args, name) is not None:
            doc[name] = getattr(args, name)
    return doc


def _open_study(factory, args: argparse.Namespace, tuning_spec, runner: str) -> int:
    """Create the study (or take it up by name); a seeds study is held by ``runner`` in the same transaction, so a
    server on the same database cannot start one of its jobs (raises LeaseHeld if another runner holds it)."""
    from driftlab.db import storage, studies
    from driftlab.services import studies as study_views

    with storage.transaction(factory) as session:
        study = studies.find_study(session, name=args.name) if args.name else None
        if study is None:
            study = study_views.start_study(session, doc=study_doc(args, tuning_spec), name=args.name)
            sys.stderr.write(f"study {study.name} (id {study.id}): {study.kind}\n")
        elif study.kind != args.kind:
            raise ConfigError(f"--name {args.name}: a {study.kind} study of that name exists; choose another name")
        else:
            sys.stderr.write(f"resuming study {study.name} (id {study.id}) with its stored settings (arguments "
                             f"given now that differ are not applied; a new --name starts a new study)\n")
        if study.kind == StudyKind.SEEDS:
            studies.hold_seeds_study(session, study_id=study.id, runner=runner)
        return study.id


def _run_seeds_jobs(factory, study_id: int, executor, workers, runner: str) -> None:
    """Runs the study's unfinished jobs at once on the server runner's scheduler (driftlab.worker.job_pool): one
    thread and one optimizer per job, the workers shared fairly, at most as many jobs at once as workers, the next
    one starting when one finishes. Ctrl-C or SIGTERM (also one lost in a finalizer, driftlab.cli.shutdown): what is
    asked completes, then the jobs are paused."""
    import threading

    from driftlab.db import lifecycle, storage, studies
    from driftlab.db.lifecycle import WorkStatus
    from driftlab.worker.job_loop import claim_job
    from driftlab.worker.job_pool import JobPool
    from driftlab.worker.slots import EpisodeSlots

    with storage.transaction(factory) as session:
        todo = [(j.id, j.name) for j in studies.study_jobs(session, study_id=study_id)
                if j.status != WorkStatus.FINISHED]
    names, started = dict(todo), {}
    stop, done = threading.Event(), threading.Semaphore(0)

    def finished(job_id: int, status: str | None) -> None:
        if status is not None:
            sys.stderr.write(f"job {names[job_id]}: {status} in {time.perf_counter() - started[job_id]:.1f} s\n")
        done.release()  # its share goes to the next one

    pool = JobPool(factory, executor, EpisodeSlots(workers), runner=runner, should_stop=stop.is_set,
                   max_trajectories=settings().max_trajectories_per_job, on_done=finished, daemon=False)

    def start(batch: list[tuple[int, str]]) -> None:
        for job_id, _ in batch:
            claim_job(factory, job_id, runner, from_statuses=(WorkStatus.QUEUED, WorkStatus.PAUSED, WorkStatus.FAILED))
            started[job_id] = time.perf_counter()
        pool.start([job_id for job_id, _ in batch])

    try:
        start(todo[:pool.free])
        for job in todo[len(started):]:
            while not done.acquire(timeout=0.2):
                raise_if_terminated()
            start([job])
        while pool.running:
            raise_if_terminated()
            pool.join(timeout_s=0.2)
    except KeyboardInterrupt:
        stop.set()
        pool.join()
        with storage.transaction(factory) as session:
            for job_id, status in pool.statuses.items():
                if status == WorkStatus.QUEUED:  # stopped by us, not finished: paused, as `tune` leaves a job
                    lifecycle.request_pause(session, job_id=job_id)
        raise


def _run_cells(factory, study_id: int, executor, workers, runner: str) -> None:
    from driftlab.db import lifecycle, storage, studies
    from driftlab.db.lifecycle import WorkStatus
    from driftlab.worker.slots import EpisodeSlots
    from driftlab.worker.study_runner import run_study

    with storage.transaction(factory) as session:
        study = studies.get_study(session, study_id=study_id)
        if study.status == WorkStatus.FINISHED:
            return
        if study.status in (WorkStatus.PAUSED, WorkStatus.FAILED):
            studies.resume_study(session, study_id=study_id)
    with storage.transaction(factory) as session:
        if not studies.claim_study(session, study_id=study_id, runner=runner):
            raise lifecycle.LeaseHeld(f"study {study_id} is being run by another runner; pause it first")
    try:
        run_study(factory, study_id, executor, runner=runner, slots=EpisodeSlots(workers),
                  should_stop=stop_if_terminated)
    except KeyboardInterrupt:
        with storage.transaction(factory) as session:
            studies.release_study(session, study_id=study_id, runner=runner, status=WorkStatus.PAUSED)
        raise


def brief_summary(summary: dict[str, Any], every: int = 10) -> dict[str, Any]:
    """What the command prints: a seeds study's band every ``every`` iterations and its final spread, or a
    robustness study's cells without their per-seed lists."""
    out = {k: summary[k] for k in ("id", "name", "kind", "status", "job_ids")}
    if summary["kind"] == StudyKind.SEEDS:
        band = summary["band"]
        keep = [i for i, it in enumerate(band["iterations"])
                if (it + 1) % every == 0 or i == len(band["iterations"]) - 1]
        out["band"] = {k: [band[k][i] for i in keep] for k in ("iterations", "median", "q25", "q75")}
        final = summary["final_best_J"]
        out["final_best_J"] = final
        if final:
            out["final_spread"] = {"min": min(final), "max": max(final), "range": max(final) - min(final)}
        return out
    out["cells"] = [{k: c[k] for k in ("settings", "status", "J", "n_completed")} for c in summary["cells"]]
    return out


def cmd_study(args: argparse.Namespace, tuning_spec, db_url: str, dask_address: str | None) -> int:
    """Create (or take up by name) and run a study; print its summary as JSON. ``show`` only prints."""
    from driftlab.db import lifecycle, storage, studies
    from driftlab.services import studies as study_views
    from driftlab.worker.executors import open_executor
    from driftlab.worker.slots import capacity_of

    factory = storage.open_database(db_url)
    if args.kind == "show":
        with storage.transaction(factory) as session:
            summary = study_views.study_summary(session, studies.get_study_by_name(session, name=args.name))
        print(json.dumps(brief_summary(summary, args.every)))
        return 0
    stop_on_sigterm()
    runner = lifecycle.new_runner_id("study")
    study_id = _open_study(factory, args, tuning_spec, runner)
    with storage.transaction(factory) as session:
        kind = studies.get_study(session, study_id=study_id).kind
    executor, workers = open_executor(args.workers, dask_address)
    workers = capacity_of(executor, args.workers, workers)  # a Dask cluster's worker threads as it grows
    started = time.perf_counter()
    try:
        if kind == StudyKind.SEEDS:
            _run_seeds_jobs(factory, study_id, executor, workers, runner)
        else:
            _run_cells(factory, study_id, executor, workers, runner)
    except KeyboardInterrupt:
        sys.stderr.write("\nstudy paused; run the same command to continue\n")
        return 130
    finally:
        executor.shutdown()
        if kind == StudyKind.SEEDS:
            with storage.transaction(factory) as session:
                studies.let_go_seeds_study(session, study_id=study_id, runner=runner)
    with storage.transaction(factory) as session:
        summary = study_views.study_summary(session, studies.get_study(session, study_id=study_id))
    print(json.dumps({**brief_summary(summary, args.every), "wall_s": round(time.perf_counter() - started, 2)}))
    return 0 if summary["status"] != lifecycle.WorkStatus.FAILED else 1


def add_study_parser(sub, db_help: str, dask_help: str, int_in, tune_options) -> argparse.ArgumentParser:
    """`driftlab study seeds|robustness|show` (``tune_options(parser)`` adds the job options of `tune`)."""
    st = sub.add_parser("study", help="run a study headless: a job over seeds, or a theta over a plant grid")
    kinds = st.add_subparsers(dest="kind", required=True, parser_class=type(st))
    seeds = kinds.add_parser("seeds", help="one tuning job per seed; prints the band of best-so-far J")
    seeds.add_argument("--seeds", required=True, help="comma-separated distinct seeds, e.g. 0,1,2")
    tune_options(seeds)
    rob = kinds.add_parser("robustness", help="a theta scored on every cell of a grid of config values")
    rob.add_argument("--theta", help="c_lr=..,c_rl=..,dV=..,k=.. (the others keep their defaults)")
    rob.add_argument("--evaluation", type=int_in(1, 2**63 - 1), metavar="ID",
                     help="score this stored evaluation's theta with its job's config, seed and robust samples")
    rob.add_argument("--grid", action="append", metavar="KEY=V1,V2,...", required=True,
                     help="a grid axis, e.g. plant.friction_scale=0.9,1.0,1.1 (repeat for more; <= 400 cells)")
    rob.add_argument("--robust-samples", type=int, metavar="N", help="seeded episodes per cell (1..64, default 1, "
                     "or the evaluation's job's)")
    rob.add_argument("--seed", type=int, help="picks the episode seeds (seed * 64 + j), as a job's seed does")
    rob.add_argument("--set", action="append", metavar="KEY=VALUE", help="base config override")
    show = kinds.add_parser("show", help="print a stored study's summary")
    for parser in (seeds, rob, show):
        parser.add_argument("--name", type=name_text, required=parser is show,
                            help="study name; an existing name continues it")
        parser.add_argument("--db", help=db_help)
        parser.add_argument("--every", type=int_in(1, 5000), default=10, metavar="N",
                            help="print the band every N iterations (default 10)")
    for parser in (seeds, rob):
        parser.add_argument("--dask", metavar="ADDRESS", help=dask_help)
        parser.add_argument("--workers", type=int_in(1, 1024), metavar="N",
                            help="episodes in flight at once (default: 1 locally, the cluster's threads with --dask)")
    return st
