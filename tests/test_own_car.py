"""Bring your own car as docs/calibration.md tells a user: a package that registers a CommonRoad variant under the
entry-point group ``driftlab.plants``, installed with pip beside DriftLab, then driven by the command line."""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.e2e  # real processes: pip and the CLI

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "heavy_bmw"


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """The example package installed by pip into a directory of its own (so the test leaves the environment as it
    found it); a process with it on PYTHONPATH sees its entry point as any installed package's."""
    target = tmp_path_factory.mktemp("site")
    source = shutil.copytree(EXAMPLE, tmp_path_factory.mktemp("source") / EXAMPLE.name)  # setuptools builds in place
    done = subprocess.run([sys.executable, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation",
                           "--target", str(target), str(source)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return {**os.environ, "PYTHONPATH": str(target)}


def _driftlab(env, *args):
    return subprocess.run([sys.executable, "-m", "driftlab.cli", *args], capture_output=True, text=True, timeout=300,
                          env=env)


def test_an_installed_variant_drifts_the_eight_with_the_base_cars_controller(installed):
    out = _driftlab(installed, "episode", "--plant", "heavy_bmw", "--seed", "1")
    assert out.returncode == 0, out.stderr
    episode = json.loads(out.stdout)
    assert episode["status"] == "completed" and episode["mean_abs_e_m"] < 1.0
    # The heavier, higher car on worse tyres drifts its own, slower drift: not the BMW's (~20.5 m/s at 0.5 rad).
    bmw = json.loads(_driftlab(installed, "episode", "--plant", "commonroad_std", "--seed", "1").stdout)
    assert episode["min_speed_mps"] < bmw["min_speed_mps"] - 0.5


def test_an_installed_variant_outside_its_window_is_refused_naming_it(installed):
    out = _driftlab(installed, "episode", "--plant", "heavy_bmw", "--set", "scenario.sideslip_rad=0.3")
    assert out.returncode == 2 and out.stdout == ""
    assert "scenario.sideslip_rad in 0.4" in out.stderr and len(out.stderr.strip().splitlines()) == 1
