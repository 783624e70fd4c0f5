"""Trajectory files, CSV and JSON, that say what they are: the API's downloads and `driftlab episode --csv`.

The metadata (the evaluation and job, theta, the seed of the episode and that episode's J beside the evaluation's
mean, the config) is the JSON's ``metadata`` object beside ``columns`` and ``rows``. The CSV is the header and the
rows alone, so that the first line a person types, ``pandas.read_csv(file)``, gives the trajectory's columns; its
metadata is the JSON download's (the API) or a sidecar JSON file beside it (`driftlab episode --csv`,
:func:`metadata_path`). Integer columns stay integers; floats are written with ``repr`` (they read back as the same
doubles). A CSV of a release before this one has its metadata as a first line ``# driftlab: {...}``
(``pandas.read_csv(f, comment="#")`` skips it).
"""

from __future__ import annotations

import csv
import io
import json
import os
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


def trajectory_csv(columns: list[str], rows: np.ndarray) -> str:
    """The header and one row per control step: nothing else, so that any CSV reader takes it as it is."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    writer.writerows(_typed_rows(list(columns), rows))
    return buffer.getvalue()


def metadata_path(csv_path: str) -> str:
    """Where `driftlab episode --csv FILE` writes the CSV's metadata: FILE with ``.json`` for its suffix
    (``run.csv`` -> ``run.json``; ``run`` -> ``run.json``)."""
    stem, suffix = os.path.splitext(csv_path)
    return (stem if suffix.lower() == ".csv" else csv_path) + ".json"


def metadata_json(metadata: dict[str, Any]) -> str:
    """The sidecar's text: ``{"metadata": {...}}``, the JSON download's object without its rows."""
    return json.dumps({"metadata": metadata}, indent=1) + "\n"
