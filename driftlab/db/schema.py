"""The database schema's version, kept by Alembic (driftlab/db/migrations): every `driftlab serve`, `tune`,
`rescore` and `report` upgrades the database it opens to the newest revision before touching it.

A database written before Alembic came in (schema 1: tables, no ``alembic_version``) is stamped at the
baseline revision first, then upgraded like any other.
"""

from __future__ import annotations

from pathlib import Path

from alembic import command
from alembic.config import Config
from alembic.runtime.migration import MigrationContext
from alembic.script import ScriptDirectory
from sqlalchemy import Connection, Engine, inspect, text

from driftlab.db.models import Base

MIGRATIONS = Path(__file__).parent / "migrations"
BASELINE = "0001"


def _config(connection) -> Config:
    config = Config()
    config.set_main_option("script_location", str(MIGRATIONS))
    config.attributes["connection"] = connection
    return config


def head_revision() -> str:
    head = ScriptDirectory.from_config(_config(None)).get_current_head()
    if head is None:
        raise RuntimeError(f"no migration head in {MIGRATIONS}: the package's migrations are missing")
    return head


def current_revision(engine: Engine) -> str | None:
    with engine.connect() as connection:
        return MigrationContext.configure(connection).get_current_revision()


def _revision_of_meta(connection) -> str:
    """A pre-Alembic database's revision, from its meta table's schema_version (1: the baseline)."""
    version = connection.execute(text("SELECT value FROM meta WHERE key = 'schema_version'")).scalar()
    return {"2": "0002"}.get(str(version), BASELINE)


class NewerDatabaseError(Exception):
    """The database was written by a newer DriftLab (a schema revision this one does not know)."""


def upgrade(engine: Engine) -> None:
    """Bring the database to the head revision (a no-op when it is there).

    Raises:
        NewerDatabaseError: the database's revision is unknown here: a newer release made it.
    """
    current = current_revision(engine)
    if current == head_revision():
        return
    if current is not None:
        try:
            known = ScriptDirectory.from_config(_config(None)).get_revision(current) is not None
        except Exception:  # alembic raises its own errors for revisions it cannot locate
            known = False
        if not known:
            raise NewerDatabaseError(f"the database is at schema revision {current!r}, newer than this DriftLab "
                                     f"knows ({head_revision()}): upgrade DriftLab, or use another --db")
    with engine.connect() as connection:
        # SQLite rebuilds a table to alter it; with foreign keys enforced, dropping the old jobs table would
        # fail. The pragma only takes effect outside a transaction, hence on the driver's connection first.
        sqlite = engine.dialect.name == "sqlite"
        if sqlite:
            _driver_execute(connection, "PRAGMA foreign_keys=OFF")
        with connection.begin():
            config = _config(connection)
            tables = set(inspect(connection).get_table_names())
            if not sqlite and not tables:
                # A new database of another kind: the schema as the models declare it. The revisions before it
                # upgrade SQLite files of earlier releases (with SQLite's SQL); later ones run on both kinds.
                Base.metadata.create_all(connection)
                command.stamp(config, "head")
            elif "alembic_version" not in tables and "jobs" in tables:
                command.stamp(config, _revision_of_meta(connection))
            command.upgrade(config, "head")
        if sqlite:
            _driver_execute(connection, "PRAGMA foreign_keys=ON")


def _driver_execute(connection: Connection, statement: str) -> None:
    """Run ``statement`` on the driver's own connection, outside SQLAlchemy's transaction."""
    driver = connection.connection.driver_connection
    if driver is None:
        raise RuntimeError("the database connection is closed")
    driver.execute(statement)
