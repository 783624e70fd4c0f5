"""Plant cost per simulated second and RK4 error against a 0.5 ms reference; for CommonRoad's MB, its substep:
the fastest mode's eigenvalue along an episode and below its speed, one control step's error against a 0.1 ms
reference, and the cost of its 30 s of plant steps, per substep.

Run: OMP_NUM_THREADS=1 python benchmarks/bench_plant.py
"""

import statistics
import time

import numpy as np

from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.plant import SPEED, STEER, YAW_RATE, Plant, PlantConfig
from driftlab.core.vehicle import VehicleParams, pack_params


def episode_of_plant_steps(plant: Plant, start: np.ndarray, n_steps: int = 600) -> np.ndarray:
    s = start
    for k in range(n_steps):
        s = plant.step(s, start[STEER] + 0.05 * np.sin(k / 10.0), start[STEER + 1], 0.05)
    return s


def main() -> None:
    vehicle = VehicleParams()
    eq = drift_equilibrium(44.0, -0.4, pack_params(vehicle))
    start = np.zeros(8)
    start[SPEED:YAW_RATE + 1] = eq.state
    start[STEER], start[STEER + 1] = eq.inputs
    for name, config in (("default", PlantConfig()), ("nominal", PlantConfig.nominal())):
        plant = Plant(config, vehicle)
        episode_of_plant_steps(plant, start, 5)  # load the compiled code
        times = []
        for _ in range(7):
            t0 = time.process_time()
            episode_of_plant_steps(plant, start)
            times.append(time.process_time() - t0)
        med = statistics.median(times)
        print(f"plant={name:8s} substep={config.substep_s * 1e3:.1f} ms  30 s episode: {med * 1e3:.2f} ms CPU "
              f"(median of 7), {med / 30.0 * 1e3:.3f} ms per simulated second")
    coarse = episode_of_plant_steps(Plant(PlantConfig(), vehicle), start, 100)
    fine = episode_of_plant_steps(Plant(PlantConfig(substep_s=0.0005), vehicle), start, 100)
    err = np.max(np.abs(coarse[SPEED:YAW_RATE + 1] - fine[SPEED:YAW_RATE + 1]))
    print(f"default plant, 5 s with steering input: max |[V, beta, r]| error of 5 ms RK4 vs 0.5 ms: {err:.2e}")
    mb_substeps()


def mb_steps_of_an_episode() -> list[tuple]:
    """(state, steer, drive, dt, params, actuators) of each MB plant step of the preset's untuned episode."""
    from driftlab.core.commonroad import mb_plant as crp
    from driftlab.core.config import Theta
    from driftlab.core.configure import preset_config
    from driftlab.core.episode import run_episode

    steps, step = [], crp.CommonRoadMbPlant.step

    def recording(self, state, steer, drive, dt):
        steps.append((state.copy(), steer, drive, dt, self.params, self.actuators))
        return step(self, state, steer, drive, dt)

    run_loop = crp.CommonRoadMbPlant.run_loop
    crp.CommonRoadMbPlant.step, crp.CommonRoadMbPlant.run_loop = recording, None  # every step through Python
    try:
        run_episode(Theta(), preset_config("commonroad_mb"))
    finally:
        crp.CommonRoadMbPlant.step, crp.CommonRoadMbPlant.run_loop = step, run_loop
    return steps


def fastest_mode_per_s(z: np.ndarray, steer: float, drive: float, p: np.ndarray, act: np.ndarray) -> float:
    """The largest |eigenvalue| of MB's Jacobian (actuator included) at ``z``, by forward differences."""
    from driftlab.core.commonroad.mb_plant import _mb_integrated_derivatives

    u, f0, f = np.empty(2), np.empty(len(z)), np.empty(len(z))
    _mb_integrated_derivatives(z, steer, drive, p, act, u, f0)
    jac = np.empty((len(z), len(z)))
    for i in range(len(z)):
        moved = z.copy()
        moved[i] += 1e-6 * max(1.0, abs(z[i]))
        _mb_integrated_derivatives(moved, steer, drive, p, act, u, f)
        jac[:, i] = (f - f0) / (moved[i] - z[i])
    return float(np.max(np.abs(np.linalg.eigvals(jac))))


def mb_substeps() -> None:
    from driftlab.core.commonroad.mb_plant import MB_FIRST, mb_plant_step

    steps = mb_steps_of_an_episode()
    modes = [fastest_mode_per_s(s[MB_FIRST:], steer, drive, p, act) for s, steer, drive, _, p, act in steps[::10]]
    s, steer, drive, _, p, act = steps[len(steps) // 2]
    slow = s[MB_FIRST:].copy()
    slow[[3, 5, 10, 15, 20, 23, 24, 25, 26]] *= 9.0 / np.hypot(slow[3], slow[10])  # the same drift at 9 m/s
    print(f"MB fastest mode along the untuned episode: median {np.median(modes):.0f} 1/s, max {max(modes):.0f} 1/s;"
          f" the same drift at 9 m/s: {fastest_mode_per_s(slow, steer, drive, p, act):.0f} 1/s")
    for substep_s in (0.001, 0.002, 0.003, 0.004):
        errors = []
        for s, steer, drive, dt, p, act in steps[::5]:
            fine = mb_plant_step(s, steer, drive, dt, 1e-4, p, act)
            coarse = mb_plant_step(s, steer, drive, dt, substep_s, p, act)
            errors.append([np.hypot(*(coarse[:2] - fine[:2])), abs(coarse[4] - fine[4]), abs(coarse[5] - fine[5])])
        walls = []
        for _ in range(5):
            t0 = time.process_time()
            for s, steer, drive, dt, p, act in steps:
                mb_plant_step(s, steer, drive, dt, substep_s, p, act)
            walls.append(time.process_time() - t0)
        worst = np.max(errors, axis=0)
        print(f"MB substep {substep_s * 1e3:.0f} ms: one control step vs 0.1 ms, max over the episode: position "
              f"{worst[0]:.1e} m, sideslip {worst[1]:.1e} rad, yaw rate {worst[2]:.1e} rad/s; {len(steps)} steps "
              f"{statistics.median(walls) * 1e3:.0f} ms CPU (median of 5)")
    mb_closed_loop()


def mb_closed_loop(seeds: range = range(1000, 1020)) -> None:
    """Episodes of bench_episode.py's tuned MB theta on 20 seeds at 1 ms and at the preset's substep."""
    from dataclasses import replace

    from bench_episode import CASES

    from driftlab.core.configure import preset_config
    from driftlab.core.episode import run_episode

    preset = preset_config("commonroad_mb")
    for substep_s in sorted({0.001, preset.plant.substep_s}):
        config = replace(preset, plant=replace(preset.plant, substep_s=substep_s))
        results = [run_episode(CASES["commonroad_mb", "default"], config, seed=seed) for seed in seeds]
        done = [r for r in results if r.status == "completed"]
        errors = [r.metrics.mean_abs_e_m for r in done]
        print(f"MB closed loop, substep {substep_s * 1e3:.0f} ms: {len(done)}/{len(results)} completed, mean |e| "
              f"{np.mean(errors) if errors else float('nan'):.3f} m, J median "
              f"{statistics.median(r.J for r in results):.4f}, episode wall median "
              f"{statistics.median(r.wall_ms for r in results):.0f} ms")


if __name__ == "__main__":
    main()
