"""Plant cost per simulated second and RK4 error against a 0.5 ms reference.

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


if __name__ == "__main__":
    main()
