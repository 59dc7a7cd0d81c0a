"""The baselines as Methods in the same cascade (issue 26): parsing, is_ts_mpc, the registry, closed
loops that complete with comfort metrics, and the acceptance command on the paper reference and
on a planned race track."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tsmpc.config import Config, Method, MPCSettings
from tsmpc.control.baselines import BASELINES, build_baseline
from tsmpc.control.cascade import Cascade, build_outer_controller
from tsmpc.errors import ConfigError
from tsmpc.robustness import robustness_scenario
from tsmpc.sim.compare import compare, load_scenario

NAMES = {"pure_pursuit": Method.PURE_PURSUIT, "stanley": Method.STANLEY, "lqr": Method.LQR,
         "ltv": Method.LTV}


def test_methods_parse_case_insensitively_and_are_not_ts_mpc() -> None:
    for text, m in NAMES.items():
        assert Method.parse(text) is m and Method.parse(f" {text.upper()} ") is m
        assert not m.is_ts_mpc
    assert [m for m in Method if m.is_ts_mpc] == [Method.FZN, Method.REF, Method.ITER]
    assert set(BASELINES) == set(NAMES.values())
    with pytest.raises(ConfigError, match="pure_pursuit, stanley, lqr, ltv"):
        Method.parse("mpc")
    with pytest.raises(ValueError, match="fzn, ref or iter"):
        MPCSettings(mode="ltv")


def test_each_baseline_speaks_the_outer_protocol(cfg: Config) -> None:
    from tsmpc.planning.circuit import builtin_circuit
    from tsmpc.synthesis.cache import load_or_design_kinematic

    kd = load_or_design_kinematic(cfg)
    ref = builtin_circuit(dt=cfg.rates.Tc)
    for m in BASELINES:
        ctl = build_outer_controller(cfg, m, kd.P, kd.S, K=kd.K)
        assert ctl.dt == cfg.rates.Tc
        res = ctl.step(np.array([0.1, -0.2, 0.01]), np.array([ref.v[0], 0.0]), ref.window(0, cfg.mpc.N + 1))
        assert res.success and res.u.shape == (2,) and res.x_pred.shape == (cfg.mpc.N + 1, 3)
        assert res.u_pred.shape == (cfg.mpc.N, 2)
        ctl.reset()
    with pytest.raises(ConfigError, match="vertex gains"):
        build_baseline(cfg, Method.LQR, kd.P, kd.S, None)
    with pytest.raises(ConfigError, match="not a baseline"):
        build_baseline(cfg, Method.REF, kd.P, kd.S, kd.K)
    assert Cascade(cfg, "stanley", ref).method is Method.STANLEY


def test_baselines_complete_a_closed_loop_with_comfort_metrics(cfg: Config) -> None:
    """60 s of the built-in circuit (the curvy part included), every baseline through the whole
    cascade: completed, tracking within 0.2 m, finite comfort metrics."""
    res = compare(cfg, load_scenario(cfg), [Method.REF, *BASELINES], None, max_steps=600)
    for name, m in res.metrics["methods"].items():
        assert m["status"] == "completed", (name, m["termination"])
        assert m["max_abs_lateral_m"] < 0.2, name
        assert all(math.isfinite(v) for v in m["comfort"].values()), name
        assert m["events"]["mpc_fallback"] == 0, name


def test_offset_start_settles_for_every_baseline(cfg: Config) -> None:
    """2 m and 0.2 rad off the path at t = 0: REF, pure pursuit, Stanley and the LTV-MPC bring
    |e_y| under 0.10 m for good. The kinematic LQR's gains are nearly dead-beat at T_c (ω gain on
    e_θ 7.4–11.3 1/s: e_θ⁺ ≈ −0.13 e_θ on the kinematic model); with the inner loop's yaw-rate lag
    and no rate limit it saturates ω at ±1.4 rad/s and may leave the road: then it must be
    reported diverged, with the reason."""
    from tsmpc.planning.circuit import builtin_circuit

    case = robustness_scenario("offset_start", cfg, builtin_circuit(dt=cfg.rates.Tc), until_s=40.0)
    res = compare(case.config, case.scenario, [Method.REF, *BASELINES], None, max_steps=400)
    for name, m in res.metrics["methods"].items():
        if name == "LQR" and m["status"] == "diverged":
            assert m["termination"].startswith("diverged: |e_y|")
            continue
        assert m["status"] == "completed", name
        assert 0.5 < m["comfort"]["settling_time_s"] < 20.0, (name, m["comfort"]["settling_time_s"])


@pytest.mark.slow
@pytest.mark.parametrize("case", ["paper", "track"])
def test_acceptance_command_runs_on_the_paper_reference_and_a_planned_track(
        case: str, tmp_path: Path, paper_reference_path: Path, tracks_dir: Path) -> None:
    """`tsmpc compare --methods ref,nl,pure_pursuit,stanley,lqr,ltv` (first 30 s) on the paper
    reference and on Monza planned at 22 m/s, 5 m/s²: every method completes or is reported
    diverged with its reason; the comfort table is written."""
    from tsmpc.cli import app

    runner = CliRunner()
    if case == "paper":
        ref = paper_reference_path
    else:
        ref = tmp_path / "monza.csv"
        res = runner.invoke(app, ["plan", str(tracks_dir / "Monza.csv"), "--v-max", "22", "--a-lat", "5",
                                  "--out", str(ref)])
        assert res.exit_code == 0, res.output
    out = tmp_path / "out"
    res = runner.invoke(app, ["compare", "--reference", str(ref), "--methods",
                              "ref,nl,pure_pursuit,stanley,lqr,ltv", "--duration", "30", "--no-plots",
                              "--out", str(out)])
    metrics = json.loads((out / "metrics.json").read_text())
    assert list(metrics["methods"]) == ["REF", "NL", "PURE_PURSUIT", "STANLEY", "LQR", "LTV"]
    for name, m in metrics["methods"].items():
        assert m["status"] in ("completed", "diverged")
        if m["status"] == "diverged":
            assert m["termination"].startswith(("diverged", "plant diverged")), name
            assert name in res.output
    assert res.exit_code == (1 if metrics["diverged"] else 0), res.output
    assert "PURE_PURSUIT" in (out / "comfort.md").read_text()
    assert "table-comfort" in (out / "report.html").read_text()


def test_a_run_folder_with_baselines_reads_back(cfg: Config, tmp_path: Path) -> None:
    """Method names with an underscore (PURE_PURSUIT) survive timeseries.npz's `<METHOD>_<signal>`
    keys: load_run gives back every method's log (what `tsmpc animate` reads)."""
    from tsmpc.sim.run_dir import load_run

    compare(cfg, load_scenario(cfg), [Method.PURE_PURSUIT, Method.REF], tmp_path, plots=False,
            max_steps=20)
    run = load_run(tmp_path)
    assert list(run.logs) == ["PURE_PURSUIT", "REF"]
    assert run.logs["PURE_PURSUIT"].u_c.shape == (20, 2)
    assert np.all(np.isnan(run.logs["PURE_PURSUIT"].x_pred[:, 1:]))  # a law has no prediction
