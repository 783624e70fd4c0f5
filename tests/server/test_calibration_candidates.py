"""A calibration's candidate models searched side by side (driftlab.core.calibration_run), on a real SQLite file with
scripted episodes: their batches overlap, and the profile is the one the searches find one batch at a time."""

import math
import threading
import time

from driftlab.core.calibration_request import CalibrationRequest
from driftlab.db import storage
from driftlab.services.calibration import run_calibration

# The BMW at its scenario's drift: both rear models and both steering limits (0.6 rad, the car's reach) fit there.
REQUEST = CalibrationRequest(plant="commonroad_std", points="0.5@44", iterations=5, seeds=2)




class ScriptedBatches:
    """Episodes whose J depends on the weights, the candidate model and the seed; each batch takes 20 ms, and the
    most batches in flight at once is counted. ``one_at_a_time`` runs the batches one after another."""

    def __init__(self, one_at_a_time: bool) -> None:
        self.lock, self.serial = threading.Lock(), threading.Lock() if one_at_a_time else None
        self.in_flight = self.most = 0

    def __call__(self, batch):
        if self.serial is not None:
            with self.serial:
                return self._run(batch)
        return self._run(batch)

    def _run(self, batch):
        with self.lock:
            self.in_flight += 1
            self.most = max(self.most, self.in_flight)
        time.sleep(0.02)
        with self.lock:
            self.in_flight -= 1
        outcomes = []
        for _, document, seed in batch:
            mpc, plant = document["mpc"], document["plant"]
            j = (0.01 * math.log(mpc["q_sideslip"] / 300.0) ** 2 + 0.1 * math.log(mpc["r_steer_step"]) ** 2
                 + 0.2 * plant["model_drive_coupling"] + 0.3 * (mpc["steer_limit_rad"] - 0.6) + 1e-3 * (seed % 7))
            outcomes.append(("completed", j, 1.0, 0.3))
        return outcomes


def _calibrate(database, one_at_a_time: bool):
    """A calibration into an empty database (a profile stored before would be a known weight set of the next)."""
    batches, events = ScriptedBatches(one_at_a_time), []
    factory = storage.open_database(f"sqlite:///{database}")
    try:
        document, = run_calibration(REQUEST, factory, batches, on_event=events.append)
    finally:
        storage.close_database(factory)
    return batches, events, {k: v for k, v in document.items() if k not in ("profile_id", "wall_s")}


def test_the_candidate_models_are_searched_side_by_side_and_find_what_they_find_one_at_a_time(tmp_path):
    side_by_side, events, found = _calibrate(tmp_path / "side_by_side.db", one_at_a_time=False)
    assert len(found["candidates"]) == 4
    # 2 seeds a set: the prune rule's first 2 seeds are all of them, so every set runs every seed.
    assert found["search_episodes"] == 4 * 5 * 2 and found["pruned_sets"] == 0
    assert side_by_side.most >= 2  # a search's batch ran while another's did
    weights = [e["progress"] for e in events if "progress" in e and e["progress"]["step"] == "weights"]
    # One event a weight set, counting every set the searches have tried by then (one may be told before another
    # that finished first reports it).
    tried = [p["tried"] for p in weights]
    assert len(tried) == 4 * 5 and tried == sorted(tried) and tried[-1] == 4 * 5 and {p["of"] for p in weights} == {20}
    assert weights[-1]["best_score"] == min(c["score"] for c in found["candidates"])

    one_at_a_time, _, alone = _calibrate(tmp_path / "one_at_a_time.db", one_at_a_time=True)
    assert one_at_a_time.most == 1
    assert alone == found
