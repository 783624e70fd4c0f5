"""Shared fixtures: the app in-process (no server, no worker, no view process) on a real SQLite file."""

import pytest
from fastapi.testclient import TestClient

from driftlab.server.app import create_app
from driftlab.settings import Settings
from driftlab.worker.executors import evaluate_episode


def in_process_client(db_path, **settings) -> TestClient:
    """A TestClient on the app with nothing started: what the routes answer, not what a runner does later."""
    app = create_app(f"sqlite:///{db_path}", start_worker=False, start_view=False, settings=Settings(**settings))
    return TestClient(app, base_url="http://127.0.0.1")


@pytest.fixture
def api(tmp_path):
    with in_process_client(tmp_path / "api.db") as client:
        yield client


class InThreadExecutor:
    """The executor interface on a thread pool: the real episodes, in this process."""

    def __init__(self, pool):
        self.pool = pool
        self.submitted = 0

    def submit(self, theta, config_doc, seed=0):
        self.submitted += 1
        return self.pool.submit(evaluate_episode, theta, config_doc, seed)

    def shutdown(self):
        pass
