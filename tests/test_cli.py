"""The `driftlab` command line, run as a real process."""

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI

EPISODE_KEYS = {"status", "J", "theta", "seed", "completed_fraction", "mean_abs_e_m", "max_abs_e_m",
                "mean_abs_beta_err_rad", "beta_flip_s", "min_speed_mps", "trigger_times_s", "wall_ms"}


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


def test_the_window_of_a_car_that_cannot_drift_at_the_presets_sideslip_is_printed(capsys):
    # The VW Vanagon countersteers only from ~0.57 rad on a 44 m circle: its model cannot be fitted at the preset's
    # 0.5 rad, which a job is refused for, naming the window; the window itself is still printed.
    from driftlab.cli import main

    assert main(["equilibrium", "--plant", "commonroad_std", "--set", "plant.commonroad_vehicle=3", "--window",
                 "--radius", "44"]) == 0
    (window,) = json.loads(capsys.readouterr().out)["window"]
    (low, high), = window["sideslip_ranges_rad"]
    assert window["radius_m"] == 44.0 and 0.5 < low <= 0.6 < 0.62 < high
    # A sideslip the user gives is kept, and refused: only the preset's is moved into the window.
    from driftlab.core.configure import overrides_inside_window, preset_config
    from driftlab.core.errors import OutsideDriftWindowError

    with pytest.raises(OutsideDriftWindowError) as given:
        overrides_inside_window(preset_config("commonroad_std"),
                                {"plant.commonroad_vehicle": 3, "scenario.sideslip_rad": 0.5})
    assert given.value.field == "scenario.sideslip_rad" and given.value.window[0] > 0.5
    assert main(["episode", "--plant", "commonroad_std", "--set", "plant.commonroad_vehicle=3"]) == 2
    refused = capsys.readouterr().err
    low_rad, high_rad = given.value.window
    assert "sideslip 0.5 rad" in refused
    assert f"needs a scenario.sideslip_rad in {low_rad:.2f}-{high_rad:.2f} rad" in refused
    moved = overrides_inside_window(preset_config("commonroad_std"), {"plant.commonroad_vehicle": 3})
    assert moved.scenario.sideslip_rad == round(sum(given.value.window) / 2, 2)


def test_a_plant_without_a_drift_is_refused_before_any_episode(tmp_path):
    episode = _run("episode", "--set", "plant.friction_scale=1.2")
    db = tmp_path / "jobs.db"
    tune = _run("tune", "--iterations", "2", "--db", str(db), "--set", "plant.friction_scale=1.2")
    for out in (episode, tune):
        assert out.returncode == 2 and out.stdout == ""
        assert "not drivable" in out.stderr and "plant" in out.stderr and len(out.stderr.strip().splitlines()) == 1


def test_tune_takes_the_plant_preset(tmp_path):
    db = tmp_path / "jobs.db"
    out = _run("tune", "--plant", "nominal", "--iterations", "2", "--seed-points", "2", "--robust-samples", "1",
               "--confirm-samples", "0", "--workers", "1", "--db", str(db), "--name", "nominal-job")
    assert out.returncode == 0, out.stderr
    from driftlab.core.plant import PlantConfig
    from driftlab.core.tuning import TuningSpec
    from driftlab.db import storage

    factory = storage.open_database(f"sqlite:///{db}")
    with storage.transaction(factory) as session:
        spec = TuningSpec.from_dict(storage.get_job_by_name(session, name="nominal-job").spec)
    assert spec.config.plant == PlantConfig.nominal()


def test_episode_json_has_the_documented_keys(tmp_path):
    csv_file = tmp_path / "traj.csv"
    out = _run("episode", "--plant", "nominal", "--theta", "c_lr=0.02,c_rl=0.02,dV=0,k=0.05",
               "--csv", str(csv_file))
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert EPISODE_KEYS <= set(data)
    assert data["status"] == "completed"
    lines = ["(the CSV holds no metadata line)", *csv_file.read_text().splitlines()]
    meta = json.loads((tmp_path / "traj.json").read_text())["metadata"]  # beside it: FILE.csv -> FILE.json
    assert meta["J"] == data["J"] and meta["seed"] == 0 and meta["theta"] == data["theta"]
    assert meta["config"]["plant"]["friction_spread"] == 0.0  # the nominal plant, as run
    assert lines[1].startswith("t_s,x_m,y_m") and len(lines) > 500
    phase = lines[1].split(",").index("phase")
    assert all(row.split(",")[phase] in {"0", "1", "2", "3", "4", "5"} for row in lines[2:])
    assert lines[1].endswith(",lap") and {row.rsplit(",", 1)[1] for row in lines[2:]} == {"1"}


def test_a_two_lap_episode_numbers_its_laps_in_the_csv(tmp_path):
    csv_file = tmp_path / "laps.csv"
    out = _run("episode", "--set", "scenario.laps=2", "--seed", "1", "--csv", str(csv_file))
    assert out.returncode == 0, out.stderr
    data = json.loads(out.stdout)
    assert data["status"] == "completed" and len(data["lap_mean_abs_e_m"]) == 2
    laps = [int(row.rsplit(",", 1)[1]) for row in csv_file.read_text().splitlines()[2:]]
    assert laps[0] == 1 and laps[-1] == 2 and laps == sorted(laps)


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


def test_tune_resumes_by_name_and_report_writes_the_tables(tmp_path):
    db = str(tmp_path / "t.db")
    first = _run("tune", "--iterations", "4", "--seed-points", "3", "--db", db, "--name", "smoke")
    assert first.returncode == 0, first.stderr
    out = json.loads(first.stdout)
    assert out["status"] == "finished" and out["n_done"] == 4
    again = _run("tune", "--iterations", "4", "--db", db, "--name", "smoke")
    assert "resuming job smoke" in again.stderr and json.loads(again.stdout)["n_done"] == 4
    rep = _run("report", "--name", "smoke", "--db", db, "--out", str(tmp_path / "rep"), "--baselines", "2")
    assert rep.returncode == 0, rep.stderr
    text = (tmp_path / "rep" / "report.md").read_text()
    assert "paper Table I" in text and "best of 2 random" in text and "untuned" in text
    # the phase table gives the numbers stored with the best evaluation (its kept episode, not re-run)
    from driftlab.db import storage
    from driftlab.reports.job import phase_table

    with storage.snapshot(storage.open_database(f"sqlite:///{db}")) as session:
        best = storage.best_evaluation(session, job_id=storage.get_job_by_name(session, name="smoke").id)
        stored = best.metrics["phases"]
    assert len(stored) >= 1 and all(line in text for line in phase_table(stored))
    assert (tmp_path / "rep" / "convergence.png").stat().st_size > 0
    assert (tmp_path / "rep" / "best_episode.png").stat().st_size > 0


def test_tune_rejects_a_bad_bound_naming_it(tmp_path):
    r = _run("tune", "--iterations", "2", "--db", str(tmp_path / "t.db"), "--bound", "k=0.2:0.1")
    assert r.returncode == 2 and "bounds.k" in r.stderr


def _theta_arg(theta):
    return ",".join(f"{k}={v!r}" for k, v in theta.items())


def test_stored_best_is_reproduced_by_episode_with_its_seed(tmp_path):
    db = str(tmp_path / "t.db")
    tuned = _run("tune", "--iterations", "5", "--seed-points", "3", "--robust-samples", "1", "--confirm-samples", "0",
                 "--seed", "4",
                 "--db", db, "--name", "repro", "--workers", "2")
    assert tuned.returncode == 0, tuned.stderr
    best = json.loads(tuned.stdout)["best"]
    [sample] = best["seeds"]
    assert sample["seed"] == 4 * 64 and sample["J"] == best["J"]
    again = _run("episode", "--theta", _theta_arg(best["theta"]), "--seed", str(sample["seed"]))
    assert again.returncode == 0, again.stderr
    episode = json.loads(again.stdout)
    assert episode["J"] == best["J"] and episode["status"] == best["status"]


def test_robust_evaluation_stores_each_seed_and_rescore_uses_fresh_ones(tmp_path):
    db = str(tmp_path / "t.db")
    tuned = _run("tune", "--iterations", "3", "--seed-points", "3", "--robust-samples", "2", "--db", db,
                 "--name", "robust", "--workers", "2")
    assert tuned.returncode == 0, tuned.stderr
    best = json.loads(tuned.stdout)["best"]
    # Two seeds per evaluation, and a best so far is confirmed on the default 4 more.
    assert [s["seed"] for s in best["seeds"]] == [0, 1, 2, 3, 4, 5]
    assert best["J"] == pytest.approx(sum(s["J"] for s in best["seeds"]) / 6, abs=1e-12)
    # An evaluation's episode and a confirmation's, each re-run in a fresh process (the others are run alike).
    for sample in (best["seeds"][0], best["seeds"][-1]):
        episode = json.loads(_run("episode", "--theta", _theta_arg(best["theta"]), "--seed",
                                  str(sample["seed"])).stdout)
        assert episode["J"] == sample["J"]
    rescored = _run("rescore", "--name", "robust", "--db", db, "--samples", "3")
    assert rescored.returncode == 0, rescored.stderr
    out = json.loads(rescored.stdout)
    assert {"theta", "samples", "completed", "completion_rate", "J_mean", "J_std", "J_worst", "J_stored",
            "by_phase"} <= set(out)
    assert out["by_phase"]["drift"]["episodes"] == out["completed"]
    assert out["theta"] == best["theta"] and out["J_stored"] == best["J"] and out["samples"] == 3
    assert min(out["seeds"]) >= 2**40


def test_rescore_of_an_unknown_job_is_one_line_exit_2(tmp_path):
    from driftlab.db import storage

    storage.close_database(storage.open_database(f"sqlite:///{tmp_path / 't.db'}"))
    out = _run("rescore", "--name", "nope", "--db", str(tmp_path / "t.db"))
    assert out.returncode == 2 and "nope" in out.stderr and len(out.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("command", [["rescore", "--name", "x"], ["report", "--name", "x", "--out", "r"],
                                     ["study", "show", "--name", "x"]])
def test_a_reading_command_refuses_a_database_file_that_does_not_exist_and_creates_none(tmp_path, command):
    typo = tmp_path / "typo.db"
    out = _run(*command, "--db", str(typo))
    assert out.returncode == 2 and len(out.stderr.strip().splitlines()) == 1
    assert f"--db {typo}: no such database file" in out.stderr and not typo.exists()


@pytest.mark.parametrize(("preset", "extra", "expected"), [
    ("default", [], {"iterations": 500, "seed_points": 12, "active_set": 400}),
    ("paper", [], {"iterations": 500, "seed_points": 20, "active_set": 400}),
    ("paper", ["--seed-points", "7", "--iterations", "30"], {"iterations": 30, "seed_points": 7, "active_set": 400}),
])
def test_tune_presets_set_the_bo_budget_and_explicit_options_win(preset, extra, expected):
    from driftlab.cli import build_parser
    from driftlab.cli.tune import tuning_spec

    args = build_parser().parse_args(["tune", "--preset", preset, *extra])
    spec = tuning_spec(args).to_dict()
    assert {k: spec[k] for k in expected} == expected


def test_tune_enqueue_hands_a_theta_to_the_job_a_server_runs(tmp_path):
    """`driftlab tune --name N --enqueue ...` while a server runs job N: the CLI runs nothing, the server evaluates
    the theta next (stored marked as enqueued)."""
    import time

    import httpx

    from tests.server_process import free_port, start_server

    db = tmp_path / "served.db"
    proc, url = start_server(db, free_port(), extra_args=("--workers", "1"))
    try:
        job = httpx.post(f"{url}/api/jobs", json={"name": "served", "iterations": 5000, "seed_points": 12,
                                                  "robust_samples": 1, "confirm_samples": 0}).json()
        deadline = time.time() + 180
        while httpx.get(f"{url}/api/jobs/{job['id']}").json()["n_done"] < 1 and time.time() < deadline:
            time.sleep(0.3)
        out = _run("tune", "--name", "served", "--db", str(db), "--enqueue", "k=0.071,dV=0.05")
        assert out.returncode == 0, out.stderr
        assert "enqueued to job served" in out.stderr and "evaluated next" in out.stderr
        picked = []
        while not picked and time.time() < deadline:
            evaluations = httpx.get(f"{url}/api/jobs/{job['id']}/evaluations").json()
            picked = [e for e in evaluations if e["theta"]["k"] == 0.071]
            time.sleep(0.3)
        assert picked and picked[0]["enqueued"] is True and picked[0]["theta"]["dV"] == 0.05
        assert httpx.get(f"{url}/api/jobs/{job['id']}").json()["status"] == "running"  # still the server's
    finally:
        proc.terminate()
        proc.wait(timeout=30)


@pytest.mark.parametrize("argv", [["tune", "--iterations", "abc"], ["tune", "--robust-samples", "99"],
                                  ["episode", "--seed", "x"], ["serve", "--port", "0"], ["--help"]])
def test_a_bad_argument_is_refused_before_the_simulation_is_imported(argv):
    """One line (or the help) from the parser alone: neither numba, the solvers nor SQLAlchemy are imported first
    (they take seconds on a loaded machine)."""
    code = ("import sys\nfrom driftlab.cli import main\ntry:\n    main(sys.argv[1:])\nexcept SystemExit:\n    pass\n"
            "heavy = [m for m in ('numba', 'scipy', 'sqlalchemy', 'osqp', 'driftlab.core.configure')\n"
            "         if m in sys.modules]\n"
            "print('HEAVY', heavy)")
    out = subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True, timeout=60)
    assert "HEAVY []" in out.stdout, out.stdout + out.stderr
    if argv != ["--help"]:
        assert len(out.stderr.strip().splitlines()) == 1 and "driftlab: error:" in out.stderr
