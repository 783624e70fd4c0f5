"""The loop that runs a piece of work's episodes on its share of the slots (driftlab.worker.slotted), called from
several threads at once, as a calibration's candidate searches call it: each run gets its own results, and none
sleeps through the return of its episodes."""

import random
import threading
import time
from concurrent.futures import Future

import numpy as np

import driftlab.worker.slotted as slotted
from driftlab.worker.executors import EpisodeOutcome
from driftlab.worker.slots import EpisodeSlots
from driftlab.worker.slotted import SlottedEpisodes


class QuickExecutor:
    """Each episode's J is its seed; it comes back after a random delay of at most 2 ms, on a thread of its own."""

    def __init__(self) -> None:
        self.rng = random.Random(0)

    def submit(self, theta, config_doc, seed=0) -> Future:
        future: Future = Future()
        delay_s = self.rng.uniform(0.0, 0.002)

        def finish():
            time.sleep(delay_s)
            future.set_result(EpisodeOutcome.packing(theta=dict(theta), seed=seed, status="completed", J=float(seed),
                                                     metrics={}, trigger_points=[], wall_ms=1.0, columns=["t_s"],
                                                     trajectory=np.zeros((2, 1))))

        threading.Thread(target=finish, daemon=True).start()
        return future


def test_runs_of_one_owner_in_several_threads_each_get_their_results_without_waiting_for_a_heartbeat(monkeypatch):
    # A wake one thread's run cleared for another's episode would leave that run asleep until the heartbeat: an hour
    # here, so such a run is still going when the threads are joined.
    monkeypatch.setattr(slotted, "HEARTBEAT_S", 3600.0)
    slots = EpisodeSlots(2)
    results: dict[int, list[float]] = {}

    def search(number: int) -> None:
        for batch in range(30):
            seeds = [1000 * number + 10 * batch + i for i in range(3)]
            got = [0.0] * len(seeds)
            episodes.run([({"k": 0.05}, {}, s) for s in seeds],
                         lambda i, outcome, got=got: got.__setitem__(i, outcome.J), lambda: True)
            assert got == [float(s) for s in seeds]
            results.setdefault(number, []).extend(got)

    with SlottedEpisodes(QuickExecutor(), slots, owner="calibration 1") as episodes:
        threads = [threading.Thread(target=search, args=(n,), daemon=True) for n in range(4)]
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(timeout=120)
    assert not any(thread.is_alive() for thread in threads)
    assert sorted(results) == [0, 1, 2, 3] and all(len(r) == 90 for r in results.values())
    assert slots.peak == 2 and slots.in_flight == 0
