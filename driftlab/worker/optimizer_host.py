"""Jobs' optimizers in processes beside the server's (DRIFTLAB_OPTIMIZER_PROCESS=1), one a job: ask and tell run
there, the job loop only sends thetas and values.

An ask is the Bayesian optimizer's whole work (the GP's hyperparameters fitted, the acquisition maximized from many
starts): 20 ms to 0.7 s of Python. On a thread of the server it held the one interpreter that also answers every
request; in a 30-client load with one job running it was 19% of what held the server's interpreter. Here it runs on
another core, and the running jobs' asks run at once (in one shared process they took turns: an 8-job study asked
slower there than on the jobs' threads). The calls are the same as on a local optimizer, in the same order, with
the same arguments, so a job asks what it asked in the server's thread (the processes inherit the server's
environment, and with it the BLAS thread count).

If a job's process dies, the next call starts a new one and restores the optimizer from what was told so far, as a
job resumed after a crash is (:func:`restore_optimizer`, which the job loop uses on its own thread too).
"""

from __future__ import annotations

import os
import threading
import uuid
from dataclasses import dataclass
from multiprocessing.connection import Connection
from multiprocessing.process import BaseProcess
from typing import TYPE_CHECKING, Any

from driftlab.worker.child_process import follow_owner, worker_context

if TYPE_CHECKING:  # an optimizer process imports this module: not the config's parsing and physics
    from driftlab.core.optimizer import BayesianOptimizer
    from driftlab.core.tuning import TuningSpec

History = list[tuple[dict[str, float], float | None, float]]


@dataclass(frozen=True)
class OptimizerStart:
    """What a job's optimizer is built from: its bounds and options, and what its warm start tells it first
    (theta, value, stored J). Plain values: an optimizer process builds it without parsing the job's config."""

    bounds: dict[str, tuple[float, float]]
    options: dict[str, Any]
    told: History

    @classmethod
    def of(cls, spec: TuningSpec) -> OptimizerStart:
        told = [(o.theta, o.value, o.stored_j) for o in spec.warm_start.told] if spec.warm_start is not None else []
        return cls(dict(spec.bounds), dict(spec.optimizer_options), told)

    def restored(self, history: History) -> BayesianOptimizer:
        # here, not at import: the server imports this module, and scikit-learn with SciPy's statistics cost ~1.5 s
        # of CPU at its start (with DRIFTLAB_OPTIMIZER_PROCESS its own process never asks at all)
        from driftlab.core.optimizer import BayesianOptimizer

        optimizer = BayesianOptimizer(self.bounds, **self.options)
        for theta, value, stored_j in [*self.told, *history]:
            optimizer.tell(theta, value, stored_j)
        return optimizer


def restore_optimizer(spec: TuningSpec, history: History) -> BayesianOptimizer:
    """An optimizer in the state it had after telling ``history`` (theta, J or None if failed, the stored J), told
    first what the job's warm start takes from jobs of its own config (driftlab.core.warm_start)."""
    return OptimizerStart.of(spec).restored(history)


# In an optimizer process: the optimizer of the job it serves (a process serves one job at a time).
_OPTIMIZERS: dict[str, Any] = {}


def _open(key: str, start: OptimizerStart, history: History) -> None:
    _OPTIMIZERS[key] = start.restored(history)


def _ask(key: str) -> dict[str, float]:
    return _OPTIMIZERS[key].ask()


def _tell(key: str, theta: dict[str, float], value: float | None, stored_j: float) -> None:
    _OPTIMIZERS[key].tell(theta, value, stored_j)


def _close(key: str) -> None:
    _OPTIMIZERS.pop(key, None)


def _warm() -> int:
    """What a job's first open and ask would load otherwise, while the server starts: the optimizer (scipy's
    optimize and stats) and the episode module its known constraint calls (a theta whose corrected model has no drift
    is not asked) with that check's compiled functions (~1 s), and the local searches' compiled acquisition."""
    import driftlab.core.optimizer  # noqa: F401
    from driftlab.core.acquisition_gradient import warm_up
    from driftlab.core.config import EpisodeConfig
    from driftlab.core.episode import runs

    runs(EpisodeConfig(), {})
    warm_up()
    return os.getpid()


def _serve(connection: Connection, niceness: int, owner_pid: int) -> None:
    """An optimizer process: answers (function, arguments) on its pipe until it is closed."""
    if niceness:
        os.nice(niceness)
    follow_owner(owner_pid)
    while True:
        try:
            fn, args = connection.recv()
        except (EOFError, OSError):
            return
        try:
            answer: tuple[bool, Any] = (True, fn(*args))
        except Exception as exc:  # noqa: BLE001  # the caller raises it
            answer = (False, exc)
        connection.send(answer)


class ProcessGone(RuntimeError):
    """The optimizer process died (or was ended) before it answered."""


class _Process:
    """One optimizer process (driftlab.worker.child_process.worker_context), called through a
    pipe on the caller's own thread: no executor threads between a job and its optimizer. A dead one is started
    again on the next call (:meth:`restart`)."""

    def __init__(self, niceness: int) -> None:
        self.niceness = niceness
        self._lock = threading.Lock()
        self._process: BaseProcess | None = None
        self._connection: Connection | None = None
        self._unanswered = 0  # calls sent without waiting (the warm-up), answered before the next call's

    def _started(self) -> Connection:
        if self._connection is None:
            context = worker_context()
            here, there = context.Pipe()
            self._process = context.Process(target=_serve, args=(there, self.niceness, os.getpid()), daemon=True)
            self._process.start()
            there.close()
            self._connection, self._unanswered = here, 0
        return self._connection

    def send(self, fn, *args) -> None:
        """Start ``fn(*args)`` without waiting for it (its answer is read by the next :meth:`call`, which raises
        what it raised)."""
        with self._lock:
            try:
                self._started().send((fn, args))
            except OSError as exc:
                raise ProcessGone(f"the optimizer process ended: {exc!r}") from exc
            self._unanswered += 1

    def call(self, fn, *args) -> Any:
        failed: Exception | None = None
        with self._lock:
            connection = self._started()
            try:
                while self._unanswered:
                    ok, value = connection.recv()
                    self._unanswered -= 1
                    failed = failed or (None if ok else value)
                connection.send((fn, args))
                ok, value = connection.recv()
            except (EOFError, OSError) as exc:
                raise ProcessGone(f"the optimizer process ended: {exc!r}") from exc
        if failed is not None:
            raise failed
        if not ok:
            raise value
        return value

    def restart(self) -> None:
        """End what is left of the process; the next call starts a new one."""
        with self._lock:
            self._end()

    def _end(self) -> None:
        connection, process = self._connection, self._process
        self._connection = None
        if connection is not None:
            connection.close()  # the process's recv ends: it returns
        if process is not None and process.is_alive():
            process.join(timeout=0.1)
            if process.is_alive():
                process.kill()

    def shutdown(self, wait: bool = True) -> None:
        with self._lock:
            connection, self._connection = self._connection, None
        if connection is not None:
            connection.close()
        if wait:
            self.join()

    def join(self) -> None:
        """Wait until the process told to end (:meth:`shutdown`) has."""
        process = self._process
        if process is not None:
            process.join(timeout=10)
            if process.is_alive():
                process.kill()
                process.join()


class OptimizerHost:
    """The running jobs' optimizers, each job's in a process of its own: the jobs' asks run at once on as many
    cores as there are, and none of them on the server's interpreter. A process whose job ended waits for the next
    job (starting one costs ~1 s of imports), so a server keeps as many as it ran jobs at once."""

    def __init__(self, niceness: int = 0) -> None:
        """``niceness`` > 0 lowers the processes' CPU priority (a job's work, below the requests the server answers)."""
        self.niceness = niceness
        self._lock = threading.Lock()
        self._idle: list[_Process] = []
        self._busy: set[_Process] = set()
        self._closed = False

    def start(self, processes: int = 1) -> None:
        """Start ``processes`` idle processes (else the first jobs' first asks wait for theirs); returns at once."""
        started = [_Process(self.niceness) for _ in range(processes)]
        for process in started:
            process.send(_warm)
        with self._lock:
            self._idle.extend(started)

    def wait_started(self) -> None:
        """Return once every idle process answers."""
        with self._lock:
            idle = list(self._idle)
        for process in idle:
            process.call(os.getpid)

    def open(self, spec: TuningSpec, history: History) -> RemoteOptimizer:
        """The job's optimizer, in a process of its own, in the state it had after telling ``history``."""
        optimizer = RemoteOptimizer(self, self._take(), OptimizerStart.of(spec), list(history))
        optimizer.restore()
        return optimizer

    def _take(self) -> _Process:
        with self._lock:
            if self._closed:
                raise RuntimeError("the optimizer host is shut down")
            process = self._idle.pop() if self._idle else _Process(self.niceness)
            self._busy.add(process)
        return process

    def release(self, process: _Process) -> None:
        """A job's optimizer is closed: its process waits for the next job."""
        with self._lock:
            self._busy.discard(process)
            if not self._closed:
                self._idle.append(process)
                return
        process.shutdown(wait=False)

    def shutdown(self) -> None:
        with self._lock:
            self._closed = True
            processes = [*self._idle, *self._busy]
            self._idle.clear()
            self._busy.clear()
        for process in processes:  # all told to end first: each ends on its own clock
            process.shutdown(wait=False)
        for process in processes:
            process.join()


class RemoteOptimizer:
    """A job's optimizer in its process: ask and tell as on driftlab.core.optimizer.BayesianOptimizer."""

    def __init__(self, host: OptimizerHost, process: _Process, start: OptimizerStart, history: History) -> None:
        self._host, self._process, self._start, self._told = host, process, start, history
        self._key = uuid.uuid4().hex

    @property
    def pid(self) -> int:
        """Its process's id (a test kills it)."""
        return self._process.call(os.getpid)

    def restore(self) -> None:
        self._process.call(_open, self._key, self._start, self._told)

    def ask(self) -> dict[str, float]:
        return self._call(_ask, self._key)

    def tell(self, theta: dict[str, float], value: float | None, stored_j: float) -> None:
        """Sent, not waited for: the job stores and asks meanwhile (the next ask is answered after this tell)."""
        self._told.append((theta, value, stored_j))
        try:
            self._process.send(_tell, self._key, theta, value, stored_j)
        except ProcessGone:  # the restored optimizer is told it with the rest of the history
            self._process.restart()
            self.restore()

    def close(self) -> None:
        try:
            self._process.call(_close, self._key)
        except ProcessGone:
            self._process.restart()  # gone: the next job that takes it starts a new one
        self._host.release(self._process)

    def _call(self, fn, *args) -> Any:
        try:
            return self._process.call(fn, *args)
        except ProcessGone:
            self._process.restart()
            self.restore()
            return self._process.call(fn, *args)
