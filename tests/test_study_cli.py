"""`driftlab study` and `driftlab report --study`, run as real processes on a real SQLite file."""

import json
import statistics
import subprocess
import sys

import pytest

from driftlab.core.convergence import best_so_far
from driftlab.core.robust import tuning_seeds
from driftlab.db import storage, studies

pytestmark = pytest.mark.e2e  # real processes: servers, browsers, Dask, the CLI


def _run(*args):
    return subprocess.run([sys.executable, "-m", "driftlab.cli", *args], capture_output=True, text=True, timeout=300)


def test_a_seeds_study_runs_continues_by_name_and_reports_its_band(tmp_path):
    db = str(tmp_path / "s.db")
    args = ("study", "seeds", "--seeds", "3,4", "--iterations", "4", "--seed-points", "4", "--robust-samples", "1",
            "--confirm-samples", "0", "--db", db, "--name", "pair", "--every", "1")
    first = _run(*args)
    assert first.returncode == 0, first.stderr
    out = json.loads(first.stdout)
    assert out["status"] == "finished" and len(out["job_ids"]) == 2
    factory = storage.open_database(f"sqlite:///{db}")
    with storage.transaction(factory) as session:
        jobs = studies.study_jobs(session, study_id=out["id"])
        assert [j.seed for j in jobs] == [3, 4] and [j.spec["seed"] for j in jobs] == [3, 4]
        curves = [best_so_far([e.J for e in storage.evaluations(session, job_id=j.id)],
                              [e.completed for e in storage.evaluations(session, job_id=j.id)]) for j in jobs]
    for k, i in enumerate(out["band"]["iterations"]):
        assert out["band"]["median"][k] == pytest.approx(statistics.median(c[i] for c in curves if c[i] is not None))
    assert sorted(out["final_best_J"]) == sorted(c[-1] for c in curves if c[-1] is not None)
    again = _run(*args)
    assert "resuming study pair" in again.stderr and json.loads(again.stdout)["job_ids"] == out["job_ids"]
    assert "stored settings" in again.stderr  # a re-run says its new arguments are not applied
    other_kind = _run("study", "robustness", "--theta", "c_lr=0.02", "--grid", "plant.mass_scale=1.0", "--db", db,
                      "--name", "pair")
    assert other_kind.returncode == 2 and "seeds study of that name exists" in other_kind.stderr
    shown = _run("study", "show", "--name", "pair", "--db", db, "--every", "1")
    assert json.loads(shown.stdout)["band"] == out["band"]
    report = _run("report", "--study", "pair", "--db", db, "--out", str(tmp_path / "rep"))
    assert report.returncode == 0, report.stderr
    assert (tmp_path / "rep" / "band.png").stat().st_size > 10_000
    assert "Final best J over seeds" in (tmp_path / "rep" / "report.md").read_text()


def test_a_robustness_study_of_a_stored_evaluation_and_its_heatmap(tmp_path):
    db = str(tmp_path / "r.db")
    tuned = _run("tune", "--iterations", "2", "--seed-points", "2", "--robust-samples", "1", "--confirm-samples", "0",
                 "--seed", "2", "--db", db, "--name", "base")
    assert tuned.returncode == 0, tuned.stderr
    factory = storage.open_database(f"sqlite:///{db}")
    with storage.transaction(factory) as session:
        evaluation = storage.evaluations(session, job_id=storage.get_job_by_name(session, name="base").id)[0]
        evaluation_id, stored_j, theta = evaluation.id, evaluation.J, evaluation.theta
    run = _run("study", "robustness", "--evaluation", str(evaluation_id), "--grid", "plant.friction_scale=1.1,0.95",
               "--db", db, "--name", "grid")
    assert run.returncode == 0, run.stderr
    out = json.loads(run.stdout)
    assert out["status"] == "finished" and [c["settings"] for c in out["cells"]] == [
        {"plant.friction_scale": 1.1}, {"plant.friction_scale": 0.95}]
    assert out["cells"][0]["J"] == stored_j  # the job's own plant: the stored evaluation, exactly
    with storage.transaction(factory) as session:
        cell = studies.cells(session, study_id=out["id"])[1]
        assert [s["seed"] for s in cell.seeds] == tuning_seeds(2, 1)
    episode = _run("episode", "--theta", ",".join(f"{k}={v!r}" for k, v in theta.items()), "--seed",
                   str(tuning_seeds(2, 1)[0]), "--set", "plant.friction_scale=0.95")
    assert json.loads(episode.stdout)["J"] == out["cells"][1]["J"]
    report = _run("report", "--study", "grid", "--db", db, "--out", str(tmp_path / "rep"))
    assert report.returncode == 0, report.stderr
    assert (tmp_path / "rep" / "heatmap.png").stat().st_size > 5_000


@pytest.mark.parametrize(("args", "field"), [
    (("study", "seeds", "--seeds", "1,1", "--iterations", "2"), "seeds"),
    (("study", "robustness", "--theta", "k=0.05", "--grid", "plant.nope=1,2"), "plant.nope"),
    (("study", "robustness", "--theta", "k=0.05", "--grid", "plant.mass_scale=1,x"), "plant.mass_scale"),
    (("study", "robustness", "--grid", "plant.mass_scale=1"), "theta"),
    (("study", "show", "--name", "nope"), "nope"),
])
def test_bad_study_arguments_exit_2_naming_the_field(tmp_path, args, field):
    from driftlab.db import storage

    storage.close_database(storage.open_database(f"sqlite:///{tmp_path / 'b.db'}"))  # `show` reads a stored one
    out = _run(*args, "--db", str(tmp_path / "b.db"))
    assert out.returncode == 2, out.stderr
    assert field in out.stderr and len(out.stderr.strip().splitlines()) == 1
