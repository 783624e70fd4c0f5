"""The inertia drift planner switches at the learned arc and not before."""

from driftlab.core.planner import InertiaDriftPlanner, Phase, Triggers


def _drive(planner, fractions, beta_err=0.3):
    phases = []
    for i, c in enumerate(fractions):
        phases.append(planner.update(i * 0.05, 0.0, 0.0, c, beta_err))
    return phases


def test_switches_when_the_arc_to_p0_falls_to_c_lr():
    planner = InertiaDriftPlanner(Triggers(c_lr=0.03, c_rl=0.02))
    phases = _drive(planner, [0.5, 0.2, 0.05, 0.031, 0.029])
    assert phases[:4] == [Phase.LEFT_DRIFT] * 4
    assert phases[4] == Phase.INERTIA_LEFT_TO_RIGHT
    assert planner.trigger_events[0].time_s == 0.2


def test_no_retrigger_before_the_far_half_of_the_new_circle():
    planner = InertiaDriftPlanner(Triggers(c_lr=0.03, c_rl=0.02))
    _drive(planner, [0.5, 0.029])  # now on the right circle, still before P0 (c small)
    phases = _drive(planner, [0.01, 0.005], beta_err=0.01)  # beta settled: sustained right drift
    assert phases[-1] == Phase.RIGHT_DRIFT
    phases = _drive(planner, [0.99, 0.7, 0.4, 0.1, 0.019])
    assert phases[-2] == Phase.RIGHT_DRIFT
    assert phases[-1] == Phase.INERTIA_RIGHT_TO_LEFT


def test_zero_trigger_switches_at_p0():
    planner = InertiaDriftPlanner(Triggers(c_lr=0.0, c_rl=0.0))
    phases = _drive(planner, [0.5, 0.1, 0.004, 0.998])
    assert phases[-1] == Phase.INERTIA_LEFT_TO_RIGHT


def test_finishes_at_the_far_point_of_the_final_left_half():
    planner = InertiaDriftPlanner(Triggers(c_lr=0.03, c_rl=0.03))
    _drive(planner, [0.5, 0.02])
    _drive(planner, [0.01], beta_err=0.0)
    _drive(planner, [0.99, 0.6, 0.02])
    _drive(planner, [0.01], beta_err=0.0)
    phases = _drive(planner, [0.99, 0.8, 0.6, 0.51, 0.49])
    assert phases[-2] == Phase.LEFT_DRIFT_FINAL
    assert phases[-1] == Phase.FINISHED


def test_a_second_lap_drives_a_full_left_lap_before_the_next_flick():
    planner = InertiaDriftPlanner(Triggers(c_lr=0.03, c_rl=0.03), laps=2)
    _drive(planner, [0.5, 0.02])
    _drive(planner, [0.01], beta_err=0.0)
    _drive(planner, [0.99, 0.6, 0.02])
    phases = _drive(planner, [0.99], beta_err=0.0)  # settled in the left circle: the second lap begins
    assert phases[-1] == Phase.LEFT_DRIFT
    phases = _drive(planner, [0.95, 0.6, 0.51, 0.49, 0.2, 0.031])  # past the far point: no finish, no flick yet
    assert set(phases) == {Phase.LEFT_DRIFT}
    assert _drive(planner, [0.029])[-1] == Phase.INERTIA_LEFT_TO_RIGHT
    _drive(planner, [0.01], beta_err=0.0)
    _drive(planner, [0.99, 0.6, 0.02])
    _drive(planner, [0.99], beta_err=0.0)
    phases = _drive(planner, [0.8, 0.6, 0.49])
    assert phases[-2:] == [Phase.LEFT_DRIFT_FINAL, Phase.FINISHED]
    assert len(planner.trigger_events) == 4
