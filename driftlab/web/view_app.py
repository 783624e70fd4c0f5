"""The viser app behind ``/viser/`` (the 3D view; the dashboard is the page at ``/dashboard/``): one
:class:`ClientSession` per browser tab, a poller that reads new evaluations (and studies, and what a tab compares)
through driftlab.services.read_model, and the what-if runner that sends single episodes to a worker process.

The view draws what it is given: stored trajectories, or episodes a worker ran. It runs no physics.
"""

from __future__ import annotations

import threading
import time
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any

import viser

from driftlab.core.errors import ConfigError
from driftlab.services import read_model
from driftlab.settings import WHAT_IF_PER_MINUTE
from driftlab.web.frames import EpisodeFrames
from driftlab.web.session import ClientSession
from driftlab.web.sources import JobHistory, frames_of_evaluation, frames_of_outcome
from driftlab.web.viser_server import quiet_viser_server

# run_episode(theta, config_doc, seed) -> Future of an EpisodeOutcome (see driftlab.worker.executors).
EpisodeRunner = Callable[[dict[str, float], dict[str, Any], int], Future]
COMPARE_EVERY_POLLS = 4  # studies and comparisons every 2 s at the default 0.5 s poll


class EpisodeBudget:
    """A token bucket: ``per_minute`` episodes a minute on average, ``burst`` at once (a slider dragged for a few
    seconds), so that one open tab cannot keep the what-if worker busy for everyone."""

    def __init__(self, per_minute: float, burst: int, clock: Callable[[], float] = time.monotonic) -> None:
        self.rate_per_s = per_minute / 60.0
        self.burst = float(burst)
        self.clock = clock
        self._tokens = float(burst)
        self._at = clock()

    def wait_s(self) -> float:
        """0 and one episode spent, or how long until the next one may start."""
        now = self.clock()
        self._tokens = min(self.burst, self._tokens + (now - self._at) * self.rate_per_s)
        self._at = now
        if self._tokens >= 1.0:
            self._tokens -= 1.0
            return 0.0
        return (1.0 - self._tokens) / self.rate_per_s


class WhatIfRunner:
    """Runs one episode per tab at a time, at most ``per_minute`` a minute per tab (the websocket connection);
    while one runs or the tab waits for its budget, only the newest request of that tab is kept."""

    def __init__(self, run_episode: EpisodeRunner | None, per_minute: float = 60.0, burst: int = 5,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.run_episode = run_episode
        self.per_minute, self.burst, self.clock = per_minute, burst, clock
        self._lock = threading.Lock()
        self._busy: set[int] = set()
        self._waiting: dict[int, tuple[ClientSession, dict, dict, dict, int]] = {}
        self._budgets: dict[int, EpisodeBudget] = {}
        self.started = 0  # episodes sent to the worker: what the rate limit bounds

    def request(self, session: ClientSession, theta: dict[str, float], config_doc: dict[str, Any],
                plant_overrides: dict[str, float], seed: int) -> None:
        if self.run_episode is None:
            session.on_what_if_result(None, "what-if needs a worker (the server was started without one)", 0.0)
            return
        key = session.client.client_id
        with self._lock:
            if key in self._busy:
                self._waiting[key] = (session, theta, config_doc, plant_overrides, seed)
                return
            self._busy.add(key)
        self._start_or_wait(session, (session, theta, config_doc, plant_overrides, seed))

    def _start_or_wait(self, session: ClientSession, request: tuple) -> None:
        key = session.client.client_id
        with self._lock:
            budget = self._budgets.setdefault(key, EpisodeBudget(self.per_minute, self.burst, self.clock))
            wait_s = budget.wait_s()
            if wait_s > 0.0:
                self._waiting[key] = request
        if wait_s > 0.0:
            timer = threading.Timer(wait_s, self._next, args=(session,))
            timer.daemon = True
            timer.start()
            return
        self._submit(*request)

    def forget(self, client_id: int) -> None:
        """A closed tab: its budget and waiting request go with it."""
        with self._lock:
            self._budgets.pop(client_id, None)
            self._waiting.pop(client_id, None)

    def _submit(self, session: ClientSession, theta: dict, config_doc: dict, overrides: dict, seed: int) -> None:
        self.started += 1
        try:
            future = self.run_episode(theta, read_model.what_if_config(config_doc, overrides), seed)
        except (ConfigError, ValueError) as exc:
            session.on_what_if_result(None, str(exc), 0.0)
            self._next(session)
            return
        future.add_done_callback(lambda f: self._done(session, f, overrides))

    def _done(self, session: ClientSession, future: Future, overrides: dict) -> None:
        try:
            outcome = future.result()
            session.on_what_if_result(frames_of_outcome(outcome, overrides), None, outcome.wall_ms)
        except Exception as exc:  # a dead worker process is a message in the panel, not a dead view
            session.on_what_if_result(None, f"{type(exc).__name__}: {exc}", 0.0)
        finally:
            self._next(session)

    def _next(self, session: ClientSession) -> None:
        key = session.client.client_id
        with self._lock:
            waiting = self._waiting.pop(key, None)
            if waiting is None:
                self._busy.discard(key)
                return
        self._start_or_wait(session, waiting)


class ViewApp:
    def __init__(self, factory: read_model.Factory, *, run_episode: EpisodeRunner | None = None,
                 host: str = "127.0.0.1", port: int = 0, poll_s: float = 0.5,
                 what_if_per_minute: float = WHAT_IF_PER_MINUTE) -> None:
        self.factory = factory
        self.poll_s = poll_s
        self.what_if = WhatIfRunner(run_episode, per_minute=what_if_per_minute)
        self.sessions: dict[int, ClientSession] = {}
        self._histories: dict[int, JobHistory] = {}
        self._jobs: list[tuple[int, str, str]] = []
        self._studies: list[tuple[int, str, str, str]] = []
        self._polls = 0
        self._frames_cache: OrderedDict[int, EpisodeFrames] = OrderedDict()
        self._lock = threading.RLock()
        self._stop = threading.Event()
        self.server = quiet_viser_server(host=host, port=port, label="DriftLab")
        self.server.on_client_connect(self._on_connect)
        self.server.on_client_disconnect(self._on_disconnect)
        self._poller = threading.Thread(target=self._poll_loop, name="driftlab-view-poller", daemon=True)
        self._poller.start()

    @property
    def port(self) -> int:
        return self.server.get_port()

    def stop(self) -> None:
        self._stop.set()
        for session in list(self.sessions.values()):
            session.close()
        self.server.stop()

    # ----- data for sessions -------------------------------------------------------------------------------
    def history(self, job_id: int) -> JobHistory:
        with self._lock:
            if job_id not in self._histories:
                history = JobHistory(job_id)
                history.refresh(self.factory)
                self._histories[job_id] = history
            return self._histories[job_id]

    def frames(self, evaluation_id: int) -> EpisodeFrames:
        """A stored episode, from a small cache (tabs following one job load the same episodes)."""
        with self._lock:
            if evaluation_id in self._frames_cache:
                self._frames_cache.move_to_end(evaluation_id)
                return self._frames_cache[evaluation_id]
        frames = frames_of_evaluation(self.factory, evaluation_id)
        with self._lock:
            self._frames_cache[evaluation_id] = frames
            while len(self._frames_cache) > 32:
                self._frames_cache.popitem(last=False)
        return frames

    def studies(self) -> list[tuple[int, str, str, str]]:
        return read_model.study_list(self.factory)

    def study(self, study_id: int) -> dict[str, Any]:
        return read_model.study(self.factory, study_id)

    def compare(self, job_ids: list[int]) -> list[dict[str, Any]]:
        return read_model.compare(self.factory, job_ids)

    def config_diff(self, job_ids: list[int]) -> dict[str, Any]:
        return read_model.config_diff(self.factory, job_ids)

    def request_what_if(self, session: ClientSession, theta: dict[str, float], config_doc: dict[str, Any],
                        plant_overrides: dict[str, float], seed: int) -> None:
        self.what_if.request(session, theta, config_doc, plant_overrides, seed)

    def enqueue(self, job_id: int, theta: dict[str, float]) -> str:
        """The what-if panel's "add to job": the theta enqueued for the job, or why not."""
        return read_model.enqueue_theta(self.factory, job_id, theta)

    # ----- clients -----------------------------------------------------------------------------------------
    def _on_connect(self, client: viser.ClientHandle) -> None:
        session = ClientSession(client, self)
        with self._lock:
            self.sessions[client.client_id] = session
        session.set_job_options(self._read_jobs())
        session.set_study_options(self.studies())

    def _on_disconnect(self, client: viser.ClientHandle) -> None:
        with self._lock:
            session = self.sessions.pop(client.client_id, None)
        self.what_if.forget(client.client_id)
        if session is not None:
            session.close()

    # ----- polling storage -----------------------------------------------------------------------------------
    def _read_jobs(self) -> list[tuple[int, str, str]]:
        return read_model.job_list(self.factory)

    def _poll_loop(self) -> None:
        while not self._stop.wait(self.poll_s):
            try:
                self.poll_once()
            except Exception as exc:  # storage busy or a tab closing mid-update: try again next round
                print(f"driftlab view: poll failed: {type(exc).__name__}: {exc}", flush=True)

    def poll_once(self) -> None:
        if not self.sessions:  # nobody watching: no storage reads
            return
        jobs = self._read_jobs()
        with self._lock:
            jobs_changed = jobs != self._jobs
            self._jobs = jobs
            sessions = list(self.sessions.values())
            watched = {s.history.job_id for s in sessions if s.history is not None}
        histories = [self.history(job_id) for job_id in watched]
        changed = [h for h in histories if h.refresh(self.factory)]
        for session in sessions:
            if jobs_changed:
                session.set_job_options(jobs)
            for history in changed:
                session.on_history(history)
        self._polls += 1
        if self._polls % COMPARE_EVERY_POLLS == 0:
            self._poll_studies(sessions)

    def _poll_studies(self, sessions: list[ClientSession]) -> None:
        """The study list, and each shown comparison read again (every few polls: it reads whole jobs)."""
        studies = self.studies()
        with self._lock:
            studies_changed = studies != self._studies
            self._studies = studies
        for session in sessions:
            if studies_changed:
                session.set_study_options(studies)
            session.compare.refresh()
