"""A calibrated car's profile reaches its new jobs: their stored config carries the profile's weights and the job
records which profile it took; a job that sets its own weights keeps them."""

from driftlab.core.tuning import TuningSpec
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
        model = TuningSpec.from_dict(job["spec"]).fitted().config.vehicle  # as the runner fits it, claiming the job
        assert model.rear_friction_circle is True and 0.0 < model.rear_coupling < 1.0


def test_a_profile_brings_the_steering_limit_its_weights_were_found_with(tmp_path):
    from driftlab.core.car_profile import profile_for
    from driftlab.services.profiles import shipped_profiles

    beyond = {**CAR, "scenario.sideslip_rad": 0.7, "scenario.left_radius_m": 30.0, "scenario.right_radius_m": 30.0}
    assert profile_for(shipped_profiles("commonroad_std", 2), 0.7, 30.0) is None  # a step from every shipped point
    with in_process_client(tmp_path / "limited.db") as client:
        job = client.post("/api/jobs", json={"iterations": 1, "config": beyond}).json()
        assert job["profile_id"] is None and job["spec"]["config"]["mpc"]["steer_limit_rad"] == 0.6  # the default
        with storage.transaction(client.app.state.factory) as session:
            profile_id = profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=2, document={
                "weights": WEIGHTS, "mpc": {**WEIGHTS, "steer_limit_rad": 1.066, "horizon": 7}}).id
        job = client.post("/api/jobs", json={"iterations": 1, "config": beyond}).json()
        mpc = job["spec"]["config"]["mpc"]
        assert job["profile_id"] == profile_id and mpc["steer_limit_rad"] == 1.066
        assert mpc["horizon"] == 20  # its weights and limits, not the rest of the controller it was stored with


def test_a_calibration_knows_each_calibrated_cars_newest_weights_then_the_shipped_ones(tmp_path):
    from dataclasses import replace

    from driftlab.core.mpc_config import MpcConfig
    from driftlab.core.plants import plant_type
    from driftlab.services.profiles import known_weight_sets

    factory = storage.open_database(f"sqlite:///{tmp_path / 'known.db'}")
    try:
        with storage.transaction(factory) as session:
            profiles.add_profile(session, plant_model="heavy", vehicle_id=2, document={"weights": {"q_speed": 1.0}})
            heavy = profiles.add_profile(session, plant_model="heavy", vehicle_id=2,
                                         document={"weights": {"q_speed": 2.0}}).id
            vanagon = profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=3,
                                           document={"weights": {"q_speed": 3.0}}).id
        std = plant_type("commonroad_std").controller()
        with storage.transaction(factory) as session:
            known = known_weight_sets(session, std)
    finally:
        storage.close_database(factory)
    labels = [label for label, _ in known]
    assert labels[:2] == [f"profile {vanagon} (commonroad_std, vehicle 3)", f"profile {heavy} (heavy, vehicle 2)"]
    assert [mpc.q_speed for _, mpc in known[:2]] == [3.0, 2.0]  # the older profile of the heavy car is not there
    assert known[0][1] == replace(std, q_speed=3.0)  # a profile's weights on the car's own set
    shipped = [mpc for label, mpc in known if "shipped" in label]
    assert MpcConfig() in shipped and plant_type("commonroad_mb").controller() in shipped
    assert std not in [mpc for _, mpc in known]  # the car's own set is its start, not a known one


def _record(sideslip_rad, radius_m, completed, mean_abs_e_m):
    return {"sideslip_rad": sideslip_rad, "radius_m": radius_m, "completed": completed, "episodes": 4,
            "mean_abs_e_m": mean_abs_e_m}


def test_a_job_takes_the_profile_that_drove_its_own_drift_best(tmp_path):
    window = [_record(0.45, 44.0, 0, None), _record(0.5, 44.0, 4, 0.2), _record(0.55, 44.0, 4, 1.3),
              _record(0.5, 32.0, 4, 0.2), _record(0.5, 52.0, 4, 0.3)]
    with in_process_client(tmp_path / "points.db") as client:
        with storage.transaction(client.app.state.factory) as session:
            whole = profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=2, document={
                "weights": {"q_sideslip": 100.0}, "per_point": window}).id
            at_045 = profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=2, document={
                "weights": {"q_sideslip": 200.0}, "per_point": [_record(0.45, 44.0, 4, 0.3)]}).id
            worse_at_055 = profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=2, document={
                "weights": {"q_sideslip": 300.0}, "per_point": [_record(0.55, 44.0, 3, 0.4)]}).id
            profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=2, document={
                "weights": {"q_sideslip": 400.0}, "per_point": [_record(0.5, 30.0, 0, None)]})

        def taken(sideslip_rad, radius_m=44.0):
            config = {**CAR, "scenario.sideslip_rad": sideslip_rad, "scenario.left_radius_m": radius_m,
                      "scenario.right_radius_m": radius_m}
            job = client.post("/api/jobs", json={"iterations": 1, "config": config})
            assert job.status_code == 201, job.text
            return job.json()["profile_id"], job.json()["spec"]["config"]["mpc"]["q_sideslip"]

        assert taken(0.45) == (at_045, 200.0)  # calibrated there, and it completed where the whole set did not
        assert taken(0.5) == (whole, 100.0)
        assert taken(0.55) == (whole, 100.0)  # 4 of 4 beat 3 of 4 at the same point, whatever the newer's error
        assert taken(0.46) == (at_045, 200.0)  # the nearest calibrated point decides
        assert taken(0.5, 31.0) == (whole, 100.0)  # calibrated at 30 m, but nothing completed with those weights
    assert worse_at_055 > whole


def test_weights_are_taken_no_further_than_a_step_from_where_they_were_calibrated():
    from types import SimpleNamespace

    from driftlab.core.car_profile import profile_for

    at_05 = SimpleNamespace(id=1, document={"per_point": [_record(0.5, 44.0, 4, 0.2)]})
    old = SimpleNamespace(id=2, document={"weights": {}})  # stored before profiles had their record
    assert profile_for([at_05], 0.54, 44.0) is at_05
    assert profile_for([at_05], 0.55, 44.0) is None  # a whole step away: the car's default weights
    assert profile_for([at_05], 0.5, 44.0 * 1.25) is None
    assert profile_for([at_05, old], 0.55, 44.0) is old


def test_a_fresh_database_takes_the_shipped_profile_for_the_jobs_drift_and_keeps_one_copy(tmp_path):
    from driftlab.core.car_profile import profile_for
    from driftlab.services.profiles import SHIPPED_KEY, shipped_profiles

    shipped = shipped_profiles("commonroad_std", 2)
    assert shipped and all(p.document["command"].startswith("driftlab calibrate --plant commonroad_std")
                           for p in shipped)
    point = max((p.document["per_point"][0] for p in shipped), key=lambda r: (r["completed"], -r["sideslip_rad"]))
    expected = profile_for(shipped, point["sideslip_rad"], point["radius_m"])
    assert expected is not None
    radius = point["radius_m"]
    car = {"plant.model": "commonroad_std", "scenario.sideslip_rad": point["sideslip_rad"],
           "scenario.left_radius_m": radius, "scenario.right_radius_m": radius}
    with in_process_client(tmp_path / "shipped.db") as client:
        first, second = (client.post("/api/jobs", json={"iterations": 1, "config": car}).json() for _ in range(2))
        assert first["profile_id"] is not None and second["profile_id"] == first["profile_id"]
        mpc = first["spec"]["config"]["mpc"]
        assert all(mpc[k] == v for k, v in expected.document["weights"].items())
        factory = client.app.state.factory
        with storage.transaction(factory) as session:
            copied, = profiles.list_profiles(session)
            assert copied.document[SHIPPED_KEY] == expected.key and copied.document["command"]
            own = profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=2, document={
                "weights": WEIGHTS, "per_point": [{**point, "completed": 1, "episodes": 1, "mean_abs_e_m": 0.9}]}).id
        third = client.post("/api/jobs", json={"iterations": 1, "config": car}).json()
        assert third["profile_id"] == own  # this database's own calibration wins over what ships


def test_a_profile_found_for_a_learned_theta_has_its_jobs_ask_that_theta_first(tmp_path):
    """A later calibration round searches the weights for the theta a job learned (k on its bound at the BMW's
    0.55 rad): a job that takes them asks that theta first, moved into its box; an untuned one adds nothing."""
    learned = {"c_lr": 0.023, "c_rl": 0.024, "dV": -0.17, "k": -0.3, "model_mu_scale": 1.04, "model_c_scale": 1.03}
    with in_process_client(tmp_path / "theta.db") as client:
        with storage.transaction(client.app.state.factory) as session:
            untuned = profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=2,
                                           document={"weights": WEIGHTS, "theta": "untuned"}).id
        first = client.post("/api/jobs", json={"iterations": 1, "config": CAR}).json()
        assert first["profile_id"] == untuned and "warm_start" not in first["spec"]
        with storage.transaction(client.app.state.factory) as session:
            found = profiles.add_profile(session, plant_model="commonroad_std", vehicle_id=2,
                                         document={"weights": WEIGHTS, "theta": learned}).id
        job = client.post("/api/jobs", json={"iterations": 1, "config": CAR}).json()
        start = job["spec"]["warm_start"]
        k_low = job["spec"]["bounds"]["k"][0]
        assert job["profile_id"] == found and start["from_profile"] == found and start["from_jobs"] == []
        assert start["initial_points"] == [{**learned, "k": k_low}]  # k -0.3 onto the box's face
        warm = client.post("/api/jobs", json={"iterations": 1, "config": CAR, "warm_start_from": [first["id"]]})
        assert warm.json()["spec"]["warm_start"]["from_profile"] == found  # both starts kept


def test_weights_that_completed_every_episode_of_their_point_beat_nearer_ones_that_did_not():
    from types import SimpleNamespace

    from driftlab.core.car_profile import profile_for

    own = SimpleNamespace(id=3, document={"per_point": [_record(0.69, 44.0, 1, 0.9)]})
    beside = SimpleNamespace(id=1, document={"per_point": [_record(0.69, 52.0, 4, 0.3)]})  # 0.91 steps away
    further = SimpleNamespace(id=2, document={"per_point": [_record(0.64, 44.0, 4, 0.2)]})  # a whole step away
    assert profile_for([own, beside, further], 0.69, 44.0) is beside
    assert profile_for([own, further], 0.69, 44.0) is own  # the only one within a step
    full_own = SimpleNamespace(id=4, document={"per_point": [_record(0.69, 44.0, 4, 0.5)]})
    assert profile_for([own, beside, full_own], 0.69, 44.0) is full_own  # then the nearest


def test_a_job_beyond_its_cars_calibrated_drifts_is_told_the_nearest_and_how_to_calibrate_its_own(tmp_path):
    """0.7 rad on 30 m circles lies a step from every shipped BMW point: the job is accepted with the car's default
    weights and a warning naming the nearest calibrated drift (and how it did there); a job at a calibrated drift,
    or one that sets its own weights, is told nothing."""
    from driftlab.core.car_profile import drift_distance
    from driftlab.services.profiles import shipped_profiles

    beyond = {**CAR, "scenario.sideslip_rad": 0.7, "scenario.left_radius_m": 30.0, "scenario.right_radius_m": 30.0}
    with in_process_client(tmp_path / "warned.db") as client:
        job = client.post("/api/jobs", json={"iterations": 1, "config": beyond})
        assert job.status_code == 201, job.text
        warning = job.json()["warning"]
        records = [r for p in shipped_profiles("commonroad_std", 2) for r in p.document["per_point"] if r["completed"]]
        nearest = min(records, key=lambda r: drift_distance(0.7, 30.0, r))
        assert job.json()["profile_id"] is None and warning.startswith("no calibrated weights for 0.7 rad, 30 m")
        assert f"nearest calibrated drift is {nearest['sideslip_rad']:g} rad, {nearest['radius_m']:g} m" in warning
        assert "driftlab calibrate --plant commonroad_std --points 0.7@30" in warning
        assert client.get(f"/api/jobs/{job.json()['id']}").json()["warning"] is None  # said once, where it was made
        assert client.post("/api/jobs", json={"iterations": 1, "config": CAR}).json()["warning"] is None
        own = client.post("/api/jobs", json={"iterations": 1, "config": {**beyond, "mpc.q_sideslip": 300.0}})
        assert own.json()["warning"] is None


def _checked(sideslip_rad, radius_m, completed, seeds=10, search=(3, 3)):
    return {"sideslip_rad": sideslip_rad, "radius_m": radius_m, "completed": search[0], "episodes": search[1],
            "mean_abs_e_m": 0.3, "verified": {"seeds": seeds, "completed": completed, "invalid": 0,
                                              "mean_abs_e_m": 0.3}}


def test_the_calibrated_window_is_where_the_weights_complete_their_fresh_seeds():
    """Per radius, the points whose weights complete at least 9 of 10 fresh seeds (the best of a point's rounds),
    neighbours joined: a point whose search completed 3 of 3 but whose weights complete 8 of 10 fresh seeds is
    outside; a radius with no such point is printed as none."""
    from driftlab.core.car_profile import calibrated_window, window_text

    documents = [{"per_point": [_checked(0.45, 44.0, 10)]}, {"per_point": [_checked(0.5, 44.0, 9)]},
                 {"per_point": [_checked(0.55, 44.0, 8)]}, {"per_point": [_checked(0.6, 44.0, 4)]},
                 {"per_point": [_checked(0.6, 44.0, 10)]},  # a later round at 0.6 rad did it
                 {"per_point": [_checked(0.5, 52.0, 6)]}]
    window = calibrated_window(documents)
    assert window == {44.0: [(0.45, 0.5), (0.6, 0.6)], 52.0: []}
    assert window_text(window).endswith("R 44 m: 0.45-0.5, 0.6 rad; R 52 m: none")
    old = [{"per_point": [{"sideslip_rad": 0.5, "radius_m": 30.0, "completed": 3, "episodes": 3}]}]
    assert calibrated_window(old) == {30.0: [(0.5, 0.5)]}  # stored before the check: its search's episodes


def test_a_job_takes_the_profile_whose_weights_completed_their_fresh_seeds_over_a_luckier_search():
    from driftlab.core.car_profile import profile_for
    from driftlab.services.profiles import ShippedProfile

    lucky = ShippedProfile(1, "a", {"per_point": [_checked(0.5, 44.0, 6, search=(3, 3))]})
    steady = ShippedProfile(2, "b", {"per_point": [_checked(0.5, 44.0, 10, search=(2, 3))]})
    assert profile_for([steady, lucky], 0.5, 44.0) is steady
    nothing = ShippedProfile(3, "c", {"per_point": [_checked(0.5, 44.0, 0, search=(3, 3))]})
    assert profile_for([nothing], 0.5, 44.0) is None


def _around(sideslip_rad, radius_m, completed, seeds=10):
    return {"sideslip_rad": sideslip_rad, "radius_m": radius_m, "seeds": seeds, "completed": completed,
            "invalid": 0, "mean_abs_e_m": 0.3}


def test_weights_are_checked_between_points_and_a_job_there_takes_the_ones_that_held():
    """The VW Vanagon's weights found at 0.64 rad, 44 m complete 10 of 10 there and 4 of 10 at 0.62; those found at
    0.59 complete 10 of 10 at 0.59, 0.62 and 0.64. A job at 0.62 takes the 0.59 profile (its check half a step from
    0.64 is what says so), and the window runs through 0.615 only because some profile held there."""
    from driftlab.core.car_profile import calibrated_window, profile_for
    from driftlab.services.profiles import ShippedProfile

    at_064 = {"per_point": [{**_checked(0.64, 44.0, 10), "verified_around": [_around(0.615, 44.0, 4),
                                                                             _around(0.665, 44.0, 0)]}]}
    at_059 = {"per_point": [{**_checked(0.59, 44.0, 10), "verified_around": [_around(0.565, 44.0, 10),
                                                                             _around(0.615, 44.0, 10)]}]}
    assert profile_for([ShippedProfile(2, "b", at_064), ShippedProfile(1, "a", at_059)], 0.62, 44.0).id == 1
    assert profile_for([ShippedProfile(2, "b", at_064), ShippedProfile(1, "a", at_059)], 0.64, 44.0).id == 2
    assert calibrated_window([at_064, at_059]) == {44.0: [(0.565, 0.64)]}
    assert calibrated_window([at_064]) == {44.0: [(0.64, 0.64)]}  # alone its neighbours fall short: a point


def test_the_shipped_profiles_are_the_data_a_job_reads():
    """A shipped profile is what a job reads (the car, its drift, weights, limits, theta, window) and where it came
    from; each calibration's log stays in the database it ran on, so the files grow with profiles, not with the
    square of them."""
    from importlib import resources

    from driftlab.core.car_profile import PROFILE_KEYS, PROFILE_PLANT
    from driftlab.services.profiles import shipped_profiles

    files = [e for e in resources.files("driftlab.profiles").iterdir() if e.name.endswith(".json")]
    assert sum(len(e.read_bytes()) for e in files) <= 40_000
    for plant_model, vehicle_id in (("commonroad_std", 2), ("commonroad_std", 3), ("commonroad_mb", 2)):
        profiles = shipped_profiles(plant_model, vehicle_id)
        assert profiles and all(set(p.document) <= {*PROFILE_KEYS, "plant", "mpc"} for p in profiles)
        assert all(set(p.document["plant"]) <= set(PROFILE_PLANT) and p.document["weights"] for p in profiles)
        assert all(p.document["command"].startswith("driftlab calibrate") for p in profiles)
