"""The `driftlab` command line, run as a real process."""

import json
import subprocess
import sys

import pytest

EPISODE_KEYS = {"status", "J", "completed_fraction", "mean_abs_e_m", "max_abs_e_m", "mean_abs_beta_err_rad",
                "beta_flip_s", "min_speed_mps", "trigger_times_s", "wall_ms"}


def _run(*args):
    return subprocess.run([sys.executable, "-m", "driftlab.cli", *args], capture_output=True, text=True, timeout=120)


def test_equilibrium_prints_table_one_json():
    out = _run("equilibrium", "--radius", "44", "--beta", "-0.4", "--plant", "default")
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert set(data) >= {"V", "beta", "r", "delta", "Fxr", "plant"}
    assert data["V"] == pytest.approx(19.1, rel=5e-3)
    assert set(data["plant"]) >= {"V", "beta", "r", "delta", "Fxr"}


def test_equilibrium_without_drift_reports_error_with_exit_2():
    out = _run("equilibrium", "--beta", "0.95")
    assert out.returncode == 2
    assert "beta" in out.stderr and len(out.stderr.strip().splitlines()) == 1


def test_episode_json_has_the_documented_keys(tmp_path):
    csv_file = tmp_path / "traj.csv"
    out = _run("episode", "--plant", "nominal", "--theta", "c_lr=0.02,c_rl=0.02,dV=0,k=0.05",
               "--csv", str(csv_file))
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert EPISODE_KEYS <= set(data)
    assert data["status"] == "completed"
    lines = csv_file.read_text().splitlines()
    assert lines[0].startswith("t_s,x_m,y_m") and len(lines) > 500


@pytest.mark.parametrize("args, field", [
    (("episode", "--set", "mpc.nope=1"), "mpc.nope"),
    (("episode", "--theta", "c_lr=3"), "theta.c_lr"),
    (("episode", "--set", "plant.cg_height_m=abc"), "plant.cg_height_m"),
    (("equilibrium", "--radius", "x"), "--radius"),
])
def test_bad_arguments_exit_2_naming_the_field(args, field):
    out = _run(*args)
    assert out.returncode == 2
    assert field in out.stderr
