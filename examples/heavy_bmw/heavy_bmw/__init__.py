"""CommonRoad's BMW 320i (vehicle 2) 30% heavier, its centre of gravity 20% higher, its tyres' peak friction 15%
lower, stepped by CommonRoad's STD: ``--set plant.model=heavy_bmw`` once this package is installed."""

from driftlab.core.plants import CommonRoadVariant

HEAVY_BMW = CommonRoadVariant({
    "m": 1.3,                             # mass [kg]
    "h_s": 1.2, "h_cg": 1.2,              # CG height above ground [m] (STD reads h_s)
    "tire.p_dx1": 0.85, "tire.p_dy1": 0.85,  # PAC2002's peak friction, longitudinal and lateral
})
