"""Trajectories as stored: byte planes of the columns, and rows stored in the format before them still read."""

import zlib

import numpy as np

from driftlab.core.config import EpisodeConfig
from driftlab.core.episode import run_episode
from driftlab.core.theta import Theta
from driftlab.db import storage
from driftlab.db.models import Trajectory
from driftlab.db.trajectory_bytes import PackedTrajectory, pack, unpack


def _episode_trajectory() -> np.ndarray:
    result = run_episode(Theta(), EpisodeConfig(), seed=3)
    return np.asarray(result.trajectory, dtype=np.float64)


def test_a_trajectory_comes_back_bit_for_bit_and_smaller_than_its_rows_compressed():
    trajectory = _episode_trajectory()
    data = pack(trajectory)
    back = unpack(data, *trajectory.shape)
    assert back.tobytes() == trajectory.tobytes() and back.flags.c_contiguous
    assert len(data) < 0.9 * len(zlib.compress(trajectory.tobytes(), 1))
    special = np.array([[np.nan, np.inf], [-0.0, 5e-324]])
    assert unpack(pack(special), 2, 2).tobytes() == special.tobytes()
    # Packed as the releases before matching runs only packed it (zlib's default matching): reads the same.
    planes = np.ascontiguousarray(trajectory.T).view(np.uint8).reshape(-1, 8).T.tobytes()
    assert unpack(b"\x01" + zlib.compress(planes, 1), *trajectory.shape).tobytes() == trajectory.tobytes()


def test_a_trajectory_stored_as_rows_before_reads_as_it_was(tmp_path):
    trajectory = _episode_trajectory()
    factory = storage.open_database(f"sqlite:///{tmp_path / 'old.db'}")
    with storage.transaction(factory) as session:
        job = storage.create_job(session, name="old", spec={"iterations": 2}, seed=0)
        columns = [f"c{i}" for i in range(trajectory.shape[1])]
        stored = [storage.add_evaluation(session, job_id=job.id, index=i, theta={}, J=-1.0, status="completed",
                                         metrics={}, trigger_points=[], wall_ms=1.0, columns=columns,
                                         trajectory=PackedTrajectory.of(trajectory)) for i in range(2)]
        # The first as an earlier release stored it: zlib of the float64 rows.
        session.get(Trajectory, stored[0].id).data = zlib.compress(trajectory.tobytes(), 1)
    with storage.snapshot(factory) as session:
        for evaluation in stored:
            names, back = storage.trajectory_array(session, evaluation_id=evaluation.id)
            assert names == columns and back.tobytes() == trajectory.tobytes()
    storage.close_database(factory)
