"""CommonRoad's vehicle models (TUM, package ``commonroad-vehicle-models``, import ``vehiclemodels``) as plants.

- :mod:`.parameters`: the package's parameter sets, read once and packed for compiled code.
- :mod:`.std`: the single-track drift model (STD: wheel speeds as states, PAC2002 tyres), a compiled port of
  ``vehiclemodels.vehicle_dynamics_std`` tested equal to the package on random states.
- :mod:`.plant`: STD as one of the episode loop's plants (steering servo, drive mapping, RK4).
- :mod:`.equilibrium`: the plant's own steady drifts at a radius and sideslip (its drift family).
"""
