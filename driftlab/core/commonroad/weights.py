"""The default controller's weights for CommonRoad's cars (the default plant's, MpcConfig's defaults, complete none
of their episodes: the flick into the opposite drift spins out or grips up). Found by
``benchmarks/tune_weights.py --plant commonroad_std`` / ``--plant commonroad_mb`` (each function says how)."""

from __future__ import annotations

from driftlab.core.mpc import MpcConfig


def std_weights() -> MpcConfig:
    """STD, vehicle 2, its fitted model: three rounds of random search, 300 sets x 4 theta x 4 seeds (best 7 of 16);
    200 around the best x 4 theta x 8 seeds (14 of 32); 200 around that one x 3 theta near the untuned one
    (``--thetas '[{}, {"k": 0.03}, {"k": 0.015, "dV": -0.1}]'``) x 8 seeds: 23 of 24, against 13 of 24 for its
    centre. Less weight on the steering's deviation, more on the yaw rate and the drive force."""
    return MpcConfig(q_sideslip=412.9075, q_yaw_rate=39.8934, q_steer=0.8418, q_drive_kn=1.2849, r_steer_step=8.3507,
                     r_drive_step_kn=0.0009, steer_rate_radps=11.5374, q_speed=0.9787, q_lateral_error=0.8447,
                     q_course_error=0.1509)


def mb_weights() -> MpcConfig:
    """MB, vehicle 2, locked differential, its fitted model with the rear friction circle: 120 sets within x1/3..x3
    of the weights found for the paper's coupling, each with the untuned theta, the best theta of a 150-iteration job
    and {"dV": -0.3, "k": 0.02} x 4 seeds: 5 of 12 (those weights: at most 4).
    ``benchmarks/tune_weights.py --plant commonroad_mb --sets 120 --seeds 4 --spread 3 --around ...``.
    Less weight on sideslip and the path's lateral error, a faster steering rate, slower steering steps.
    Then the speed weight 0.75 -> 2 and the disturbance estimate held 1.5 s after a flick (0.61): with the first
    set, the fresh seeds a tuned theta lost gripped up after the second flick, the car out of it up to 3.7 m/s
    faster than its reference and the MPC cutting the drive that would have slid its rear out. With these, three
    jobs' best thetas complete 19, 18, 18 of episode seeds 0-19 (before 14, 10, 19), and six 150-iteration jobs'
    (job seeds 0-5) 20, 20, 18, 19, 20, 20 of 20 fresh seeds (before 20, 20, 20, 15, 19, 15).
    A second search round (80 sets within x1/2..x2 of the first set, 12 of 16 at best) tracked the path closer and
    was less robust: 19, 20, 19, 18, 14, 18, and 13 of 20 after 500 iterations."""
    return MpcConfig(q_sideslip=107.2345, q_yaw_rate=75.5064, q_steer=0.5356, q_drive_kn=1.2568, r_steer_step=30.2087,
                     r_drive_step_kn=0.0007, steer_rate_radps=13.6521, q_speed=2.0, q_lateral_error=0.3233,
                     q_course_error=0.1319, estimator_hold_s=1.5)

