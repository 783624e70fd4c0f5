"""The what-if panel's rate limit: one tab (websocket connection) cannot keep the what-if worker busy."""

import threading
import time
from concurrent.futures import Future

from driftlab.core.config import EpisodeConfig, config_to_dict
from driftlab.web.view_app import EpisodeBudget, WhatIfRunner


class _Tab:
    """What the runner needs of a ClientSession: its connection's id, and where results go."""

    def __init__(self, client_id: int) -> None:
        self.client = type("Client", (), {"client_id": client_id})()
        self.results: list[tuple] = []
        self.done = threading.Event()

    def on_what_if_result(self, frames, error, wall_ms) -> None:
        self.results.append((frames, error))
        self.done.set()


def _failing_runner(theta, config_doc, seed) -> Future:
    future: Future = Future()
    future.set_exception(RuntimeError(f"ran seed {seed}"))  # finished at once: only the rate limit holds it back
    return future


def test_the_budget_allows_a_burst_then_the_average_rate():
    now = [0.0]
    budget = EpisodeBudget(per_minute=60.0, burst=3, clock=lambda: now[0])
    assert [budget.wait_s() for _ in range(3)] == [0.0, 0.0, 0.0]
    assert abs(budget.wait_s() - 1.0) < 1e-9  # 60 a minute: the next in a second
    now[0] = 2.5
    assert budget.wait_s() == 0.0 and budget.wait_s() == 0.0 and budget.wait_s() > 0.0


def test_a_tab_flooding_requests_starts_only_its_budget_and_keeps_the_newest():
    runner = WhatIfRunner(_failing_runner, per_minute=60.0, burst=2)
    tab, other = _Tab(1), _Tab(2)
    doc = config_to_dict(EpisodeConfig())
    for seed in range(50):
        runner.request(tab, {}, doc, {}, seed)
    assert runner.started == 2  # the burst; the other 48 wait, and only the newest is kept
    runner.request(other, {}, doc, {}, 7)
    assert runner.started == 3  # another tab has a budget of its own
    deadline = time.monotonic() + 5.0
    while runner.started < 4 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)
    assert runner.started == 4  # after ~1 s the newest waiting request ran, and nothing else
    assert tab.results[-1][1] == "RuntimeError: ran seed 49"
