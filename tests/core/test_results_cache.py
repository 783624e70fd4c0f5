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

# Prints the family of the BMW (vehicle 2) at 0.5 rad @ R 44 m, its mass scaled by argv[2], and with argv[3] "fit"
# the controller's model of it fitted there with the drive coupling (its rear coupling found from ~460 of the model's
# equilibria); with argv[1] "read", a call into a solver (the plant's or the model's equilibria) fails the process.
_SOLVED = """
import json, sys
import driftlab.core.commonroad.equilibrium as equilibrium
import driftlab.core.equilibrium as model_equilibrium
from driftlab.core.commonroad.model_fit import fitted_model_vehicle
from driftlab.core.commonroad.parameters import pack_commonroad
from driftlab.core.plants import plant_type

if sys.argv[1] == "read":
    def _no_solve(*args, **kwargs):
        raise AssertionError("solved again")
    equilibrium.hybr = model_equilibrium.hybr = _no_solve
family = equilibrium.plant_drifts(44.0, -0.5, pack_commonroad(2, mass_scale=float(sys.argv[2])))
print(json.dumps([[drift.as_dict() for drift in part] for part in family]))
if sys.argv[3] == "fit":
    print(repr(fitted_model_vehicle(2, 44.0, 0.5, plant_type("commonroad_std"), drive_coupling=True)))
"""


def _solved(cache_home, mode, mass_scale, fit="fit"):
    # NUMBA_CACHE_DIR (set by driftlab.core in this process) is inherited: the kernels are not compiled again.
    env = {**os.environ, "XDG_CACHE_HOME": str(cache_home)}
    return subprocess.run([sys.executable, "-c", _SOLVED, mode, str(mass_scale), fit], env=env, capture_output=True,
                          text=True, timeout=300)


def test_a_family_and_a_fit_solved_in_one_process_are_read_by_the_next_and_another_cars_is_solved(tmp_path):
    solved = _solved(tmp_path, "solve", 1.0)
    assert solved.returncode == 0, solved.stderr
    family, fit = solved.stdout.splitlines()
    holdable, frozen = json.loads(family)
    assert holdable and holdable[0]["countersteer"] and frozen  # the BMW's drift there, and its frozen-wheel states
    assert "rear_friction_circle=True" in fit and "rear_coupling=1.0)" not in fit  # the coupling was fitted
    read = _solved(tmp_path, "read", 1.0)
    assert read.returncode == 0, read.stderr
    assert read.stdout == solved.stdout  # every float as solved
    heavier = _solved(tmp_path, "read", 1.1, fit="no")
    assert heavier.returncode != 0 and "solved again" in heavier.stderr


def test_without_a_writable_cache_home_each_process_solves_its_own(tmp_path):
    not_a_folder = tmp_path / "file"
    not_a_folder.write_text("")
    solved = _solved(not_a_folder, "solve", 1.0, fit="no")
    assert solved.returncode == 0, solved.stderr
    again = _solved(not_a_folder, "read", 1.0, fit="no")
    assert again.returncode != 0 and "solved again" in again.stderr

