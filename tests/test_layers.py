"""The layers as the code reads them (an AST walk of driftlab/): core imports nothing of the outer layers, and the
settings are read from the environment only at an entry point, then passed in."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "driftlab"
OUTER = ("driftlab.db", "driftlab.server", "driftlab.web", "driftlab.worker", "driftlab.cli", "driftlab.services",
         "driftlab.reports")
# Where the DRIFTLAB_* environment is read: the command line (once per command) and the app (its default).
SETTINGS_ENTRY_POINTS = {"cli/options.py", "server/app.py"}


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        yield path.relative_to(PACKAGE).as_posix(), ast.parse(path.read_text(), filename=str(path))


def _imported(tree):
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            yield node.module
        elif isinstance(node, ast.Import):
            yield from (alias.name for alias in node.names)


def test_core_imports_nothing_of_the_outer_layers():
    wrong = [(name, module) for name, tree in _modules() if name.startswith("core/")
             for module in _imported(tree) if module.startswith(OUTER)]
    assert wrong == []


def test_settings_are_built_only_at_entry_points():
    built = sorted({name for name, tree in _modules() for node in ast.walk(tree)
                    if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "Settings"})
    assert built and set(built) <= SETTINGS_ENTRY_POINTS, built


# What the view may not import: storage, and the modules that simulate, control or solve the car's physics. It reads
# through driftlab.services.read_model and draws; it may use the config's schema, the track's geometry and the
# statuses' names.
VIEW_MAY_NOT = ("driftlab.db", "driftlab.worker", "driftlab.core.vehicle", "driftlab.core.plant",
                "driftlab.core.plants", "driftlab.core.commonroad", "driftlab.core.equilibrium",
                "driftlab.core.drivability", "driftlab.core.episode", "driftlab.core.closed_loop", "driftlab.core.mpc",
                "driftlab.core.controller", "driftlab.core.compiled", "driftlab.core.variation",
                "driftlab.core.calibration", "driftlab.core.robust", "sqlalchemy")


def test_the_view_imports_neither_storage_nor_the_physics():
    wrong = [(name, module) for name, tree in _modules() if name.startswith("web/")
             for module in _imported(tree) if any(module == m or module.startswith(f"{m}.") for m in VIEW_MAY_NOT)]
    assert wrong == []
    assert any(module == "driftlab.services" or module.startswith("driftlab.services.")
               for name, tree in _modules() if name.startswith("web/") for module in _imported(tree))
