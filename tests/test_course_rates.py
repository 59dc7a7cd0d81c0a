"""The course fusion at any pose rate (issue 35; tsmpc.estimation.fusion.course_close /
course_sample): with the pose at 1–10 Hz while speed and yaw rate stay at 100 Hz, intervals end at
the measured poses, the heading between them is the gyro's integral, and chords of at least
BASELINE T_c are fitted; with a pose at every call nothing changes (the published numbers)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from _motion import arc_step
from tsmpc.config import Config, replace
from tsmpc.control.ts_lqr import equilibrium
from tsmpc.estimation.fusion import CourseFusion
from tsmpc.sim import engine as eng
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.simulator import simulate

SEGMENTS = [(10.0, 0.0, 4.0), (10.0, 0.15, 6.0), (12.0, -0.2, 6.0), (8.0, 0.3, 6.0), (10.0, 0.0, 4.0)]


def _due(rate_hz: float | None, k: int, Td: float = 0.01) -> bool:
    """The pose sensor's schedule (tsmpc.sensors: the first call at or after each 1 / rate)."""
    if rate_hz is None:
        return True
    r = rate_hz * Td
    return math.floor(k * r + 1e-9) > math.floor((k - 1) * r + 1e-9)


def _drive(f: CourseFusion, segments, *, pose_hz: float | None, kappa: float = 0.0, beta: float = 0.0,
           v_offset: float = 0.0, true_vehicle=None, every_call: bool = True, Td: float = 0.01) -> None:
    """Arcs of constant (v, ω) [segment = (v, ω, seconds)] driven exactly, fed as the cascade
    feeds the fusion: every call :meth:`close` (an MPC step every 10th) then :meth:`sample`, the
    pose only when due at ``pose_hz`` (None: every call); α the true slip (the vehicle's steady
    state, or 0.01 ω), the model's α̂ = α − (κ v ω + β), the speed sensor v + ``v_offset``.
    ``every_call`` False: :meth:`close` at the MPC steps only (the protocol before issue 35)."""
    X = Y = th = 0.0
    k = 0
    for v, w, secs in segments:
        if true_vehicle is not None:
            alpha, _F, delta = equilibrium(v, w, true_vehicle)
        else:
            alpha, delta = 0.01 * w, 0.0
        alpha_hat = alpha - (kappa * v * w + beta)
        for _ in range(round(secs / Td)):
            mpc = k % 10 == 0
            pose = np.array([X, Y, th]) if _due(pose_hz, k) else None
            if every_call or mpc:
                f.close(pose, v + v_offset, w, v * w, mpc)
            f.sample(True, th if pose is not None else math.nan, v + v_offset, alpha_hat, v * w, w, delta,
                     0.0, pose is not None)
            X, Y, th = arc_step(X, Y, th, v, w, alpha, Td)  # exact motion over T_d
            k += 1


@pytest.mark.parametrize(("hz", "per_s"), [(1.0, 1.0), (3.0, 3.0), (5.0, 5.0), (None, 10.0)])
def test_chords_form_at_any_pose_rate(hz: float | None, per_s: float) -> None:
    """A chord ends at every pose once BASELINE T_c (0.5 s) of intervals are held: 1, 3, 5 chords
    per second at 1, 3, 5 Hz (one per MPC step at the nominal rate); before issue 35 none formed
    below 10 Hz."""
    f = CourseFusion(0.1, 0.0)
    _drive(f, SEGMENTS, pose_hz=hz)
    assert f.n_chords == pytest.approx(26.0 * per_s, abs=per_s + 1.0)


@pytest.mark.parametrize("hz", [1.0, 2.0, 3.0])
def test_slip_and_speed_offset_are_fitted_at_a_low_pose_rate(hz: float) -> None:
    """A slip error κ a_y + β of the model and a speed-sensor offset of 0.2 m/s, with the pose at
    1–3 Hz: the fits find them as at the nominal rate."""
    f = CourseFusion(0.1, 0.0)
    _drive(f, SEGMENTS * 2, pose_hz=hz, kappa=0.004, beta=-0.002, v_offset=0.2)
    k, b = f.slip_params
    assert k == pytest.approx(0.004, abs=3e-4) and b == pytest.approx(-0.002, abs=3e-4)
    assert f.speed_offset(10.0) == pytest.approx(0.2, abs=0.01)


@pytest.mark.parametrize("hz", [1.0, 3.0, 5.0])
def test_the_stiffnesses_are_fitted_at_a_low_pose_rate(hz: float, cfg: Config) -> None:
    """A car whose tyres are 30 % off the model's, pose at 1–5 Hz: the compliance fits reach them
    (the chords' α̇ and forgetting per second, not per chord)."""
    model = cfg.vehicle
    true = replace(model, cornering_stiffness_front=0.7 * model.C_f, cornering_stiffness_rear=1.3 * model.C_r)
    f = CourseFusion(0.1, 0.0, model)
    _drive(f, SEGMENTS * 3, pose_hz=hz, true_vehicle=true)
    C = f.stiffness
    assert C is not None
    assert C[0] == pytest.approx(true.C_f, rel=0.02) and C[1] == pytest.approx(true.C_r, rel=0.02)


def test_the_heading_between_poses_is_the_gyros_integral() -> None:
    """At 2 Hz in a corner the heading turns 0.15 rad between poses: without the gyro's integral
    between them (the heading held at the last pose's) the chord's mean heading would lag by about
    half of that, which the slip fit would take for a model error of tens of mrad. With it, an
    exact drive (α̂ = α) leaves the slip fit at 0."""
    f = CourseFusion(0.1, 0.0)
    _drive(f, SEGMENTS, pose_hz=2.0)
    k, b = f.slip_params
    assert f.n_chords > 40
    assert abs(k) < 2e-4 and abs(b) < 2e-4
    assert abs(f.slip_correction(3.0)) < 5e-4


def test_a_pose_at_every_call_ends_intervals_at_the_mpc_steps_only() -> None:
    """With a pose at every call the fusion is what it was before issue 35 (intervals of one T_c
    between MPC steps, chords of BASELINE of them): called every call or only at the MPC steps, it
    ends with the same records to the bit."""
    model = Config().vehicle
    true = replace(model, cornering_stiffness_rear=0.8 * model.C_r)
    fa, fb = CourseFusion(0.1, 0.001, model), CourseFusion(0.1, 0.001, model)
    _drive(fa, SEGMENTS, pose_hz=None, kappa=0.003, v_offset=0.1, true_vehicle=true, every_call=True)
    _drive(fb, SEGMENTS, pose_hz=None, kappa=0.003, v_offset=0.1, true_vehicle=true, every_call=False)
    assert fa.state.n_chords == fb.state.n_chords > 200
    assert fa.state.slip == fb.state.slip and fa.state.speed == fb.state.speed
    assert fa.state.stiff == fb.state.stiff


def test_the_engine_runs_a_low_pose_rate_alike(cfg: Config, paper_reference_path) -> None:
    """The course glue of the run engine (every call's close, the gyro-integrated heading) against
    the Python loop: a 4.3 Hz pose (intervals ending between MPC steps), a gyro bias and a softer
    rear axle, the stiffness fit at work."""
    c = replace(cfg, scenario=replace(cfg.scenario, sensors=replace(
        cfg.scenario.sensors, pose_rate_hz=4.3, omega_bias=0.01), plant=replace(
        cfg.scenario.plant, cornering_rear_scale=0.75)))
    sc = load_scenario(c, paper_reference_path)
    assert eng.applicability(c, "REF", sc) is None
    eng.LAST_RUN.clear()
    le = simulate(c, "REF", sc, engine=True, max_steps=400)
    assert eng.LAST_RUN
    lp = simulate(c, "REF", sc, engine=False, max_steps=400)
    assert le.termination == lp.termination and le.events == lp.events
    for name in ("state", "estimate", "command", "errors_measured", "u_c"):
        np.testing.assert_array_equal(getattr(le, name), getattr(lp, name), err_msg=name)
