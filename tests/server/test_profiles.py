"""A calibrated car's profile reaches its new jobs: their stored config carries the profile's weights and the job
records which profile it took; a job that sets its own weights keeps them."""

from driftlab.db import profiles, storage
from tests.server.conftest import in_process_client

WEIGHTS = {"q_sideslip": 123.0, "q_yaw_rate": 45.0, "steer_rate_radps": 9.5}
CAR = {"plant.model": "commonroad_std", "scenario.sideslip_rad": 0.5}


def test_a_new_job_takes_its_cars_newest_profile(tmp_path):
    with in_process_client(tmp_path / "profiles.db") as client:
        with storage.transaction(client.app.state.factory) as session:
            profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=2,
                                 document={"weights": {"q_sideslip": 1.0}})
            newest = profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=2,
                                          document={"weights": WEIGHTS}).id
            profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=3,
                                 document={"weights": {"q_sideslip": 7.0}})
        job = client.post("/api/jobs", json={"iterations": 1, "config": CAR})
        assert job.status_code == 201, job.text
        assert job.json()["profile_id"] == newest
        mpc = job.json()["spec"]["config"]["mpc"]
        assert {k: mpc[k] for k in WEIGHTS} == WEIGHTS
        own = client.post("/api/jobs", json={"iterations": 1, "config": {**CAR,
                                                                          "mpc.q_sideslip": 300.0}}).json()
        assert own["profile_id"] is None and own["spec"]["config"]["mpc"]["q_sideslip"] == 300.0
        default_plant = client.post("/api/jobs", json={"iterations": 1}).json()
        assert default_plant["profile_id"] is None


def test_a_profile_brings_the_controllers_model_it_was_calibrated_with(tmp_path):
    with in_process_client(tmp_path / "coupled.db") as client:
        with storage.transaction(client.app.state.factory) as session:
            profile_id = profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=2, document={
                "weights": WEIGHTS, "plant": {"model_drive_coupling": True}}).id
        job = client.post("/api/jobs", json={"iterations": 1, "config": CAR}).json()
        config = job["spec"]["config"]
        assert job["profile_id"] == profile_id and config["plant"]["model_drive_coupling"] is True
        assert config["vehicle"]["rear_friction_circle"] is True and 0.0 < config["vehicle"]["rear_coupling"] < 1.0
