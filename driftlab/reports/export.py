"""Trajectory files, CSV and JSON, that say what they are: the API's downloads and `driftlab episode --csv`.

Each carries its metadata (the evaluation and job, theta, the seed of the episode and that episode's J beside the
evaluation's mean, the config): JSON as a ``metadata`` object beside ``columns`` and ``rows``; CSV as one comment
line before the header, ``# driftlab: {...JSON...}`` (``pandas.read_csv(f, comment="#")`` and
``numpy.loadtxt`` skip it). Integer columns stay integers; floats are written with ``repr`` (they read back as
the same doubles).
"""

from __future__ import annotations

import csv
import io
import json
import re
from typing import Any

import numpy as np

from driftlab.core.metrics import laps_of_rows
from driftlab.core.track import FigureEight

# Columns whose values are integers (the planner's phase, the solver flag, the lap); the rest are SI floats.
INTEGER_COLUMNS = frozenset({"phase", "osqp", "lap"})


def with_lap_column(columns: list[str], rows: np.ndarray, track: FigureEight) -> tuple[list[str], np.ndarray]:
    """The trajectory with a last column ``lap``: the lap of the 8 each step is on (1, 2, ...; by the arc length
    driven, as the per-lap metrics cut them)."""
    lap = laps_of_rows(rows, {name: i for i, name in enumerate(columns)}, track)
    return [*columns, "lap"], np.column_stack([rows, lap]) if len(rows) else np.zeros((0, len(columns) + 1))


def _typed_rows(columns: list[str], rows: np.ndarray) -> list[list[Any]]:
    integer = [i for i, name in enumerate(columns) if name in INTEGER_COLUMNS]
    out = rows.tolist()
    for row in out:
        for i in integer:
            row[i] = int(row[i])
    return out


def trajectory_json(columns: list[str], rows: np.ndarray, metadata: dict[str, Any]) -> str:
    return json.dumps({"metadata": metadata, "columns": list(columns), "rows": _typed_rows(list(columns), rows)})


_JSON_STRING = re.compile(r'"(?:[^"\\]|\\.)*"')


def one_cell_json(value: Any) -> str:
    """JSON whose string literals hold no comma (written as the escape \\u002c, which reads back the same): a
    spreadsheet that splits the metadata line at commas keeps it in one cell starting with '#', so a name such
    as '=cmd|...' never becomes a formula cell of its own (OWASP's CSV injection)."""
    return _JSON_STRING.sub(lambda m: m.group(0).replace(",", "\\u002c"), json.dumps(value))


def trajectory_csv(columns: list[str], rows: np.ndarray, metadata: dict[str, Any]) -> str:
    buffer = io.StringIO()
    buffer.write("# driftlab: " + one_cell_json(metadata) + "\n")
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    writer.writerows(_typed_rows(list(columns), rows))
    return buffer.getvalue()


def read_csv_metadata(text: str) -> dict[str, Any]:
    """The metadata of a trajectory CSV written by :func:`trajectory_csv` ({} for a file without it)."""
    first = text.split("\n", 1)[0]
    return json.loads(first[len("# driftlab: "):]) if first.startswith("# driftlab: ") else {}
