"""Drive your own vehicle model with tsmpc's cascade: a plant class (the Plant protocol: reset,
step, applied_input, friction_force) run through ``simulate`` on the built-in circuit.

    python examples/own_plant.py            # the whole circuit (≈ 140 s simulated)
    TSMPC_EXAMPLE_STEPS=100 python examples/own_plant.py   # the first 10 s
"""

import math
import os

import numpy as np

from tsmpc.config import Config
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.metrics import compute_metrics
from tsmpc.sim.simulator import simulate


class DynamicBicycle:
    """Your vehicle: a single-track model with linear tyres and rolling resistance, explicit
    Euler at 1 ms (state [X, Y, θ, v, β, ω], input [F_xR, δ]; the paper car's numbers)."""

    def __init__(self, m=683.0, Iz=560.94, lf=0.758, lr=1.036, Cf=25e3, Cr=25e3, h=1e-3) -> None:
        self.m, self.Iz, self.lf, self.lr, self.Cf, self.Cr, self.h = m, Iz, lf, lr, Cf, Cr, h
        self.x, self.u, self.mu = np.zeros(6), np.zeros(2), 0.5

    def reset(self, x0):
        self.x, self.u = np.array(x0, dtype=float), np.zeros(2)

    def step(self, u, dt, mu_road):
        self.u, self.mu = np.array(u, dtype=float), mu_road
        (X, Y, th, v, b, om), (F, d), h, m = self.x, self.u, self.h, self.m
        for _ in range(round(dt / h)):
            vs = max(v, 0.5)
            fyf, fyr = self.Cf * (d - b - self.lf * om / vs), self.Cr * (self.lr * om / vs - b)
            res = mu_road * m * 9.81 * math.tanh(v / 0.05)
            dv = (F * math.cos(b) - fyf * math.sin(d - b) + fyr * math.sin(b) - res) / m
            db = (-F * math.sin(b) + fyf * math.cos(d - b) + fyr * math.cos(b)) / (m * vs) - om
            dom = (self.lf * fyf * math.cos(d) - self.lr * fyr) / self.Iz
            X, Y, th = X + h * v * math.cos(th + b), Y + h * v * math.sin(th + b), th + h * om
            v, b, om = v + h * dv, b + h * db, om + h * dom
        self.x = np.array([X, Y, th, v, b, om])
        return self.x.copy()

    applied_input = property(lambda self: self.u.copy())  # no actuator dynamics
    friction_force = property(lambda self: (self.mu - 0.5) * self.m * 9.81)  # beyond μ_o M g


if __name__ == "__main__":
    cfg = Config()
    steps = int(os.environ.get("TSMPC_EXAMPLE_STEPS", "0")) or None
    log = simulate(cfg, "ref", load_scenario(cfg), plant=DynamicBicycle(), max_steps=steps)
    m = compute_metrics(log)
    print(f"{log.termination}: {m['simulated_s']:.1f} s simulated, RMSE "
          + ", ".join(f"{k} {v:.3f}" for k, v in m["rmse"].items())
          + f", max |e_y| {m['max_abs_lateral_m']:.3f} m")
