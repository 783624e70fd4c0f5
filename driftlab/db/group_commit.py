"""Several writers' transactions committed as one: each caller hands a write (a function of the session) to the
database's writer thread and gets its result once the transaction that ran it is committed.

Eight jobs storing their evaluations at once each opened a write transaction of its own: eight lock handoffs and
eight commits, each writer holding the lock while the interpreter ran the other jobs' threads. The writer thread
takes every write waiting when it frees up and runs them one after another in one transaction (a group commit,
as databases do with their logs). Nothing is acknowledged before its commit: a caller's result comes after it.

A write that raises rolls the batch back; the writes of a batch of several are then run again one transaction each,
so one write's error is its caller's alone (a write may therefore run twice: its effects outside the database must
bear it).
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable
from concurrent.futures import Future
from typing import Any, TypeVar

from sqlalchemy import Connection
from sqlalchemy.orm import Session, sessionmaker

from driftlab.db import storage

T = TypeVar("T")
_IDLE_S = 1.0  # a writer thread with nothing to do for this long ends (the next write starts another)


class _Writer:
    def __init__(self, factory: sessionmaker[Session]) -> None:
        self.factory = factory
        self.waiting: queue.SimpleQueue[tuple[Callable[[Session], Any], Future]] = queue.SimpleQueue()
        self.thread: threading.Thread | None = None
        self.connection: Connection | None = None  # kept open while the thread runs (storage.transaction_on)

    def loop(self) -> None:
        try:
            self._loop()
        finally:
            self._close()

    def _close(self) -> None:
        if self.connection is not None:
            self.connection.close()
            self.connection = None

    def _loop(self) -> None:
        while True:
            try:
                batch = [self.waiting.get(timeout=_IDLE_S)]
            except queue.Empty:
                with _LOCK:
                    if self.waiting.empty():
                        self.thread = None
                        if _WRITERS.get(id(self.factory)) is self:
                            del _WRITERS[id(self.factory)]
                        return
                continue
            while True:
                try:
                    batch.append(self.waiting.get_nowait())
                except queue.Empty:
                    break
            self.commit(batch)

    def commit(self, batch: list[tuple[Callable[[Session], Any], Future]]) -> None:
        try:
            if self.connection is None:
                self.connection = storage.engine_of(self.factory).connect()
            with storage.transaction_on(self.connection) as session:
                results = [write(session) for write, _ in batch]
        except Exception as exc:  # noqa: BLE001  # a write's error goes to its caller, the others run again
            self._close()  # the next transaction on a new connection, whatever state this one is in
            if len(batch) == 1:
                batch[0][1].set_exception(exc)
            else:
                for item in batch:
                    self.commit([item])
            return
        for (_, future), result in zip(batch, results, strict=True):
            future.set_result(result)


_LOCK = threading.Lock()
_WRITERS: dict[int, _Writer] = {}


def write(factory: sessionmaker[Session], fn: Callable[[Session], T]) -> T:
    """``fn(session)`` run in a write transaction shared with whatever other writes wait at the same time, its
    result returned once that transaction is committed (its exception raised, alone, if it raised)."""
    future: Future = Future()
    with _LOCK:
        writer = _WRITERS.get(id(factory))
        if writer is None or writer.factory is not factory:
            writer = _WRITERS[id(factory)] = _Writer(factory)
        writer.waiting.put((fn, future))
        if writer.thread is None:
            writer.thread = threading.Thread(target=writer.loop, name="driftlab-group-commit", daemon=True)
            writer.thread.start()
    return future.result()
