"""The cascade in your own loop (the README's "Use your own vehicle"): call it every T_d with
what your sensors measure and apply what it returns. tsmpc's plant stands in for the vehicle."""

from tsmpc.config import Config
from tsmpc.control import Cascade, Measurement
from tsmpc.planning import builtin_circuit
from tsmpc.vehicle import VehiclePlant

cfg = Config()
reference = builtin_circuit(dt=cfg.rates.Tc)
cascade = Cascade(cfg, "ref", reference)  # LMI designs from the cache
car = VehiclePlant(cfg.vehicle, cfg.tyre, cfg.rates.h)  # stands in for your vehicle
car.reset([reference.x[0], reference.y[0], reference.theta[0], reference.v[0], 0.0, 0.0])
for i in range(500):  # 5 s at T_d = 10 ms
    X, Y, theta, v, _, omega = car.state  # your sensors: pose, speed, yaw rate
    cmd = cascade.step(i * cfg.rates.Td, Measurement((X, Y, theta), v, omega))
    car.step([cmd.F_xR, cmd.delta], cfg.rates.Td, mu_road=0.9)  # your actuators
plan, estimate = cascade.last_plan, cascade.last_estimate  # None before the first step
assert plan is not None and estimate is not None
print(cascade.events, plan.status, estimate.x)
