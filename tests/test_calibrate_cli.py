"""`driftlab calibrate` as a real process on CommonRoad's STD: points outside the car's window are set aside with
the reason, the profile is stored and written, and a job of that car started afterwards takes it."""

import json
import sqlite3
import subprocess
import sys

import pytest

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI


def _run(*args, timeout=600):
    return subprocess.run([sys.executable, "-m", "driftlab.cli", *args], capture_output=True, text=True,
                          timeout=timeout)


def _logs(db):
    """Each stored profile's whole document by id: the profile and its calibration's log (the start, the candidates,
    the known sets tried, the points skipped), which stays in the database."""
    with sqlite3.connect(db) as connection:
        return {pid: json.loads(doc) for pid, doc in connection.execute("SELECT id, document FROM car_profiles")}


# What these tests check (points, known sets, rounds, the profile a job takes) does not depend on the candidate
# controllers (tests/server/test_calibrations.py checks those): one candidate, a quarter of the episodes.
ONE_CANDIDATE = ("--set", "plant.model_drive_coupling=false", "--set", "mpc.steer_limit_rad=0.6")


def test_calibrate_stores_a_profile_that_the_next_job_of_that_car_takes(tmp_path):
    db, out_file = tmp_path / "lab.db", tmp_path / "std.json"
    out = _run("calibrate", "--plant", "commonroad_std", *ONE_CANDIDATE, "--points", "0.5@44,0.2@44",
               "--iterations", "3", "--seeds", "1", "--workers", "2", "--db", str(db), "--out", str(out_file))
    assert out.returncode == 0, out.stderr
    summary, = json.loads(out.stdout)["profiles"]  # the point outside the window got none
    assert summary["profile_id"] == 1 and summary["plant_model"] == "commonroad_std" and summary["episodes"] == 1
    assert "skipped 0.2 rad @ R 44 m" in out.stderr  # outside the window: not run, and said why
    profile, = json.loads(out_file.read_text())["profiles"]
    assert profile["command"].startswith("driftlab calibrate --plant commonroad_std --set plant.model_drive_coupling")
    assert "--points 0.5@44,0.2@44" in profile["command"]
    assert not {"start", "candidates", "known", "skipped"} & set(profile)  # the file is data; the log is stored
    log = _logs(db)[1]
    assert log["skipped"][0]["sideslip_rad"] == 0.2 and log["start"]["per_point"][0]["episodes"] == 1
    assert profile["score"] == log["score"] <= log["start"]["score"]  # the warm start is among the sets tried
    tune = _run("tune", "--plant", "commonroad_std", "--iterations", "1", "--seed-points", "1",
                "--robust-samples", "1", "--confirm-samples", "0", "--name", "after", "--db", str(db))
    assert tune.returncode == 0, tune.stderr

    with sqlite3.connect(db) as connection:
        profile_id, spec = connection.execute("SELECT profile_id, spec FROM jobs WHERE name = 'after'").fetchone()
    mpc = json.loads(spec)["config"]["mpc"]
    assert profile_id == 1 and all(mpc[k] == v for k, v in profile["weights"].items())
    bad = _run("calibrate", "--plant", "commonroad_std", "--points", "0.5/44", "--db", str(db))
    assert bad.returncode == 2 and "--points" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
    bad = _run("calibrate", "--plant", "commonroad_std", "--theta", "dV=0.1,nope=1", "--db", str(db))
    assert bad.returncode == 2 and "'nope'" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1
    bad = _run("calibrate", "--plant", "commonroad_std", "--prune", "0.95", "--db", str(db))
    assert bad.returncode == 2 and "--prune" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1


def test_each_point_is_calibrated_on_its_own_from_the_scenarios_drift_outwards(tmp_path):
    db, out_file = tmp_path / "points.db", tmp_path / "points.json"
    out = _run("calibrate", "--plant", "commonroad_std", *ONE_CANDIDATE, "--points", "0.45@44,0.5@44",
               "--iterations", "2", "--seeds", "1", "--workers", "2", "--db", str(db), "--out", str(out_file))
    assert out.returncode == 0, out.stderr
    written = json.loads(out_file.read_text())["profiles"]
    # (A point where the 2 sets complete nothing gets a second round: round 1 of each is what this test reads.)
    first, second = (p for p in written if p["round"] == 1)
    assert [p["sideslip_rad"] for p in first["per_point"] + second["per_point"]] == [0.5, 0.45]  # scenario's first
    assert [p["profile_id"] for p in json.loads(out.stdout)["profiles"]] == list(range(1, len(written) + 1))
    # The second search tried what the first found (when it found other weights than the car's own) right after
    # the car's own, and each known set once.
    logs = _logs(db)
    tried_first = logs[second["profile_id"]]["known"][0]
    if first["weights"] != logs[first["profile_id"]]["start"]["weights"]:
        assert tried_first["from"] == "profile 1 (0.5 rad @ R 44 m)" and tried_first["weights"] == first["weights"]
    else:
        assert tried_first["from"] == "driftlab's shipped weights"  # (2 iterations: the own set and one more)
    together = _run("calibrate", "--plant", "commonroad_std", *ONE_CANDIDATE, "--points", "0.45@44,0.5@44",
                    "--iterations", "1", "--seeds", "1", "--workers", "2", "--one-set", "--theta", "dV=0.1",
                    "--db", str(db), "--out", str(out_file))
    assert together.returncode == 0, together.stderr
    profile, = json.loads(together.stdout)["profiles"]
    assert len(profile["per_point"]) == 2 and profile["profile_id"] == len(written) + 1
    assert json.loads(out_file.read_text())["profiles"][0]["theta"]["dV"] == 0.1
    rounds = _run("calibrate", "--plant", "commonroad_std", *ONE_CANDIDATE, "--points", "0.5@44", "--iterations", "2",
                  "--seeds", "1", "--workers", "2", "--rounds", "2", "--db", str(db), "--out", str(out_file))
    assert rounds.returncode == 0, rounds.stderr
    first, second = json.loads(out_file.read_text())["profiles"]
    assert [first["round"], second["round"]] == [1, 2]
    if first["per_point"][0]["completed"]:  # the second round searched around the weights the first found
        assert _logs(db)[second["profile_id"]]["start"]["weights"] == pytest.approx(first["weights"], rel=1e-9)
    assert "learned at 0.5 rad @ R 44 m" in rounds.stderr
    bad = _run("calibrate", "--plant", "commonroad_std", "--rounds", "2", "--one-set", "--db", str(db))
    assert bad.returncode == 2 and "--rounds" in bad.stderr and len(bad.stderr.strip().splitlines()) == 1


def test_a_batch_comes_back_in_the_order_it_was_sent_whatever_the_number_of_workers():
    """What makes a calibration's profiles the same with any --workers (its default is a process per core): each
    batch's scores in the order sent, though with 2 workers the short failing episodes come back first."""
    from driftlab.cli.calibrate import run_batch_on
    from driftlab.core.config import Theta, config_to_dict
    from driftlab.core.configure import preset_config
    from driftlab.worker.executors import LocalProcessExecutor

    document = config_to_dict(preset_config("commonroad_std"))
    drives, spins = Theta().as_dict(), {**Theta().as_dict(), "dV": 1.0, "k": 0.12}
    batch = [(theta, document, seed) for seed in range(3) for theta in (drives, spins)]
    scores = []
    for workers in (1, 2):
        executor = LocalProcessExecutor(workers)
        try:
            scores.append(run_batch_on(executor)(batch))
        finally:
            executor.shutdown()
    assert scores[0] == scores[1] and len({status for status, *_ in scores[0]}) == 2
