"""The paper preset, the ablation on the paper reference, the oracle ablation (checked on the run
log) and the speed-mode analysis of the inner loop (issue 13; SPEC §8, §13)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.config import Config, FrictionEstimate, TyreModel, load_config, replace
from tsmpc.control.speed_mode import speed_modes
from tsmpc.control.ts_lqr import TSLQR
from tsmpc.errors import ConfigError
from tsmpc.estimation.mhe_uio import Estimate, EstimatorStatus
from tsmpc.models.dynamic import DynamicTS
from tsmpc.sim.compare import load_scenario
from tsmpc.sim.metrics import compute_metrics
from tsmpc.sim.simulator import Method, simulate
from tsmpc.synthesis.cache import load_or_design_dynamic
from tsmpc.vehicle.plant import Plant

PAPER_REF = {"x": 0.501, "y": 0.238, "theta": 0.016, "v": 0.251, "omega": 0.013}  # Table 5, REF


# --- the preset --------------------------------------------------------------------------------

def test_paper_preset_is_the_published_cascade() -> None:
    paper, default = Config.preset("paper"), Config()
    assert paper.lqr.speed_feedback is False and default.lqr.speed_feedback is True
    assert paper.lqr.friction_compensation is True
    assert paper.lqr.friction_estimate == FrictionEstimate.UIO
    # Everything else (weights, boxes, rates, noise) is the paper's in both.
    # The outer loop's mechanisms beyond the paper (issue 15) are off in the paper preset.
    outer = ("slip_aware", "tangent_heading", "step_average_reference")
    assert not any(getattr(paper.mpc, f) for f in outer)
    assert all(getattr(default.mpc, f) for f in outer)
    assert paper.mpc.offset_free_s == default.mpc.offset_free_s == 0.0  # offset_free.py: opt-in
    # only the named switches differ (not the whole lqr section: force limits, compensation, ...)
    # the fusion and adaptation switches (issue 21) likewise
    fusion = set(type(default.fusion).model_fields)
    assert not any(getattr(paper.fusion, f) for f in fusion)
    assert all(getattr(default.fusion, f) for f in fusion)
    assert paper.lqr.low_speed_resistance is False and default.lqr.low_speed_resistance is True
    assert paper.lqr.friction_step is False and default.lqr.friction_step is True
    assert paper.recovery.enabled is False and default.recovery.enabled is True  # issue 38
    assert paper.mhe.margin_slip_rate == 0.0 and default.mhe.margin_slip_rate > 0.0  # issue 35
    # the force limits: the published absolute [-2000, 10000] N in the paper presets, per kg in
    # ours (issue 36: they follow the mass) — the same limits at the paper's vehicle
    assert paper.lqr.force_limits(paper.vehicle) == default.lqr.force_limits(default.vehicle) == \
        (-2000.0, 10000.0)
    assert default.lqr.force_max is None and paper.lqr.force_max == 10000.0
    beyond = {"lqr": {"speed_feedback", "friction_estimate", "low_speed_resistance", "friction_step",
                      "force_min", "force_max", "force_min_per_kg", "force_max_per_kg"},
              "mpc": {*outer, "offset_free_s"},
              "fusion": fusion,
              "recovery": {"enabled"},
              "mhe": {"margin_slip_rate"},  # issue 35: the yaw-model margin
              "governor": {"enabled"}}  # issue 36: beyond the paper
    assert paper.model_dump(exclude=beyond) == default.model_dump(exclude=beyond)
    assert Config.preset("default") == default


def test_preset_from_toml_and_overrides(tmp_path: Path) -> None:
    f = tmp_path / "c.toml"
    f.write_text('preset = "paper"\n[lqr]\nspeed_time_constant = 0.5\n', encoding="utf-8")
    c = load_config(f)
    assert c.lqr.speed_feedback is False and c.lqr.speed_time_constant == 0.5
    assert load_config(f, preset="default").lqr.speed_feedback is True  # the argument wins
    assert load_config(None, preset="paper") == Config.preset("paper")
    f.write_text('preset = "papr"\n', encoding="utf-8")
    with pytest.raises(ConfigError, match=r"papr.*allowed: default, paper"):
        load_config(f)
    with pytest.raises(ConfigError, match="unknown preset"):
        Config.preset("fast")


def test_cli_preset_option(tmp_path: Path) -> None:
    runner = CliRunner()
    res = runner.invoke(app, ["run", "--preset", "nope", "--duration", "0.5", "--out", str(tmp_path / "a")])
    assert res.exit_code == 2 and "unknown preset 'nope'" in res.output
    out = tmp_path / "b"
    res = runner.invoke(app, ["run", "--preset", "paper", "--duration", "1", "--no-plots", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert load_config(out / "config.toml").lqr == Config.preset("paper").lqr


# --- the oracle, on the log --------------------------------------------------------------------

def _replay_commands(cfg: Config, log, states: np.ndarray, F_fr: np.ndarray, settings) -> np.ndarray:
    """Re-run the inner law on logged inputs: state fed to the law per inner step, F̂ per step."""
    dd = load_or_design_dynamic(cfg)
    lqr = TSLQR(dd.K, DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td), cfg.vehicle, settings,
                cfg.rates.Td, bandwidth=cfg.dynamic_lmi.filter_bandwidth)
    n_in = cfg.rates.inner_per_outer
    out = np.zeros((len(states), 2))
    for m, (xs, F) in enumerate(zip(states, F_fr, strict=True)):
        e = Estimate(x=xs, F_fr=float(F), F_fr_raw=float(F), status=EstimatorStatus.OK, solve_time_s=0.0)
        v_ref, w_ref = log.u_c[m // n_in]
        cmd = lqr.step(e, float(v_ref), float(w_ref))
        out[m] = cmd.F_xR, cmd.delta
    return out


def test_oracle_feeds_the_true_state_and_disables_compensation(cfg: Config) -> None:
    """The logged commands of an oracle run are exactly the law applied to the logged *true*
    state with no F̂ added; the same law on the logged MHE estimates, or with compensation of
    the logged F̂, does not reproduce them. A normal run is the law on the estimates + F̂. (Without
    the steering-offset fit: the servo takes its correction off the law's angle, on a calibrated car
    a third of the fit's sub-mrad wander, which the replay of the law alone does not have.)"""
    cfg = replace(cfg, fusion=replace(cfg.fusion, steering_offset=False))
    sc = load_scenario(cfg)
    steps = 30
    olog = simulate(cfg, Method.REF, sc, oracle=True, max_steps=steps)
    no_comp = replace(cfg.lqr, friction_compensation=False)
    true_v_a_w = olog.state[:, 3:6]
    np.testing.assert_allclose(_replay_commands(cfg, olog, true_v_a_w, np.zeros(len(true_v_a_w)), no_comp),
                               olog.command, rtol=0, atol=1e-9)
    # The estimates differ from the truth (noise, slip), so feeding them would show in the commands.
    assert not np.allclose(_replay_commands(cfg, olog, olog.estimate, np.zeros(len(true_v_a_w)), no_comp),
                           olog.command, atol=1e-3)
    assert np.max(np.abs(olog.F_fr_hat)) > 100.0  # the estimator ran and had something to add
    with_comp = _replay_commands(cfg, olog, true_v_a_w, olog.F_fr_hat, cfg.lqr)
    assert np.max(np.abs(with_comp[:, 0] - olog.command[:, 0])) > 100.0
    # Control: the normal run is the law on the MHE estimates plus its window F̂.
    log = simulate(cfg, Method.REF, sc, max_steps=steps)
    np.testing.assert_allclose(_replay_commands(cfg, log, log.estimate, log.F_fr_hat, cfg.lqr),
                               log.command, rtol=0, atol=1e-9)


# --- the speed mode: analysis against the nonlinear plant --------------------------------------

@pytest.mark.parametrize("speed_feedback", [False, True])
def test_speed_mode_time_constant_matches_the_plant(cfg: Config, speed_feedback: bool) -> None:
    """The 63 % time of a 0.5 m/s v_ref step predicted by ``speed_modes`` (linearised loop,
    constant rolling resistance) equals the one measured on the nonlinear plant (RK4, linear
    tyres, μ(road) = μ_o, true state fed back) within 10 % (linearisation of a finite step,
    10 ms sampling of the crossing)."""
    dd = load_or_design_dynamic(cfg)
    dyn = DynamicTS(cfg.dynamic_box, cfg.vehicle, cfg.rates.Td)
    v0, dv = 10.0, 0.5
    z = np.array([0.0, v0, 0.0])
    K = np.tensordot(dyn.premise_box.memberships(z), dd.K, axes=(0, 0))[None]
    lam, tau = cfg.dynamic_lmi.filter_bandwidth, cfg.lqr.speed_time_constant
    mode = speed_modes(K, z[None], cfg.vehicle, lam, tau)[0]
    predicted = mode.with_speed_feedback if speed_feedback else mode.static_gain
    st = replace(cfg.lqr, speed_feedback=speed_feedback, friction_compensation=False)
    lqr = TSLQR(dd.K, dyn, cfg.vehicle, st, cfg.rates.Td)
    plant = Plant(cfg.vehicle, replace(cfg.tyre, model=TyreModel.LINEAR), cfg.rates.h)
    x = np.array([0.0, 0.0, 0.0, v0, 0.0, 0.0])
    mu, n_pl = cfg.vehicle.mu_nominal, cfg.rates.plant_per_inner
    for _ in range(1000):  # settle at v0 first (10 s)
        cmd = lqr.step(Estimate(x[3:6].copy(), 0.0, 0.0, EstimatorStatus.OK, 0.0), v0, 0.0)
        x = plant.step(x, np.array([cmd.F_xR, cmd.delta]), mu, n_pl)
    assert x[3] == pytest.approx(v0, abs=1e-3)
    t = 0.0
    while x[3] < v0 + 0.632 * dv and t < 30.0:
        cmd = lqr.step(Estimate(x[3:6].copy(), 0.0, 0.0, EstimatorStatus.OK, 0.0), v0 + dv, 0.0)
        x = plant.step(x, np.array([cmd.F_xR, cmd.delta]), mu, n_pl)
        t += cfg.rates.Td
    assert t == pytest.approx(predicted, rel=0.10)
    # And the feed-forward scheduled at the reference is far slower than what the MPC assumes.
    assert mode.reference_scheduled > 5.0 > predicted


# --- the paper run (slow) ----------------------------------------------------------------------

@pytest.fixture(scope="module")
def ablation(paper_reference_path: Path) -> dict[str, dict]:
    paper = Config.preset("paper")
    rows = {
        "paper": (paper, False),
        "speed_feedback": (replace(paper, lqr=replace(paper.lqr, speed_feedback=True)), False),
        "default": (Config(), False),
        "oracle": (Config(), True),
    }
    out = {}
    for name, (c, oracle) in rows.items():
        log = simulate(c, Method.REF, load_scenario(c, paper_reference_path), oracle=oracle)
        m = compute_metrics(log)
        m["log"] = log
        out[name] = m
    return out


@pytest.mark.slow
def test_paper_preset_completes_the_paper_run(ablation: dict[str, dict]) -> None:
    """Acceptance of issue 13: no divergence, no soft or fallback MPC step; RMSE_v within
    [½×, 2×] of the paper's REF row and no column worse than 2× the paper. (x, y, θ, ω land
    *below* ½× — the lateral columns do not depend on the speed loop at all, README.)"""
    m = ablation["paper"]
    log = m["log"]
    assert log.termination == "completed"
    assert log.events["mpc_soft"] == 0 and log.events["mpc_fallback"] == 0
    r = m["rmse"]
    assert 0.5 * PAPER_REF["v"] <= r["v"] <= 2.0 * PAPER_REF["v"]
    for k, ref in PAPER_REF.items():
        assert r[k] <= 2.0 * ref, k
    # and no column more than 1.5× what this preset measures (the README's ablation row:
    # x 0.134, y 0.108, θ 0.0060, v 0.141, ω 0.0036, max |e_y| 0.45): the band above alone is
    # 3.5–7× looser than the run
    measured = {"x": 0.134, "y": 0.108, "theta": 0.0060, "v": 0.141, "omega": 0.0036}
    for k, v in measured.items():
        assert r[k] <= 1.5 * v, (k, r[k])
    assert m["max_abs_lateral_m"] < 1.5 * 0.45


@pytest.mark.slow
def test_ablation_order(ablation: dict[str, dict]) -> None:
    """Each added part: the speed-error feedback lowers RMSE_x (by ≥ 3×) and RMSE_v; the
    MHE-window friction estimate (= default) keeps RMSE_x within 5 % (it does *not* lower it; it
    lowers the compensated estimate's error and the force-command noise); the oracle (true
    state, no compensation) has a larger RMSE_x than the default (the compensation matters)."""
    x = {k: m["rmse"]["x"] for k, m in ablation.items()}
    assert x["speed_feedback"] < x["paper"] / 3.0
    assert ablation["speed_feedback"]["rmse"]["v"] < ablation["paper"]["rmse"]["v"]
    assert x["default"] <= 1.05 * x["speed_feedback"]
    fb, df = ablation["speed_feedback"]["log"], ablation["default"]["log"]
    err_raw = np.sqrt(np.mean((fb.F_fr_raw - fb.F_fr_true) ** 2))
    err_win = np.sqrt(np.mean((df.F_fr_hat - df.F_fr_true) ** 2))
    assert err_win < err_raw / 2.0  # measured 227 N vs 523 N RMS
    assert np.std(np.diff(df.command[:, 0])) < np.std(np.diff(fb.command[:, 0]))
    assert x["oracle"] > 2.0 * x["default"]
    for m in ablation.values():
        assert m["log"].termination == "completed"
        assert m["log"].events["mpc_soft"] == 0 and m["log"].events["mpc_fallback"] == 0


@pytest.mark.slow
def test_offset_start_makes_the_methods_differ(cfg: Config, paper_reference_path: Path) -> None:
    """The named scenario of the README where the outer-loop methods differ: over the start-up
    transient (20 s) FZN and REF differ by far more than 5 % in RMSE_x (measured 0.43 vs 0.26)."""
    from tsmpc.robustness import ROBUSTNESS_SCENARIOS, apply_robustness

    assert "offset_start" in ROBUSTNESS_SCENARIOS
    c, sc = apply_robustness("offset_start", cfg, load_scenario(cfg, paper_reference_path))
    assert sc.initial_error == (2.0, 0.2)
    x = {m: compute_metrics(simulate(c, m, sc, max_steps=200))["rmse"]["x"] for m in (Method.FZN, Method.REF)}
    assert x[Method.FZN] > 1.2 * x[Method.REF]


def test_sweep_base_config_accepts_a_preset(tmp_path: Path) -> None:
    from tsmpc.sweep import base_config, load_sweep

    base = 'preset = "paper"\n[lqr]\nspeed_time_constant = 0.7\n'
    (tmp_path / "base.toml").write_text(base, encoding="utf-8")
    (tmp_path / "s.toml").write_text('name = "p"\nbase_config = "base.toml"\n[grid]\nmethod = ["ref"]\n',
                                     encoding="utf-8")
    c = base_config(load_sweep(tmp_path / "s.toml"))
    assert c.lqr.speed_feedback is False and c.lqr.speed_time_constant == 0.7
