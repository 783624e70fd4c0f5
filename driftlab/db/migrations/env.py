"""Alembic environment: runs on the connection :func:`driftlab.db.schema.upgrade` hands it (no alembic.ini)."""

from alembic import context

from driftlab.db.models import Base

connection = context.config.attributes["connection"]
# render_as_batch: SQLite alters tables by copying them; batch mode does that where ALTER cannot.
context.configure(connection=connection, target_metadata=Base.metadata, render_as_batch=True)
with context.begin_transaction():
    context.run_migrations()
