"""The job document's version: a stored job says which release's document it is.

Revision 17 stamps "version": 1 on every job document stored before it (a document without one is a new one, of
this release: driftlab.core.tuning.JOB_DOCUMENT_VERSION): what a later version changes in how a job runs applies to
new jobs only, and the stored ones re-run bit for bit.

Revision ID: 0017
Revises: 0016
"""

import json

import sqlalchemy as sa
from alembic import op

revision = "0017"
down_revision = "0016"
branch_labels = None
depends_on = None


def upgrade() -> None:
    bind = op.get_bind()
    for row_id, raw in bind.execute(sa.text("SELECT id, spec FROM jobs")).all():
        spec = json.loads(raw) if isinstance(raw, str) else raw
        if isinstance(spec, dict) and "version" not in spec:
            bind.execute(sa.text("UPDATE jobs SET spec = :value WHERE id = :id"),
                         {"value": json.dumps({"version": 1, **spec}), "id": row_id})
    op.execute("UPDATE meta SET value = '17' WHERE key = 'schema_version'")
