"""Shared fixtures: the app in-process (no server, no worker, no view process) on a real SQLite file."""

import pytest
from fastapi.testclient import TestClient

from driftlab.server.app import create_app
from driftlab.settings import Settings


def in_process_client(db_path, **settings) -> TestClient:
    """A TestClient on the app with nothing started: what the routes answer, not what a runner does later."""
    app = create_app(f"sqlite:///{db_path}", start_worker=False, start_view=False, settings=Settings(**settings))
    return TestClient(app, base_url="http://127.0.0.1")


@pytest.fixture
def api(tmp_path):
    with in_process_client(tmp_path / "api.db") as client:
        yield client
