"""Table: the plant's own drift equilibrium at R = 44 m, beta = -0.4 for each mismatch alone.

Run: python benchmarks/mismatch_equilibria.py
"""

from driftlab.core.equilibrium import drift_equilibrium
from driftlab.core.errors import NoEquilibriumError
from driftlab.core.plant import PlantConfig
from driftlab.core.vehicle import VehicleParams, pack_params

NOMINAL = PlantConfig.nominal()
CASES = [
    ("friction_scale", (0.95, 1.05, 1.10, 1.15)),
    ("tyre_c_scale", (1.1, 1.2)),
    ("tyre_b_scale", (0.85, 1.15)),
    ("mass_scale", (1.1,)),
    ("friction_circle", (True,)),
    ("load_transfer+cg_height_m", (0.1, 0.2, 0.45)),
]


def main() -> None:
    vehicle = VehicleParams()
    model = drift_equilibrium(44.0, -0.4, pack_params(vehicle))
    print("| plant | V m/s | delta rad | Fxr N | dV | ddelta | dFxr |")
    print("|---|---|---|---|---|---|---|")
    print(f"| model | {model.speed_mps:.3f} | {model.steer_rad:.4f} | {model.drive_force_n:.0f} | | | |")
    rows = [(f"{k}={v}", {k: v}) for k, vs in CASES[:-1] for v in vs]
    rows += [(f"load_transfer, cg_height_m={h}", {"load_transfer": True, "cg_height_m": h}) for h in CASES[-1][1]]
    rows += [("default plant", None)]
    for label, change in rows:
        config = PlantConfig() if change is None else PlantConfig(**{**NOMINAL.__dict__, **change})
        try:
            eq = drift_equilibrium(44.0, -0.4, config.packed_params(vehicle))
        except NoEquilibriumError:
            print(f"| {label} | none | | | | | |")
            continue
        print(f"| {label} | {eq.speed_mps:.3f} | {eq.steer_rad:.4f} | {eq.drive_force_n:.0f} | "
              f"{eq.speed_mps - model.speed_mps:+.3f} | {eq.steer_rad - model.steer_rad:+.4f} | "
              f"{eq.drive_force_n - model.drive_force_n:+.0f} |")


if __name__ == "__main__":
    main()
