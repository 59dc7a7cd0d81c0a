"""Tests that fail when the code is wrong (issue 34, item 5): each guards a mutation a reviewer made
that survived the rest of the suite.

1. ZOH discretisation (models/dynamic.py): B_d must be the zero-order-hold integral
   ∫₀ᵀ e^{As} ds B, not Euler's T·B — checked against scipy's ``cont2discrete(method='zoh')`` and
   the identity A·B_d = (A_d − I)·B on every public path that makes a discrete dynamic model.
2. Running-μ blend (conditions.py and its kernel port): an event blends from the μ in force when
   it acts (after the earlier events), not from the base profile's μ.
3. Arc against chord (estimation/fusion.py): on an exact circular arc the course fusion finds no
   slip (the chord's direction is the chord's *mean* heading, ω·T/2 past its first) and no speed
   offset (the chord is shorter than the arc driven by the factor sin(φ/2)/(φ/2)).
4. Pose gate after an outage (Cascade's pose-jump gate, control/gates.py: pose_consistent, which the
   Python cascade calls and the run engine and the batch kernel compile; a hand port in
   kernels/engine.py when the mutation was made): the heading allowance grows by
   HEADING_DRIFT_RAD_PER_S per second without an accepted pose, on every path alike.
"""

from __future__ import annotations

import math
from dataclasses import replace as dc_replace

import numpy as np
import pytest
import scipy.signal

from tsmpc import kernels
from tsmpc.conditions import EventFriction, ResolvedEvent, SensorModel, apply_conditions
from tsmpc.config import Config, SensorFaults, replace
from tsmpc.control.cascade import Cascade, Measurement
from tsmpc.estimation.fusion import BASELINE, CourseFusion
from tsmpc.models.dynamic import (
    Discretization,
    DynamicTS,
    augment_apkarian,
    continuous_matrices,
    discretize,
)
from tsmpc.models.kinematic import KinematicTS
from tsmpc.robustness import NaNBurstFault
from tsmpc.scenarios import ConstantFriction
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.simulator import Scenario, simulate
from tsmpc.synthesis.dynamic import augmented_models
from tsmpc.vehicle.plant import VehiclePlant

# float64 products of matrices with entries up to ~1e3 (the dynamic model's 1/v terms at the box's
# lowest speed) carry ~1e-13 relative rounding; scipy's expm (Padé, scaling and squaring) is good to
# a few 1e-15. 1e-10 relative leaves two orders of margin; Euler's T·B is off by ~T|A|/2, ≥ 1e-3.
RTOL_ZOH = 1e-10


# ============================================================================ 1. ZOH discretisation
def _zoh_reference(A: np.ndarray, B: np.ndarray, T: float) -> tuple[np.ndarray, np.ndarray]:
    """scipy.signal.cont2discrete(..., method='zoh') of one (A, B)."""
    n, m = B.shape
    Ad, Bd, *_ = scipy.signal.cont2discrete((A, B, np.eye(n), np.zeros((n, m))), T, method="zoh")
    return Ad, Bd


def _assert_zoh(A: np.ndarray, B: np.ndarray, Ad: np.ndarray, Bd: np.ndarray, T: float) -> None:
    """(Ad, Bd) (..., n, n), (..., n, m) are the exact ZOH discretisation of (A, B) at T."""
    A2, B2 = A.reshape(-1, *A.shape[-2:]), B.reshape(-1, *B.shape[-2:])
    Ad2, Bd2 = Ad.reshape(A2.shape), Bd.reshape(B2.shape)
    for a, b, ad, bd in zip(A2, B2, Ad2, Bd2, strict=True):
        want_a, want_b = _zoh_reference(a, b, T)
        np.testing.assert_allclose(ad, want_a, rtol=RTOL_ZOH, atol=RTOL_ZOH * np.abs(want_a).max())
        np.testing.assert_allclose(bd, want_b, rtol=RTOL_ZOH, atol=RTOL_ZOH * np.abs(want_b).max())
        # A ∫₀ᵀ e^{As} ds B = (e^{AT} − I) B: exact for ZOH, O(T²) off for Euler's T·B
        lhs, rhs = a @ bd, (ad - np.eye(a.shape[0])) @ b
        scale = np.abs(a).max() * np.abs(bd).max()
        np.testing.assert_allclose(lhs, rhs, rtol=0, atol=RTOL_ZOH * scale)
        # the check has teeth: Euler's B_d violates it by far more than the tolerance
        assert np.abs(a @ (T * b) - rhs).max() > 1e3 * RTOL_ZOH * scale


@pytest.fixture(scope="module")
def premises(cfg: Config) -> np.ndarray:
    """Scheduling points (δ, v, α): the box's 8 vertices and 12 random inner points."""
    box = cfg.dynamic_box
    lo = np.array([box.delta[0], box.v[0], box.alpha[0]])
    hi = np.array([box.delta[1], box.v[1], box.alpha[1]])
    rng = np.random.default_rng(34)
    inner = lo + (hi - lo) * rng.random((12, 3))
    return np.concatenate([DynamicTS(box, cfg.vehicle, cfg.rates.Td).premise_box.vertices(), inner])


@pytest.mark.parametrize("T", [0.01, 0.1])  # T_d and a coarser period (T_c)
def test_discretize_zoh_is_the_exact_hold_integral(cfg: Config, premises: np.ndarray, T: float) -> None:
    A, B = continuous_matrices(premises[:, 1], premises[:, 0], cfg.vehicle)
    Ad, Bd = discretize(A, B, T, Discretization.ZOH)  # batched
    _assert_zoh(A, B, Ad, Bd, T)
    Ad1, Bd1 = discretize(A[3], B[3], T, Discretization.ZOH)  # one model
    _assert_zoh(A[3], B[3], Ad1, Bd1, T)
    # Euler stays the paper's I + T A, T B exactly
    Ae, Be = discretize(A, B, T, Discretization.EULER)
    np.testing.assert_array_equal(Ae, np.eye(3) + T * A)
    np.testing.assert_array_equal(Be, T * B)


@pytest.mark.parametrize("T", [0.01, 0.1])
def test_dynamic_ts_zoh_vertices_and_points(cfg: Config, premises: np.ndarray, T: float) -> None:
    """DynamicTS(method=ZOH): the vertex models, the models at any scheduling point, the TS blend
    at a vertex and the disturbance input E_d (ZOH of E = [−1/M, 0, 0]ᵀ) are exact ZOH."""
    ts = DynamicTS(cfg.dynamic_box, cfg.vehicle, T, Discretization.ZOH)
    z = ts.premise_box.vertices()
    A, B = continuous_matrices(z[:, 1], z[:, 0], cfg.vehicle)
    _assert_zoh(A, B, ts.A_vertices, ts.B_vertices, T)
    A, B = continuous_matrices(premises[:, 1], premises[:, 0], cfg.vehicle)
    Ad, Bd = ts.matrices(premises)
    _assert_zoh(A, B, Ad, Bd, T)
    At, Bt = ts.ts_matrices(z[5])  # at a vertex the blend is that vertex's model
    _assert_zoh(A[5], B[5], At, Bt, T)
    E = np.array([[-1.0 / cfg.vehicle.mass], [0.0], [0.0]])
    Ed = ts.disturbance(premises)
    for i in range(premises.shape[0]):
        _, want = _zoh_reference(A[i], E, T)
        np.testing.assert_allclose(Ed[i], want, rtol=RTOL_ZOH, atol=RTOL_ZOH * np.abs(want).max())


def test_the_augmented_design_models_are_exact_zoh(cfg: Config, premises: np.ndarray) -> None:
    """The inner loop's LMI design model (synthesis/dynamic.py: Apkarian-augmented, ZOH)."""
    lam = cfg.dynamic_lmi.filter_bandwidth
    for T in (cfg.rates.Td, cfg.rates.Tc):
        Ad, Bd = augmented_models(premises, cfg.vehicle, T, lam)
        A, B = continuous_matrices(premises[:, 1], premises[:, 0], cfg.vehicle)
        Aa, Ba = augment_apkarian(A, B, lam)
        _assert_zoh(Aa, np.broadcast_to(Ba, (*Aa.shape[:-2], 6, 2)), Ad, Bd, T)


def test_kinematic_vertices_are_the_papers_euler_model(cfg: Config) -> None:
    """The kinematic model's discrete form is Euler by definition (paper): A_i = I + T_c A(z_i)
    with the continuous error dynamics' Jacobian [[0, ω, 0], [−ω, 0, v_d sinc e_θ], [0, 0, 0]]."""
    ts = KinematicTS(cfg.kinematic_box, cfg.rates.Tc)
    for zi, Ai in zip(ts.premise_box.vertices(), ts.A_vertices, strict=True):
        w, vs = zi[0], zi[1] * zi[2]
        Ac = np.array([[0.0, w, 0.0], [-w, 0.0, vs], [0.0, 0.0, 0.0]])
        np.testing.assert_allclose(Ai, np.eye(3) + ts.Tc * Ac, rtol=0, atol=1e-15)
    np.testing.assert_array_equal(ts.B, ts.Tc * np.array([[-1.0, 0.0], [0.0, 0.0], [0.0, -1.0]]))


# ============================================================================ 2. running-μ blend
# Ramp law (ResolvedEvent.weight): w = 0 before the start, (x − start)/ramp on the ramp, 1 after;
# EventFriction applies the events in order, μ ← (1 − w) μ + w μ_event, from the μ *before* the event.
MU0, MU1, MU2 = 1.0, 0.5, 0.2


def _expected_two_events() -> dict[float, float]:
    """μ at times [s] of: event 1 from 1 s, ramp 2 s to 0.5; event 2 from 4 s, ramp 2 s to 0.2."""
    return {
        2.0: 0.5 * MU0 + 0.5 * MU1,  # event 1 mid-ramp: 0.75
        3.5: MU1,  # event 1 holds: 0.5
        5.0: 0.5 * MU1 + 0.5 * MU2,  # event 2 mid-ramp from the running 0.5 (not the base 1.0): 0.35
        5.5: 0.25 * MU1 + 0.75 * MU2,  # 0.275
        7.0: MU2,
    }


def test_a_second_event_blends_from_the_running_mu() -> None:
    ev = (ResolvedEvent(True, 1.0, 2.0, math.inf, MU1), ResolvedEvent(True, 4.0, 2.0, math.inf, MU2))
    prof = EventFriction(ConstantFriction(MU0), ev)
    for t, want in _expected_two_events().items():
        assert prof.mu(t) == pytest.approx(want, rel=1e-12, abs=1e-15), t
    # the base-blend would give 0.5·1.0 + 0.5·0.2 = 0.6 at 5 s: far from 0.35
    assert abs(prof.mu(5.0) - (0.5 * MU0 + 0.5 * MU2)) > 0.2
    # the second event starting while the first is still on its ramp: from the blended μ
    ev2 = (ResolvedEvent(True, 1.0, 2.0, math.inf, MU1), ResolvedEvent(True, 1.5, 1.0, math.inf, MU2))
    running = 0.5 * MU0 + 0.5 * MU1  # event 1 at 2 s
    assert EventFriction(ConstantFriction(MU0), ev2).mu(2.0) == pytest.approx(
        0.5 * running + 0.5 * MU2, rel=1e-12)
    # by distance: the same law on the travelled-distance axis
    evd = (ResolvedEvent(False, 10.0, 20.0, math.inf, MU1), ResolvedEvent(False, 40.0, 20.0, math.inf, MU2))
    assert EventFriction(ConstantFriction(MU0), evd).mu(0.0, 50.0) == pytest.approx(0.35, rel=1e-12)


def test_the_configured_events_and_the_engine_blend_from_the_running_mu(cfg: Config) -> None:
    """The same two events written in ``[[scenario.friction]]`` (apply_conditions), and the
    engine's compiled friction program (kernels/engine.py: friction_mu) on them."""
    base = load_scenario(cfg, None)
    c = replace(cfg, scenario=replace(cfg.scenario, friction=(
        {"at_s": 1.0, "mu": MU1, "ramp_s": 2.0}, {"at_s": 4.0, "mu": MU2, "ramp_s": 2.0})))
    _, sc = apply_conditions(c, dc_replace(base, friction=ConstantFriction(MU0)))
    assert isinstance(sc.friction, EventFriction)
    for t, want in _expected_two_events().items():
        assert sc.friction.mu(t, 0.0) == pytest.approx(want, rel=1e-12, abs=1e-15), t
    if not kernels.enabled():
        pytest.skip("compiled kernels are off")
    from tsmpc.sim import engine as eng

    ke = eng._load_kernel()
    assert ke is not None
    frb, patches, events = eng._friction_program(sc.friction)
    for t, want in _expected_two_events().items():
        assert ke.friction_mu(t, 0.0, frb, patches, events) == pytest.approx(want, rel=1e-12, abs=1e-15), t


# ============================================================================ 3. arc against chord
def _drive_arc(v: float, omega: float, theta0: float, mpc_steps: int, Tc: float = 0.1,
               n_in: int = 10) -> CourseFusion:
    """CourseFusion fed as the cascade feeds it (close at each MPC call, then one sample per T_d
    call, the MPC call's included) along an exact circular arc: constant v and ω, zero slip
    (α̂ = 0, heading = course), no noise."""
    cf = CourseFusion(Tc, position_sigma=0.001, vehicle=None)
    R = v / omega
    Td = Tc / n_in
    cx, cy = -R * math.sin(theta0), R * math.cos(theta0)  # centre: start at the origin

    def pose(t: float) -> np.ndarray:  # the heading as a sensor gives it: wrapped to [−π, π)
        th = theta0 + omega * t
        wrapped = (th + math.pi) % (2.0 * math.pi) - math.pi
        return np.array([cx + R * math.sin(th), cy - R * math.cos(th), wrapped])

    for k in range(mpc_steps):
        t = k * Tc
        cf.close(pose(t), v, omega, v * omega)
        for i in range(n_in):
            th = pose(t + i * Td)[2]
            cf.sample(True, th, v, 0.0, v * omega, omega)
    return cf


@pytest.mark.parametrize(("omega", "theta0"), [(0.5, 0.3), (-0.5, -3.0), (0.8, 3.0)])  # ±π crossed
def test_course_fusion_finds_no_slip_and_no_speed_offset_on_an_exact_arc(omega: float,
                                                                         theta0: float) -> None:
    v, Tc = 10.0, 0.1
    cf = _drive_arc(v, omega, theta0, mpc_steps=40, Tc=Tc)
    assert cf.n_chords >= 30
    span = BASELINE * Tc
    phi = omega * span  # heading turned over one chord
    # the chord points ω·span/2 past the chord's first heading (its mean heading, trapezoid-exact for
    # a linear θ(t)); taken against the first heading instead, the slip fit would find that angle
    kappa, beta = cf.slip_params
    assert abs(beta) < 1e-9 and abs(kappa) < 1e-9, (kappa, beta)
    assert abs(0.5 * phi) > 1e6 * 1e-9
    assert cf.slip_correction(v * omega) == pytest.approx(0.0, abs=1e-9)
    # the car drove the arc R φ, the chord is 2R sin(φ/2): the speed over ground is the arc's; the
    # chord of one interval (T_c) would read a speed-sensor offset of v (1 − sin(φ/2)/(φ/2)),
    # φ = ω T_c (1–2.7 mm/s here)
    assert abs(cf.speed_offset(v)) < 1e-9, cf.speed_offset(v)
    phi_iv = omega * Tc
    assert v * (1.0 - math.sin(0.5 * abs(phi_iv)) / (0.5 * abs(phi_iv))) > 1e6 * 1e-9


# ============================================================================ 4. pose gate after an outage
#: The pose gate's documented heading allowance (Cascade's docstring: "a heading off by more than
#: 0.3 rad + 0.5 rad/s" without an accepted pose), and the cascade's heading-noise margin 5 σ_θ.
HEADING_JUMP_RAD, HEADING_DRIFT_RAD_PER_S = 0.3, 0.5


def test_cascade_pose_gate_allowance_grows_with_the_outage(cfg: Config) -> None:
    """Cascade.step from Python: 1 s without a pose (speed and yaw rate keep coming, so the
    dead-reckoned pose stays on the car), then the true pose with its heading off by the jump
    threshold plus half the drift allowance: accepted; plus 1.5 drift allowances: rejected
    (pose_jump_rejected), and so is every later sample while the allowance is short."""
    from tsmpc.planning.circuit import builtin_circuit

    ref = builtin_circuit(dt=cfg.rates.Tc)
    Td = cfg.rates.Td
    noise = 5.0 * cfg.noise.theta * cfg.noise.scale
    x0 = np.array([ref.x[0], ref.y[0], ref.theta[0], ref.v[0], 0.0, ref.omega[0]])
    t_lost, t_back, t_end = 0.2, 1.2, 1.25
    for frac, accepted in ((0.5, True), (1.5, False)):
        cas = Cascade(cfg, "REF", ref, x0=x0)
        plant = VehiclePlant(cfg.vehicle, cfg.tyre, cfg.rates.h)
        plant.reset(x0)
        x = x0
        dt = t_back - (t_lost - Td)  # since the last accepted pose
        dth = HEADING_JUMP_RAD + frac * HEADING_DRIFT_RAD_PER_S * dt
        assert dth > HEADING_JUMP_RAD + noise + 0.2  # well beyond the jump threshold alone
        for m in range(round(t_end / Td)):
            t = m * Td
            if t < t_lost - 1e-9:
                pose = (x[0], x[1], x[2])
            elif t < t_back - 1e-9:
                pose = (math.nan, math.nan, math.nan)
            else:  # back, with the heading offset from now on
                pose = (x[0], x[1], x[2] + dth)
            cmd = cas.step(t, Measurement(pose, x[3], x[5]))
            if abs(t - t_back) < 1e-9:
                assert cas.events["pose_jump_rejected"] == (0 if accepted else 1), (frac, dth, dt)
            x = plant.step(cmd.u, Td, 0.9)
        # the 10 MPC calls of the outage, and afterwards every one while the pose is rejected
        assert cas.events["pose_rejected"] == (10 if accepted else 11), cas.events
        assert (cas.events["pose_jump_rejected"] == 0) if accepted else (
            cas.events["pose_jump_rejected"] >= 1), cas.events


#: The engine and batch runs: the pose (every channel: NaNBurstFault) is lost from 0.2 s to 0.6 s,
#: shorter than recovery.blind_after_s (0.5 s; after it the cascade stops blind and takes the next
#: pose as it comes, issue 38), so the gate alone decides on the return, 0.41 s after the last pose.
OUTAGE = (0.2, 0.4)  # start, duration [s]
#: heading-sensor drift [rad/s] → accepted on return: the pose comes back drift × 0.41 s off the
#: dead-reckoned heading; 1.0 rad/s gives 0.41 rad, inside 0.3 + 0.5·0.41 = 0.505 rad but beyond the
#: 0.3 rad without the drift allowance; 2.0 rad/s gives 0.82 rad, beyond the allowance (and so is
#: every later sample: the jump grows faster than the allowance).
GATE_CASES = ((1.0, True), (2.0, False))
GATE_STEPS = 10  # 1 s: 0.4 s after the pose comes back


def _gate_scenario(cfg: Config, theta_drift: float) -> Scenario:
    """The built-in circuit with the OUTAGE while the heading sensor drifts at ``theta_drift``
    rad/s. (Beyond the config's ±0.005 rad/s, hence model_construct: the fault stands for a heading
    that jumps during the outage; the engine takes it as data all the same.)"""
    base = load_scenario(cfg, None)
    faults = SensorFaults.model_construct(**{**SensorFaults().model_dump(), "theta_drift": theta_drift})
    fault = SensorModel(faults, cfg.rates.Td, cfg.noise.position * cfg.noise.scale, cfg.seed,
                        inner=NaNBurstFault(period_s=1e4, duration_s=OUTAGE[1], start_s=OUTAGE[0]))
    return dc_replace(base, sensor_fault=fault, divergence_bound_m=1e3)


def _check_gate(log, accepted: bool) -> None:
    assert log.termination == "completed"
    assert log.events["mhe_rejected"] >= 40, log.events  # the outage happened: 0.4 s of NaN samples
    if accepted:
        assert log.events["pose_jump_rejected"] == 0, log.events
        assert log.events["pose_rejected"] == 4, log.events  # the outage's MPC calls only
    else:  # the return and the samples after it
        assert log.events["pose_jump_rejected"] >= 1, log.events
        assert log.events["pose_rejected"] >= 5, log.events


@pytest.mark.parametrize(("drift", "accepted"), GATE_CASES)
def test_pose_gate_after_an_outage_python_loop(cfg: Config, drift: float, accepted: bool) -> None:
    _check_gate(simulate(cfg, "REF", _gate_scenario(cfg, drift), engine=False, max_steps=GATE_STEPS),
                accepted)


@pytest.mark.skipif(not kernels.enabled(), reason="compiled kernels are off")
@pytest.mark.parametrize(("drift", "accepted"), GATE_CASES)
def test_pose_gate_after_an_outage_engine(cfg: Config, drift: float, accepted: bool) -> None:
    """The whole-run engine (it must really run: it steps aside silently when the Python side it
    reproduces changed), with the same events as the Python loop."""
    from tsmpc.sim import engine as eng

    sc = _gate_scenario(cfg, drift)
    why = eng.applicability(cfg, "REF", sc)
    assert why is None, why
    eng.LAST_RUN.clear()
    log = simulate(cfg, "REF", sc, engine=True, max_steps=GATE_STEPS)
    assert eng.LAST_RUN, "the engine did not run (it stepped aside: the Python loop ran)"
    _check_gate(log, accepted)
    py = simulate(cfg, "REF", _gate_scenario(cfg, drift), engine=False, max_steps=GATE_STEPS)
    assert log.events == py.events


@pytest.mark.skipif(not kernels.enabled(), reason="compiled kernels are off")
def test_pose_gate_after_an_outage_batch(cfg: Config) -> None:
    """The batch kernel (the engine's step compiled once more, lanes side by side): both cases as
    lanes of one batch, neither sent to the one-by-one fallback."""
    from tsmpc.sim import batch

    scs = [_gate_scenario(cfg, d) for d, _ in GATE_CASES]
    logs = batch.simulate_batch(cfg, "REF", scs, max_steps=GATE_STEPS)
    assert batch.LAST_BATCH["batched"] == len(scs) and not batch.LAST_BATCH["single"], batch.LAST_BATCH
    for log, (_, accepted) in zip(logs, GATE_CASES, strict=True):
        _check_gate(log, accepted)
