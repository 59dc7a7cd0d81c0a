"""REF on the built-in circuit driving CommonRoad's single-track model (vehicle 2, a BMW 320i)
behind a 50 ms steering servo, next to tsmpc's own plant with the same parameters (linear tyres,
same servo), default sensor noise. Needs the extra: pip install -e ".[commonroad]".

    python examples/commonroad_plant.py                        # the whole circuit
    TSMPC_EXAMPLE_STEPS=150 python examples/commonroad_plant.py  # the first 15 s

The same from the command line: tsmpc run --plant commonroad-st --cr-vehicle 2
"""

import os
from dataclasses import replace

from tsmpc.config import Config, TyreModel, TyreParams
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.metrics import compute_metrics
from tsmpc.sim.simulator import simulate
from tsmpc.vehicle.actuators import Actuators, SteeringServo
from tsmpc.vehicle.commonroad import CommonRoadPlant, commonroad_config

cfg = commonroad_config(Config(), vehicle_id=2)  # its parameters, force limits per kg
steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None
# the platform measures the applied steering (a CAN signal on real cars): the MHE uses it
scenario = replace(load_scenario(cfg), measured_steering=True)
own = replace(scenario, plant_tyre=TyreParams(model=TyreModel.LINEAR),
              actuators=Actuators(SteeringServo(time_constant_s=0.05, rate_limit=0.4)))
runs = {"CommonRoad ST": simulate(cfg, "ref", scenario, plant=CommonRoadPlant(2), max_steps=steps),
        "tsmpc plant": simulate(cfg, "ref", own, max_steps=steps)}
print("| plant | x | y | θ | v | ω | max abs(e_y) | termination |")
print("|---|---|---|---|---|---|---|---|")
for name, log in runs.items():
    m = compute_metrics(log)
    print(f"| {name} | " + " | ".join(f"{v:.4f}" for v in m["rmse"].values())
          + f" | {m['max_abs_lateral_m']:.3f} | {log.termination} |")
