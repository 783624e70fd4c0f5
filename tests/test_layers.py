"""The layers as the code reads them (an AST walk of driftlab/): core imports nothing of the outer layers, and the
settings are read from the environment only at an entry point, then passed in."""

import ast
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent.parent / "driftlab"
OUTER = ("driftlab.db", "driftlab.server", "driftlab.web", "driftlab.worker", "driftlab.cli", "driftlab.services",
         "driftlab.reports", "driftlab.gym")
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


def test_the_gym_package_imports_only_core_and_gymnasium():
    """driftlab.gym sits at the edge: the computation it steps is core's, and it needs no storage, service or view."""
    imported = {module for name, tree in _modules() if name.startswith("gym/") for module in _imported(tree)}
    driftlab = {module for module in imported if module.startswith("driftlab")}
    assert driftlab and all(module.startswith(("driftlab.core", "driftlab.gym")) for module in driftlab), driftlab
    assert "gymnasium" in imported


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


def _module_name(relative: str) -> str:
    name = "driftlab." + relative.removesuffix(".py").replace("/", ".")
    return name.removesuffix(".__init__")


def _import_graph():
    """Every driftlab module and the driftlab modules it imports, at module level or inside a function."""
    modules = {_module_name(name): (name, tree) for name, tree in _modules()}
    graph = {}
    for module, (name, tree) in modules.items():
        package = module if name.endswith("__init__.py") else module.rpartition(".")[0]
        targets = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                candidates = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")
                    base = ".".join(parts[:len(parts) - node.level + 1] + ([node.module] if node.module else []))
                candidates = [f"{base}.{alias.name}" for alias in node.names] + [base]
            else:
                continue
            for candidate in candidates:
                while candidate and candidate not in modules:
                    candidate = candidate.rpartition(".")[0]
                if candidate and candidate != module:
                    targets.add(candidate)
                    break
        graph[module] = targets
    return graph


def test_driftlab_has_no_import_cycle_counting_imports_inside_functions():
    from graphlib import CycleError, TopologicalSorter

    try:
        TopologicalSorter(_import_graph()).prepare()
    except CycleError as exc:
        raise AssertionError(f"an import cycle: {' -> '.join(exc.args[1])}") from None


def test_the_config_schema_loads_no_plant_solver_or_controller():
    """Importing the schema (what the view, the API's models and storage read) runs no physics: the plant catalog,
    CommonRoad's models, the equilibrium solver, the MPC and its QP solver stay unloaded."""
    import subprocess
    import sys

    loaded = subprocess.run([sys.executable, "-c", "import sys, driftlab.core.config; print(*sorted(sys.modules))"],
                            check=True, capture_output=True, text=True).stdout.split()
    heavy = ("driftlab.core.mpc", "driftlab.core.plants", "driftlab.core.commonroad", "driftlab.core.equilibrium",
             "driftlab.core.controller", "driftlab.core.episode", "osqp", "vehiclemodels")
    assert [m for m in loaded if any(m == h or m.startswith(f"{h}.") for h in heavy)] == []
    assert "driftlab.core.config" in loaded
