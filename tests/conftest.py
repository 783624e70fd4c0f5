"""Fixtures every test folder may use."""

import pytest


@pytest.fixture(scope="session")
def postgres():
    """A real PostgreSQL server for the session (tests/postgres_server.py): ``postgres.new_database()`` gives the
    URL of a new empty database."""
    from tests.postgres_server import PostgresServer

    server = PostgresServer()
    yield server
    server.stop()
