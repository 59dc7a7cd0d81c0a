"""The ``paper-as-run`` preset (SPEC §14; issue 22): each quirk of the published run is its own
switch and does what it says (hand computations), the published run's RMSE convention, the
feasibility LMI with numpy certificates, the walk to the ``paper`` preset, and one slow end-to-end
run of the acceptance numbers."""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.config import Config, InnerLaw, LQRSettings, load_config, replace
from tsmpc.control.cascade import Cascade, Measurement
from tsmpc.control.paper_as_run import AsRunLQR, as_run_memberships, as_run_reference_gain
from tsmpc.control.ts_lqr import TSLQR
from tsmpc.errors import ConfigError
from tsmpc.models.dynamic import DynamicTS, continuous_matrices
from tsmpc.models.kinematic import pose_to_errors
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.metrics import (
    PAPER_RUN_POSE_DROP,
    PAPER_RUN_ZERO_PAD,
    paper_run_rmse,
    paper_run_rmse_from_arrays,
)
from tsmpc.sim.simulator import Method, simulate

AS_RUN = "paper-as-run"


@pytest.fixture(scope="module")
def as_run() -> Config:
    return Config.preset(AS_RUN)


# --- the preset ---------------------------------------------------------------------------------

def test_preset_carries_every_condition_of_spec_14(as_run: Config) -> None:
    c = as_run
    v = c.vehicle
    assert v.mu_nominal * v.mass * v.g == pytest.approx(4355.15, abs=0.01)  # M g μ (SPEC §14)
    assert c.lqr.friction_compensation is False and c.lqr.true_state_feedback is True
    assert (c.rates.Td, c.rates.inner_steps_per_outer, c.rates.inner_per_outer) == (0.001, 101, 101)
    assert c.lqr.law == InnerLaw.AS_RUN and c.lqr.steering_bias_rad == 0.5236
    assert c.lqr.scheduling_speed_shift == 2.0 and c.lqr.extrapolate_memberships is True
    assert c.dynamic_box.v == (2.0, 18.0) and c.dynamic_lmi.formulation == "feasibility-euler"
    assert c.dynamic_lmi.feasible_point == "analytic-center"  # our reading of the unknown point
    assert c.lqr.initial_filter_state == (4355.15, 0.52466)
    assert c.noise.scale == 0.0 and c.metrics.paper_run_rmse is True
    assert c.lqr.speed_feedback is False  # no speed integral, no speed-error feedback
    # the paper preset's own settings are kept
    assert c.mpc.slip_aware is False and c.mpc.tangent_heading is False


def test_preset_is_never_the_default_and_new_switches_default_off() -> None:
    d = Config()
    assert d != Config.preset(AS_RUN)
    assert d.rates.inner_steps_per_outer is None and d.rates.inner_per_outer == 10
    assert d.lqr.law == InnerLaw.STATIC_GAIN and d.lqr.true_state_feedback is False
    assert (d.lqr.steering_bias_rad, d.lqr.scheduling_speed_shift) == (0.0, 0.0)
    assert d.lqr.extrapolate_memberships is False and d.lqr.initial_filter_state is None
    assert d.dynamic_lmi.formulation == "guaranteed-cost" and d.mhe.form == "window"
    assert d.dynamic_lmi.feasible_point == "solver"
    assert d.metrics.paper_run_rmse is False
    for name in ("paper", "default"):  # the other presets do not touch the new switches
        assert Config.preset(name).model_dump(include={"metrics"}) == d.model_dump(include={"metrics"})


def test_default_dynamic_design_key_is_unchanged() -> None:
    """The new ``formulation`` and ``feasible_point`` fields are left out of the hash at their
    defaults: cached designs of every existing config keep their key."""
    import hashlib
    import json

    from tsmpc.synthesis.cache import FORMAT_VERSION, dynamic_key

    for cfg in (Config(), Config.preset("paper")):
        lmi = cfg.dynamic_lmi.model_dump(mode="json")
        lmi.pop("formulation")
        lmi.pop("feasible_point")
        payload = {"kind": "dynamic", "format": FORMAT_VERSION,
                   "box": cfg.dynamic_box.model_dump(mode="json"), "lmi": lmi,
                   "vehicle": cfg.vehicle.model_dump(mode="json", exclude_none=True), "Td": cfg.rates.Td}
        old = hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()
        assert dynamic_key(cfg) == old
    assert dynamic_key(Config.preset(AS_RUN)) != dynamic_key(
        replace(Config.preset(AS_RUN), dynamic_lmi=replace(Config().dynamic_lmi)))
    as_run = Config.preset(AS_RUN)
    assert dynamic_key(as_run) != dynamic_key(
        replace(as_run, dynamic_lmi=replace(as_run.dynamic_lmi, feasible_point="solver")))


def test_preset_from_toml_and_cli(tmp_path: Path) -> None:
    f = tmp_path / "c.toml"
    f.write_text('preset = "paper-as-run"\n[lqr]\nsteering_bias_rad = 0.0\n', encoding="utf-8")
    c = load_config(f)
    assert c.lqr.steering_bias_rad == 0.0 and c.rates.inner_steps_per_outer == 101
    assert load_config(None, preset=AS_RUN) == Config.preset(AS_RUN)
    assert load_config(tmp_path / "none.toml" if False else None, preset=AS_RUN).lqr.law == "as-run"
    out = tmp_path / "run"
    res = CliRunner().invoke(app, ["run", "--preset", AS_RUN, "--duration", "0.3", "--no-plots",
                                   "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert load_config(out / "config.toml") == Config.preset(AS_RUN)
    assert "REF (paper-run RMSE)" in (out / "rmse.md").read_text(encoding="utf-8")
    import json

    m = json.loads((out / "metrics.json").read_text(encoding="utf-8"))
    assert set(m["methods"]["REF"]["rmse_paper_run"]) == {"x", "y", "theta", "v", "omega"}
    assert m["paper_run_rmse"] is True


@pytest.mark.parametrize("field, value", [("steering_bias_rad", 0.1), ("scheduling_speed_shift", 2.0),
                                          ("extrapolate_memberships", True),
                                          ("initial_filter_state", (1.0, 0.0))])
def test_as_run_switches_need_the_as_run_law(field: str, value: object) -> None:
    with pytest.raises(ConfigError, match=f"{field}: only for the as-run law"):
        replace(LQRSettings(), **{field: value})
    replace(LQRSettings(), law="as-run", **{field: value})  # fine with the law
    with pytest.raises(ConfigError, match=f"lqr.*{field}: only for the as-run law"):
        load_config(None, preset=None) if False else __import__("tsmpc.config").config.validate(
            Config, {"lqr": {field: value}})


# --- the inner law, by hand ---------------------------------------------------------------------

def _law(cfg: Config, K: np.ndarray, **lqr: object) -> AsRunLQR:
    settings = replace(cfg.lqr, **lqr)
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td)
    return AsRunLQR(K, dyn, cfg.vehicle, settings, cfg.rates.Td, bandwidth=cfg.dynamic_lmi.filter_bandwidth)


def _gains(seed: int = 3) -> np.ndarray:
    rng = np.random.default_rng(seed)
    K = np.zeros((8, 2, 6))
    K[:] = [[-1700.0, -2.0, 9.0, -18.0, -20.0, 19.0], [0.05, 47.0, -3.0, 0.0, -104.0, 99.0]]
    return K + rng.normal(scale=0.5, size=K.shape)


def _est(x: tuple[float, float, float], F: float = 0.0) -> SimpleNamespace:
    return SimpleNamespace(x=np.array(x), F_fr=F, F_fr_raw=F)


def _continuous_nbar(cfg: Config, delta: float, v: float, K: np.ndarray) -> np.ndarray:
    """The static reference gain from the continuous model, computed independently."""
    A, B = continuous_matrices(v, delta, cfg.vehicle)
    lam = cfg.dynamic_lmi.filter_bandwidth
    Ac = np.block([[A, B], [np.zeros((2, 3)), -lam * np.eye(2)]])
    Bc = np.vstack([np.zeros((3, 2)), lam * np.eye(2)])
    X = np.linalg.solve(Ac + Bc @ K[:, :5], Bc)
    return -np.linalg.inv(X[[0, 2], :])


def test_one_step_of_the_as_run_law_by_hand(as_run: Config) -> None:
    """u = N̄ r + K [v, α, ω, F_app, σ, ζ] with σ = δ + b, Euler filter, applied δ = sat(σ − b)."""
    K = _gains()
    law = _law(as_run, K)
    F1, s1 = as_run.lqr.initial_filter_state
    b, T, lam = 0.5236, 0.001, 10.0
    x, r = (9.0, 0.01, 0.05), np.array([9.5, 0.06])
    cmd = law.step(_est(x), *r)
    lo, hi = as_run.dynamic_box.delta[0], as_run.dynamic_box.delta[1]
    vlo, vhi = as_run.dynamic_box.v
    z = np.array([s1 - b, x[0] + 2.0, x[1]])
    eta = (z - np.array([lo, vlo, -0.1])) / (np.array([hi, vhi, 0.1]) - np.array([lo, vlo, -0.1]))
    mu = [np.prod([eta[j] if (i >> (2 - j)) & 1 else 1 - eta[j] for j in range(3)]) for i in range(8)]
    Kb = sum(m * Ki for m, Ki in zip(mu, K, strict=True))
    Nbar = _continuous_nbar(as_run, s1 - b, x[0], Kb)
    u = Nbar @ r + Kb @ np.array([*x, F1, s1, 0.0])
    F1n, s1n = F1 + T * lam * (u[0] - F1), s1 + T * lam * (u[1] - s1)
    d = min(max(s1n - b, -math.radians(25)), math.radians(25))
    assert cmd.F_xR == pytest.approx(min(max(F1n, -2000.0), 10000.0), rel=1e-9)
    assert cmd.delta == pytest.approx(d, rel=1e-9, abs=1e-12)
    assert law.state[:3] == pytest.approx((F1n, s1n, T * (r[1] - x[2])), rel=1e-9)


@pytest.mark.parametrize("extrapolate", [True, False])
def test_step_on_floats_equals_the_numpy_formula(as_run: Config, extrapolate: bool) -> None:
    """The step (plain floats, N̄ in closed form) computes what the public numpy functions compute:
    K = Σ μ_i K_i (as_run_memberships), N̄ = as_run_reference_gain(model5) and u = N̄ r + K x, over
    states inside and outside the box (δ beyond ±25° through σ, v + 2 beyond 18 m/s, α beyond
    ±0.1, v under the model's floor). rel 1e-9: the two N̄ differ by rounding only (≤ 1e-10 seen:
    the numpy LU and the closed form round differently; a wrong entry is off by orders more)."""
    law = _law(as_run, _gains(), extrapolate_memberships=extrapolate)
    box = law.model.premise_box
    lo, hi, bits = np.array(box.lower), np.array(box.upper), np.array(box.vertex_bits)
    st, a, b = law.settings, 0.01, as_run.lqr.steering_bias_rad
    rng = np.random.default_rng(7)
    law.step(_est((0.12, 0.0, 0.0)), 0.5, 0.0)  # started
    for k in range(300):
        x = (float(rng.choice([0.05, rng.uniform(0.1, 25.0)])), float(rng.uniform(-0.2, 0.2)),
             float(rng.uniform(-1.0, 1.0)))
        r = np.array([rng.uniform(0.0, 20.0), rng.uniform(-1.0, 1.0)])
        law._sigma = float(rng.uniform(-0.7, 0.7)) + b  # δ over and beyond the box
        F1, s1, zeta, F_app = law.state
        d = s1 - b
        mu = as_run_memberships((d, x[0] + 2.0, x[1]), lo, hi, bits, extrapolate=extrapolate)
        K = np.tensordot(mu, law.K, axes=(0, 0))
        Nbar = as_run_reference_gain(law.model5(d, x[0]), law.B5, K)
        u = Nbar @ r + K @ np.array([*x, F_app, s1, zeta])
        cmd = law.step(_est(x), *r)
        F1n, s1n = F1 + a * (u[0] - F1), s1 + a * (u[1] - s1)
        assert law.state == pytest.approx((F1n, s1n, zeta + 0.001 * (r[1] - x[2]),
                                           min(max(F1n, -2000.0), 10000.0)), rel=1e-9), k
        assert (cmd.F_xR, cmd.delta) == pytest.approx(
            (min(max(F1n, -2000.0), 10000.0), min(max(s1n - b, -st.delta_max), st.delta_max)), rel=1e-9)


def test_steering_bias_enters_as_K5_times_b(as_run: Config) -> None:
    """Same δ, bias b or none: the filter input differs by exactly K(:, 5)·b, so after one Euler
    step (a = T_d λ) the applied steering differs by a b (K_δ,5 − 1) and the force by a b K_F,5
    (the design has nothing that cancels it)."""
    K = np.broadcast_to(_gains()[0], (8, 2, 6)).copy()  # one gain: the blend cannot hide anything
    a, d0, x, r = 0.001 * 10.0, 0.01, (5.0, 0.0, 0.02), (5.0, 0.02)
    for b in (0.5236, 1e-3):
        with_b = _law(as_run, K, steering_bias_rad=b, initial_filter_state=(4355.15, d0 + b))
        without = _law(as_run, K, steering_bias_rad=0.0, initial_filter_state=(4355.15, d0))
        c1, c0 = with_b.step(_est(x), *r), without.step(_est(x), *r)
        assert (with_b.state[1] - b) - without.state[1] == pytest.approx(a * b * (K[0, 1, 4] - 1.0), rel=1e-9)
        # a difference of two ≈ 4.4 kN forces: resolvable to a few ulp of the force, not of the
        # difference (8 ulp of 4.4 kN ≈ 8e-12 N; the term itself is 2e-4 … 4e-7 N)
        ulp_F = np.spacing(abs(c0.F_xR))
        assert c1.F_xR - c0.F_xR == pytest.approx(a * b * K[0, 0, 4], rel=1e-9, abs=64 * ulp_F)
    assert c1.delta - c0.delta == pytest.approx(a * b * (K[0, 1, 4] - 1.0), rel=1e-9)  # unsaturated


def test_reference_gain_matches_the_continuous_formula_and_tracks(as_run: Config) -> None:
    """N̄ = [C (I − A₅ − B₅K₅)⁻¹ B₅]⁻¹ on the Euler model equals the continuous static gain, and
    the discrete loop's steady state then has C x = r."""
    law = _law(as_run, _gains())
    for delta, v in ((0.0, 0.5), (0.1, 7.0), (-0.3, 15.0)):
        K = law.gains((delta, v + 2.0, 0.02))
        A5 = law.model5(delta, v)
        Nbar = as_run_reference_gain(A5, law.B5, K)
        np.testing.assert_allclose(Nbar, _continuous_nbar(as_run, delta, v, K), rtol=1e-7)
        ts = TSLQR(_gains(), DynamicTS(replace(as_run.dynamic_box, v=(0.1, 40.0), delta=(-1.0, 1.0)),
                                       as_run.vehicle, 0.001), as_run.vehicle, Config().lqr, 0.001, jit=False)
        np.testing.assert_allclose(Nbar, ts.reference_gain(delta, v, K), rtol=1e-7)
        r = np.array([v + 0.3, 0.05])
        xss = np.linalg.solve(np.eye(5) - A5 - law.B5 @ K[:, :5], law.B5 @ (Nbar @ r))
        np.testing.assert_allclose(xss[[0, 2]], r, rtol=1e-9, atol=1e-12)


def test_memberships_extrapolate_and_speed_shift(as_run: Config) -> None:
    box = DynamicTS(as_run.dynamic_box, as_run.vehicle, 0.001).premise_box
    lo, hi, bits = np.array(box.lower), np.array(box.upper), np.array(box.vertex_bits)
    z = (-0.6, 25.0, 0.0)  # δ and v outside the box
    mu = as_run_memberships(z, lo, hi, bits, extrapolate=True)
    assert mu.min() < 0.0 and mu.sum() == pytest.approx(1.0)
    np.testing.assert_allclose(mu @ box.vertices(), z, atol=1e-12)  # affine maps extrapolate exactly
    np.testing.assert_allclose(as_run_memberships(z, lo, hi, bits, extrapolate=False), box.memberships(z))
    # gains linear in the vertex speed: K(z) is the gain at v + shift, even outside the box
    G = np.ones((2, 6))
    K = np.array([vz[1] * G for vz in box.vertices()])
    law = _law(as_run, K)
    np.testing.assert_allclose(law.gains((0.0, 19.0 + 2.0, 0.0)), 21.0 * G)
    clipped = _law(as_run, K, extrapolate_memberships=False)
    np.testing.assert_allclose(clipped.gains((0.0, 21.0, 0.0)), 18.0 * G)


def test_previous_clipped_force_and_no_anti_windup(as_run: Config) -> None:
    K = np.broadcast_to(_gains()[0], (8, 2, 6)).copy()
    law = _law(as_run, K, initial_filter_state=(20000.0, 0.5236))  # F₁ beyond the 10 kN limit
    x, r = (5.0, 0.0, 0.0), np.array([5.0, 1.0])
    F1, s1 = 20000.0, 0.5236
    Nbar = as_run_reference_gain(law.model5(0.0, 5.0), law.B5, K[0])
    u = Nbar @ r + K[0] @ np.array([*x, 10000.0, s1, 0.0])  # F_app = sat(F₁) = 10 kN, not 20 kN
    cmd = law.step(_est(x), *r)
    assert law.state[0] == pytest.approx(F1 + 0.01 * (u[0] - F1), rel=1e-9)
    assert cmd.F_xR == 10000.0 and cmd.saturated
    zeta = 0.001 * 1.0
    for _ in range(50):  # saturated steering: ζ keeps integrating (no anti-windup)
        cmd = law.step(_est(x), 5.0, 1.0)
        zeta += 0.001 * 1.0
    assert law.state[2] == pytest.approx(zeta, rel=1e-12)


# --- the time base, the state source, the start ------------------------------------------------

@pytest.fixture(scope="module")
def short_log(as_run: Config, paper_reference_path: Path):
    sc = load_scenario(as_run, paper_reference_path)
    return sc, simulate(as_run, Method.REF, sc, max_steps=3)


def test_101_inner_steps_per_reference_sample(as_run: Config, short_log) -> None:
    sc, log = short_log
    ref = sc.reference
    assert log.t_inner.size == 3 * 101
    t0 = float(ref.t[0])
    assert log.t_inner[101] - t0 == pytest.approx(0.101) and log.t_inner[202] - t0 == pytest.approx(0.202)
    for k in range(3):  # outer step k: the plant at k · 0.101 s against reference sample k (k · 0.1 s)
        x = log.state[k * 101]
        np.testing.assert_allclose(log.errors_measured[k],
                                   pose_to_errors(x[0], x[1], x[2], ref.x[k], ref.y[k], ref.theta[k]),
                                   atol=1e-12)
    # no sensor noise: the measurement is the state
    np.testing.assert_array_equal(log.measurement, log.state[:, [3, 5]])
    # the start: on the reference's first sample at its speed (0.12 m/s)
    np.testing.assert_allclose(log.state[0], [ref.x[0], ref.y[0], ref.theta[0], ref.v[0], 0.0, ref.omega[0]])
    assert ref.v[0] == pytest.approx(0.12, abs=0.001)


def _check_the_reference_sample_is_counted_not_timed(sc, log) -> None:
    """After 100 outer steps the plant time (k · 0.101 s) is a whole sample ahead of the reference
    time (k · 0.1 s): the MPC must still track sample k (floor(t / T_c) would give k + 1). Checked
    on the end-to-end run's steps 100–101 (a 102-step run of its own cost 6 s of CPU; nothing in a
    step depends on the run's length)."""
    ref = sc.reference
    for k in (100, 101):
        x = log.state[k * 101]
        assert math.floor((log.t_inner[k * 101] - ref.t[0]) / 0.1 + 1e-9) > k  # the plant is ahead
        np.testing.assert_allclose(log.errors_measured[k],
                                   pose_to_errors(x[0], x[1], x[2], ref.x[k], ref.y[k], ref.theta[k]),
                                   atol=1e-12)


def test_cascade_holds_the_mpc_input_over_101_calls(as_run: Config, paper_reference_path: Path) -> None:
    sc = load_scenario(as_run, paper_reference_path)
    casc = Cascade(as_run, "ref", sc.reference)
    ref = sc.reference
    x0 = np.array([ref.x[0], ref.y[0], ref.theta[0], ref.v[0], 0.0, ref.omega[0]])
    casc.reset(x0)
    ran, refs = [], []
    for m in range(203):
        cmd = casc.step(m * 0.001, Measurement(tuple(x0[:3]), x0[3], x0[5], state=x0[3:6]))
        ran.append(cmd.plan is not None)
        refs.append((cmd.v_ref, cmd.omega_ref))
        if m == 0:  # the first previous input was [v, ω] of the first sample
            np.testing.assert_allclose(cmd.plan.u_pred[0] - cmd.plan.du[0], [ref.v[0], ref.omega[0]])
    assert [i for i, r in enumerate(ran) if r] == [0, 101, 202]
    assert len(set(refs[:101])) == 1 and len(set(refs[101:202])) == 1


def test_true_state_feedback_keeps_the_compensation(as_run: Config, paper_reference_path: Path) -> None:
    """The published run's quirk: the law gets the true state and the MHE's F̂ (compensation as
    configured); the oracle ablation gets the true state and F̂ = 0."""
    sc = load_scenario(as_run, paper_reference_path)
    seen = {}
    for name, cfg in (("quirk", as_run), ("oracle", replace(as_run, lqr=replace(as_run.lqr,
                                                                                true_state_feedback=False)))):
        casc = Cascade(cfg, "ref", sc.reference)
        got = []
        step = casc.lqr.step
        casc.lqr.step = lambda e, v, w, _s=step, _g=got: (_g.append(e), _s(e, v, w))[1]
        truth = np.array([0.2, 0.03, 0.01])
        for m in range(5):
            casc.step(m * 0.001, Measurement((sc.reference.x[0], sc.reference.y[0], sc.reference.theta[0]),
                                             0.12, 0.0, state=truth))
        seen[name] = got[-1]
        np.testing.assert_array_equal(got[-1].x, truth)
        assert casc.last_estimate is not None
        if name == "quirk":
            assert got[-1].F_fr_raw == casc.last_estimate.F_fr_raw != 0.0
    assert seen["oracle"].F_fr == 0.0 and seen["oracle"].F_fr_raw == 0.0


# --- the published run's RMSE convention --------------------------------------------------------

def test_paper_run_rmse_convention_on_known_values() -> None:
    K = 1272
    pose = np.ones((K, 3)) * [1.0, 2.0, 3.0]
    pose[-PAPER_RUN_POSE_DROP:] = 100.0  # left out: 1262 of 1272 steps count
    ref_vw = np.tile([10.0, 0.1], (K, 1))
    end_vw = ref_vw - [2.0, 0.3]
    s = paper_run_rmse_from_arrays(pose, ref_vw, end_vw)
    assert (s.x, s.y, s.theta) == pytest.approx((1.0, 2.0, 3.0))
    assert s.v == pytest.approx(math.sqrt(K * 4.0 / (K + PAPER_RUN_ZERO_PAD)))  # 1292 entries
    assert s.omega == pytest.approx(math.sqrt(K * 0.09 / 1292))
    assert (PAPER_RUN_POSE_DROP, PAPER_RUN_ZERO_PAD) == (10, 20)


def test_paper_run_rmse_of_a_log_uses_the_state_at_the_end_of_each_step(
        as_run: Config, paper_reference_path: Path) -> None:
    cfg = replace(as_run, rates=replace(as_run.rates, Td=0.01, inner_steps_per_outer=None))
    cfg = replace(cfg, lqr=replace(cfg.lqr, law="static-gain", steering_bias_rad=0.0,
                                   scheduling_speed_shift=0.0, extrapolate_memberships=False,
                                   initial_filter_state=None),
                  dynamic_lmi=replace(cfg.dynamic_lmi, formulation="guaranteed-cost",
                                      feasible_point="solver"),
                  dynamic_box=Config().dynamic_box)
    sc = load_scenario(cfg, paper_reference_path)
    short, longer = (simulate(cfg, Method.REF, sc, max_steps=n) for n in (12, 13))
    np.testing.assert_allclose(short.meta["final_state"], longer.state_outer[12], rtol=0, atol=1e-12)
    end = np.vstack([short.state_outer[1:], short.meta["final_state"]])[:, [3, 5]]
    err = short.ref[:, 3:5] - end
    s = paper_run_rmse(short)
    assert s.v == pytest.approx(math.sqrt(np.sum(err[:, 0] ** 2) / (12 + 20)), rel=1e-12)
    assert s.y == pytest.approx(math.sqrt(np.mean(short.errors[:2, 1] ** 2)), rel=1e-12)


# --- the feasibility design ---------------------------------------------------------------------

def test_feasibility_design_certificates_recomputed(as_run: Config) -> None:
    from tsmpc.synthesis.cache import load_or_design_dynamic
    from tsmpc.synthesis.paper_as_run import FeasibilityDesign, certify_vertices, vertex_models

    d = load_or_design_dynamic(as_run)
    assert isinstance(d, FeasibilityDesign) and d.K.shape == (8, 2, 6)
    A, B = vertex_models(as_run.dynamic_box, as_run.vehicle, d.Td, d.bandwidth)
    assert all(c.holds for c in certify_vertices(A, B, as_run.dynamic_lmi, d.K, d.P))
    # independently, in physical units: the common P decreases at every vertex
    L = np.linalg.cholesky(d.P)
    Li = np.linalg.inv(L)
    for i in range(8):
        Acl = A[i] + B[i] @ d.K[i]
        assert np.max(np.linalg.eigvalsh(Li @ Acl.T @ d.P @ Acl @ Li.T)) < 1.0
    bad = d.K.copy()
    bad[3, 1, 5] *= -1.0  # a tampered gain fails its vertex certificate
    assert not all(c.holds for c in certify_vertices(A, B, as_run.dynamic_lmi, bad, d.P))


# --- the walk -----------------------------------------------------------------------------------

def test_the_walk_removes_one_switch_per_row_and_ends_on_the_paper_preset() -> None:
    from generator.paper_explained_runs import QUIRKS, walk_rows

    rows = walk_rows()
    assert rows[0].config == Config.preset(AS_RUN) and len(rows) == len(QUIRKS) + 1
    last = rows[-1].config.model_dump(exclude={"metrics"})
    assert last == Config.preset("paper").model_dump(exclude={"metrics"})

    def flat(d: dict, pre: str = "") -> dict:
        out = {}
        for k, v in d.items():
            out.update(flat(v, f"{pre}{k}.") if isinstance(v, dict) else {f"{pre}{k}": v})
        return out

    for a, b, q in zip(rows[:-1], rows[1:], QUIRKS, strict=True):
        fa, fb = flat(a.config.model_dump(mode="json")), flat(b.config.model_dump(mode="json"))
        changed = {k for k in fa if fa[k] != fb[k]}
        assert len(changed) == 1, (q.name, changed)
        assert changed.pop() in q.switch


def test_steady_straight_is_the_fixed_point_of_the_law(as_run: Config) -> None:
    """The speed-headroom evidence: the (F₁, ζ) it solves for leave the law's filters where they
    are when stepped (checked by stepping the law itself)."""
    from generator.paper_explained_runs import steady_straight

    from tsmpc.synthesis.cache import load_or_design_dynamic

    d = load_or_design_dynamic(as_run)
    law = _law(as_run, d.K)
    v, v_ref = 13.9, 18.0
    F, zeta = steady_straight(law, v, v_ref)
    b = as_run.lqr.steering_bias_rad
    law2 = _law(as_run, d.K, initial_filter_state=(F, b))
    law2.step(_est((v, 0.0, 0.0)), v_ref, 0.0)  # start, then put ζ at its fixed point
    law2._F1, law2._sigma, law2._zeta, law2._F_app = F, b, zeta, F
    law2.step(_est((v, 0.0, 0.0)), v_ref, 0.0)
    assert law2.state[0] == pytest.approx(F, rel=1e-9) and law2.state[1] == pytest.approx(b, abs=1e-9)


def test_the_preset_gains_fall_short_on_the_fastest_stretch(as_run: Config,
                                                           paper_reference_path: Path) -> None:
    """The evidence for RMSE_x and NL's divergence, computed from the law itself: with the
    preset's gains the steady force at the fastest reference sample with v_ref at the bound is
    below what the plant needs; either counterfactual of the explained table (bound 22 m/s, or
    the speed entry × 2.5) covers it. The needed force is μ_dry M g + drag (hand formula)."""
    from dataclasses import replace as dc_replace

    from generator.paper_explained_runs import speed_headroom

    from tsmpc.synthesis.cache import load_or_design_dynamic

    d = load_or_design_dynamic(as_run)
    v_d_max = float(np.max(load_scenario(as_run, paper_reference_path).reference.v))
    h = speed_headroom(as_run, d, v_d_max)
    p = as_run.vehicle
    assert h.v == pytest.approx(v_d_max / 1.01, rel=1e-12) and h.v_ref_bound == 18.0
    assert h.force_needed_N == pytest.approx(0.9 * p.mass * p.g + 0.5 * 1.184 * 0.36 * 1.91 * h.v**2)
    assert h.force_needed_N - h.force_at_bound_N > 200.0  # measured: 332 N short
    bound = replace(as_run, mpc=replace(as_run.mpc, u_max=(22.0, 1.4)))
    assert speed_headroom(bound, d, v_d_max).force_at_bound_N > h.force_needed_N
    K = np.array(d.K)
    K[:, 0, 0] *= 2.5
    assert speed_headroom(as_run, dc_replace(d, K=K), v_d_max).force_at_bound_N > h.force_needed_N


def test_design_points_and_divergence_onset(paper_reference_path: Path) -> None:
    """The design-points study (3 outer steps each): the centre and Clarabel's answer certify and
    differ, the physical-units answer does not certify; the onset of two runs' difference."""
    from generator.paper_explained_runs import design_points, divergence_onset

    pts = design_points(paper_reference_path, max_steps=3, uncertified_steps=3)
    assert [p.certified for p in pts] == [True, True, False]
    assert pts[0].steering_ratio != pytest.approx(pts[1].steering_ratio, rel=0.05)
    assert all(p.result.metrics["outer_steps"] == 3 for p in pts)
    a = SimpleNamespace(n_outer=4, t_outer=np.arange(4) * 0.1 + 5.0,
                        errors=np.array([[1.0, 0.0, 0], [2.0, 0.05, 0], [3.0, 0.3, 0], [4.0, 1.0, 0]]))
    b = SimpleNamespace(n_outer=4, t_outer=a.t_outer, errors=np.zeros((4, 3)))
    assert divergence_onset(a, b) == pytest.approx((0.2, 3.0))
    assert divergence_onset(b, b) is None


def test_the_transient_grows_as_the_steering_zeta_gain_shrinks(paper_reference_path: Path) -> None:
    """SPEC §14: the transient's size depends on the steering row's δ_f / ζ ratio. 5 s runs: the
    e_y peaks of the 8 s window are at 2.4 s (0.72 m) and 3.0 s (1.69 m), so the 5 s runs have
    the same peaks at 5/8 of the CPU."""
    from generator.paper_explained_runs import gain_sensitivity

    res = gain_sensitivity(paper_reference_path, (1.0, 0.5), max_steps=50)
    peaks = [abs(r.transient.ey_peak_m) for r in res]
    assert peaks[1] > 1.5 * peaks[0] > 0.0


# --- the paper's UIO-MHE form -------------------------------------------------------------------

def test_uio_gain_and_structure_for_euler() -> None:
    from tsmpc.estimation.mhe_paper_uio import uio_gain

    M, T = 683.0, 0.001
    th = uio_gain(np.array([-T / M, 0.0, 0.0]))
    np.testing.assert_allclose(th, [-M / T, 0.0, 0.0])
    Pi = np.eye(3) - np.outer([-T / M, 0.0, 0.0], th)  # I − E Θ C
    A = np.arange(9.0).reshape(3, 3) + 1.0
    assert np.all((Pi @ A)[0] == 0.0) and np.all((Pi @ A)[1:] == A[1:])


def _nominal_data(cfg: Config, Td: float, F: float, n: int, seed: int = 0):
    rng = np.random.default_rng(seed)
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td)
    x = np.array([10.0, 0.01, 0.05])
    xs, ys, us = [x.copy()], [], []
    for _k in range(n):
        u = np.array([3000.0 + 200.0 * rng.standard_normal(), 0.02 + 0.01 * rng.standard_normal()])
        A, B = dyn.matrices(np.array([u[1], x[0], x[1]]))
        x = A @ x + B @ u - B[:, 0] * F
        us.append(u)
        xs.append(x.copy())
    ys = [np.array([s[0], s[2]]) for s in xs]
    return dyn, np.array(xs), ys, us


def test_uio_form_recovers_state_and_friction_exactly_on_the_nominal_model() -> None:
    from tsmpc.estimation.mhe_paper_uio import PaperUIOMHE

    cfg, Td, F = Config(), 0.01, 800.0
    dyn, xs, ys, us = _nominal_data(cfg, Td, F, 60)
    mhe = PaperUIOMHE(cfg.mhe, dyn, cfg.vehicle, Td, x0=xs[0].copy())
    u_prev = np.zeros(2)
    for k in range(len(ys)):
        e = mhe.step(ys[k], u_prev)
        u_prev = us[k] if k < len(us) else u_prev
    assert e.status == "ok"
    assert e.F_fr == pytest.approx(F, rel=1e-7) and e.F_fr_raw == pytest.approx(F, rel=1e-7)
    np.testing.assert_allclose(e.x, xs[len(ys) - 1], rtol=1e-7, atol=1e-9)


def test_uio_window_qp_matches_cvxpy_on_a_random_instance() -> None:
    """The condensed window QP of the UIO form against the same problem posed directly in cvxpy
    (states as variables, the UIO transition as equality constraints), with a rejected sample."""
    import cvxpy as cp

    from tsmpc.estimation.mhe_paper_uio import PaperUIOMHE, uio_gain

    cfg, Td = Config(), 0.01
    settings = replace(cfg.mhe, x_min=(-1e3, -1e3, -1e3), x_max=(1e3, 1e3, 1e3))
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, Td)
    mhe = PaperUIOMHE(settings, dyn, cfg.vehicle, Td)
    rng = np.random.default_rng(7)
    n = 6
    A, B = dyn.matrices(np.column_stack([rng.uniform(-0.2, 0.2, n), rng.uniform(3, 15, n),
                                         rng.uniform(-0.05, 0.05, n)]))
    ys = rng.normal(size=(n + 1, 2)) * [1.0, 0.1] + [8.0, 0.0]
    us = rng.normal(size=(n, 2)) * [500.0, 0.05] + [2000.0, 0.0]
    w = np.ones(n + 1)
    w[3] = 0.0  # a rejected sample: plain model with the last F̂ there
    arrival, F_prev = np.array([8.0, 0.01, 0.02]), 300.0
    qp = mhe.build_uio(ys, us, w, A, B, arrival, F_prev)
    z = np.linalg.solve(qp.H, -qp.f)
    X = (qp.M @ z + qp.c).reshape(-1, 3)

    q, r, p = (1.0 / np.asarray(v) for v in (settings.Q, settings.R, settings.P))
    xv = [cp.Variable(3) for _ in range(n + 1)]
    wv = [cp.Variable(3) for _ in range(n)]
    cons = []
    for k in range(n):
        E = -B[k, :, 0]
        if w[k + 1] > 0:
            th = uio_gain(E)
            Pi = np.eye(3) - np.outer(E, th)
            nxt = Pi @ A[k] @ xv[k] + Pi @ B[k] @ us[k] + E * (th[0] * ys[k + 1, 0] + th[2] * ys[k + 1, 1])
        else:
            nxt = A[k] @ xv[k] + B[k] @ us[k] + E * F_prev
        cons.append(xv[k + 1] == nxt + wv[k])
    cost = cp.sum(cp.multiply(p, cp.square(xv[0] - arrival)))
    cost += sum(cp.sum(cp.multiply(q, cp.square(wk))) for wk in wv)
    cost += sum(w[k] * cp.sum(cp.multiply(r, cp.square(ys[k] - cp.hstack([xv[k][0], xv[k][2]]))))
                for k in range(n + 1))
    cp.Problem(cp.Minimize(cost), cons).solve(solver=cp.CLARABEL)
    Xc = np.array([x.value for x in xv])
    np.testing.assert_allclose(X, Xc, rtol=1e-5, atol=1e-6)


def test_cascade_selects_the_uio_form(paper_reference_path: Path) -> None:
    from tsmpc.estimation.mhe_paper_uio import PaperUIOMHE
    from tsmpc.estimation.mhe_uio import MHEUIO

    cfg = Config.preset("paper")
    sc = load_scenario(cfg, paper_reference_path)
    assert type(Cascade(cfg, "ref", sc.reference).mhe) is MHEUIO
    uio = replace(cfg, mhe=replace(cfg.mhe, form="uio"))
    assert isinstance(Cascade(uio, "ref", sc.reference).mhe, PaperUIOMHE)
    log = simulate(uio, Method.REF, sc, max_steps=20)
    assert log.termination == "completed" and np.all(np.isfinite(log.F_fr_hat))


# --- docs generator pieces ----------------------------------------------------------------------

def test_update_block_replaces_only_between_its_markers() -> None:
    from generator.paper_explained import update_block

    text = "a\n<!-- paper-explained:t:begin -->\nold\n<!-- paper-explained:t:end -->\nb\n"
    out = update_block(text, "t", "| new |\n")
    assert out == "a\n<!-- paper-explained:t:begin -->\n| new |\n<!-- paper-explained:t:end -->\nb\n"
    assert update_block(out, "t", "| new |") == out  # idempotent
    with pytest.raises(ValueError, match="markers"):
        update_block("no markers", "t", "x")


def test_design_command_prints_the_feasibility_design(tmp_path: Path) -> None:
    f = tmp_path / "c.toml"
    f.write_text('preset = "paper-as-run"\n', encoding="utf-8")
    res = CliRunner().invoke(app, ["design", "--config", str(f)])
    assert res.exit_code == 0, res.output
    assert "feasibility LMI" in res.output and "True" in res.output


# --- end to end ----------------------------------------------------------------------------------

@pytest.mark.slow
def test_paper_as_run_end_to_end(as_run: Config, paper_reference_path: Path) -> None:
    """The whole paper run with the preset (REF). Tolerances: the columns README reports inside
    the ½–2× band of Table 5 are asserted inside it; RMSE_x is documented outside it (the gains'
    speed headroom on the fastest stretch), so the test asserts that stretch and that x is within
    the band outside it; the transient bounds bracket what the analytic centre's gains give
    (δ_f / ζ ≈ −1.6: e_y peak 0.72 m, e_θ peak 10.2°; the published ≈ 1.9 m is not reached).
    The same run checks that the reference sample is counted, not timed (one run, not two: a
    module fixture would not be shared between pytest-xdist workers)."""
    from generator.paper_explained_runs import longitudinal_stretch

    from tsmpc.sim.metrics import PAPER_TABLE5, compute_metrics

    sc = load_scenario(as_run, paper_reference_path)
    log = simulate(as_run, Method.REF, sc)
    assert log.termination == "completed"
    _check_the_reference_sample_is_counted_not_timed(sc, log)
    m = compute_metrics(log)
    paper = PAPER_TABLE5["REF"]
    for k in ("y", "theta", "v", "omega"):
        assert 0.5 <= m["rmse_paper_run"][k] / paper[k] <= 2.0, (k, m["rmse_paper_run"][k])
    assert m["rmse_paper_run"]["x"] / paper["x"] > 2.0  # the documented miss
    st = longitudinal_stretch(log)
    assert st is not None and 55.0 < st.start_s < st.end_s < 85.0 and st.max_abs_m > 3.0
    assert 0.5 <= st.rmse_x_outside_m / paper["x"] <= 2.0
    # the start-up transient: positive e_y hump in the first 8 s, e_θ peak of several degrees
    t = log.t_outer - log.t_outer[0]
    ey = log.errors[t < 8.0, 1]
    assert 0.5 < ey.max() < 1.0 and 8.0 < math.degrees(np.abs(log.errors[t < 8.0, 2]).max()) < 13.0


@pytest.mark.slow
def test_nl_completes_once_the_speed_bound_leaves_headroom(as_run: Config,
                                                           paper_reference_path: Path) -> None:
    """NL's divergence with the preset is the speed shortfall on the fastest stretch (v_d ≥ 13 m/s
    from 63 to 76 s): run from 55 s (reference column 555, the car on the reference) for 30 s,
    past that stretch, NL with the preset's v_ref bound of 18 m/s leaves the road in it (|e_y| >
    5 m at 69.5 s: the full run's divergence of docs/paper.md, 69.6 s), and with the bound at
    22 m/s (nothing else changed) it completes with |e_x| below 1.5 m (measured 1.33 m; 0.9 m
    over the whole run) and RMSE_x inside the ½–2× band of Table 5 (0.40 m; 0.30 m over the whole
    run). The window costs a fifth of the whole run's ~60 s of CPU (the Python loop and CasADi)."""
    from tsmpc.sim.metrics import PAPER_TABLE5, compute_metrics

    sc = load_scenario(as_run, paper_reference_path, window=(555, 1316))
    preset = simulate(as_run, Method.NL, sc, max_steps=300)
    assert preset.termination.startswith("diverged") and 63.0 < preset.t_outer[-1] < 76.0
    cfg = replace(as_run, mpc=replace(as_run.mpc, u_max=(22.0, as_run.mpc.u_max[1])))
    log = simulate(cfg, Method.NL, sc, max_steps=300)
    assert log.termination == "completed" and log.n_outer == 300
    m = compute_metrics(log)
    assert 0.5 <= m["rmse"]["x"] / PAPER_TABLE5["NL"]["x"] <= 2.0
    assert np.abs(log.errors[:, 0]).max() < 1.5
    assert m["events"]["mpc_soft"] == 0 and m["events"]["mpc_fallback"] == 0
