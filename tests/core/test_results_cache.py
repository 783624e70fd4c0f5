"""A CommonRoad car's drift family and the controller model's fit to it are solved once and read from the cache of
solved results by every other process (driftlab.core.results_cache): the same floats, no solve; another car's
parameters are solved, never answered from another's entry; without a writable cache home nothing is kept and all
still works."""

import json
import os
import subprocess
import sys

import pytest

pytestmark = pytest.mark.e2e  # real processes: each reads what the one before it kept

# Prints the family of the BMW (vehicle 2) at 0.5 rad @ R 44 m, its mass scaled by argv[2]; with argv[1] "read",
# a call into a solver (the plant's or the model's equilibria) fails the process.
_FAMILY = """
import json, sys
import driftlab.core.commonroad.equilibrium as equilibrium
import driftlab.core.equilibrium as model_equilibrium
from driftlab.core.commonroad.parameters import pack_commonroad

if sys.argv[1] == "read":
    def _no_solve(*args, **kwargs):
        raise AssertionError("solved again")
    equilibrium.root = model_equilibrium.root = _no_solve
family = equilibrium.plant_drifts(44.0, -0.5, pack_commonroad(2, mass_scale=float(sys.argv[2])))
print(json.dumps([[drift.as_dict() for drift in part] for part in family]))
"""
# Prints the controller's model of the BMW fitted at 0.5 rad @ R 44 m with the drive coupling (its rear coupling found
# from ~460 of the model's equilibria).
_FIT = _FAMILY.split("family =")[0] + """
from driftlab.core.commonroad.model_fit import fitted_model_vehicle
from driftlab.core.plants import plant_type

print(repr(fitted_model_vehicle(2, 44.0, 0.5, plant_type("commonroad_std"), drive_coupling=True)))
"""


def _family(cache_home, mode, mass_scale, script=_FAMILY):
    # NUMBA_CACHE_DIR (set by driftlab.core in this process) is inherited: the kernels are not compiled again.
    env = {**os.environ, "XDG_CACHE_HOME": str(cache_home)}
    return subprocess.run([sys.executable, "-c", script, mode, str(mass_scale)], env=env, capture_output=True,
                          text=True, timeout=300)


def test_a_family_solved_in_one_process_is_read_by_the_next_and_another_cars_is_solved(tmp_path):
    solved = _family(tmp_path, "solve", 1.0)
    assert solved.returncode == 0, solved.stderr
    holdable, frozen = json.loads(solved.stdout)
    assert holdable and holdable[0]["countersteer"] and frozen  # the BMW's drift there, and its frozen-wheel states
    read = _family(tmp_path, "read", 1.0)
    assert read.returncode == 0, read.stderr
    assert read.stdout == solved.stdout  # every float as solved
    heavier = _family(tmp_path, "read", 1.1)
    assert heavier.returncode != 0 and "solved again" in heavier.stderr
    assert _family(tmp_path, "solve", 1.1).stdout != solved.stdout


def test_the_models_fit_is_read_by_the_next_process(tmp_path):
    fitted = _family(tmp_path, "solve", 1.0, _FIT)
    assert fitted.returncode == 0, fitted.stderr
    assert "rear_friction_circle=True" in fitted.stdout and "rear_coupling=1.0)" not in fitted.stdout
    read = _family(tmp_path, "read", 1.0, _FIT)
    assert read.returncode == 0, read.stderr
    assert read.stdout == fitted.stdout


def test_without_a_writable_cache_home_each_process_solves_its_own(tmp_path):
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("")
    solved = _family(not_a_folder, "solve", 1.0)
    assert solved.returncode == 0, solved.stderr
    again = _family(not_a_folder, "read", 1.0)
    assert again.returncode != 0 and "solved again" in again.stderr

