"""Time base of the paper format (issue 15): the column period is measured from the data, a file
sampled at 0.05 s is read at 0.05 s (or refused with --dt 0.1), and the paper's Table 5 is only
printed beside the paper's own run."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.config import Config
from tsmpc.errors import DataFormatError
from tsmpc.planning.paper_format import (
    PAPER_RUN_WINDOW,
    column_period,
    load_paper_reference,
    save_paper_format,
)
from tsmpc.sim.compare import load_scenario


@pytest.fixture(scope="module")
def file_005(paper_reference_path: Path, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The paper's file resampled at 0.05 s and written in the same 6-row format."""
    full = load_paper_reference(paper_reference_path, window=None)
    out = tmp_path_factory.mktemp("tb") / "paper_50ms.csv"
    save_paper_format(full.resample(0.05), out)
    return out


def test_the_paper_file_measures_0_1_s(paper_reference_path: Path) -> None:
    data = np.loadtxt(paper_reference_path, delimiter=",")
    t_pos, t_ang = column_period(data)
    assert t_pos == pytest.approx(0.1, rel=1e-3) and t_ang == pytest.approx(0.1, rel=1e-3)
    assert load_paper_reference(paper_reference_path).dt == pytest.approx(0.1)


def test_a_0_05_s_file_is_detected_and_covers_the_same_run(file_005: Path,
                                                           paper_reference_path: Path) -> None:
    cfg = Config()
    sc = load_scenario(cfg, file_005)
    ref = sc.reference
    assert ref.dt == pytest.approx(0.05)
    assert sc.meta["paper_reference"] is False and sc.meta["paper_format"] is True
    paper = load_scenario(cfg, paper_reference_path)
    assert paper.meta["paper_reference"] is True
    # same time span, same path: the speed row is driven at its own speed, not at half of it
    assert ref.t[0] == pytest.approx(paper.reference.t[0]) and ref.t[-1] == pytest.approx(
        paper.reference.t[-1])
    np.testing.assert_allclose(ref.resample(0.1).x, paper.reference.x, atol=1e-6)
    # --dt that agrees is accepted; one the data contradict is refused naming --dt
    assert load_scenario(cfg, file_005, dt=0.05).reference.dt == pytest.approx(0.05)
    with pytest.raises(DataFormatError, match=r"--dt 0.1 s disagrees .* pass --dt 0.05"):
        load_scenario(cfg, file_005, dt=0.1)


def test_inconsistent_rows_are_refused_without_dt(tmp_path: Path, paper_reference_path: Path) -> None:
    data = np.loadtxt(paper_reference_path, delimiter=",")
    data[5] *= 2.0  # ω row twice what the headings say: positions imply 0.1 s, Δθ/ω 0.05 s
    f = tmp_path / "bad.csv"
    f.write_text("\n".join(",".join(f"{v:.10g}" for v in r) for r in data) + "\n")
    with pytest.raises(DataFormatError, match="cannot tell the column period"):
        load_paper_reference(f, window=None)
    assert load_paper_reference(f, window=PAPER_RUN_WINDOW, dt=0.1).dt == pytest.approx(0.1)


@pytest.mark.slow
def test_cli_runs_the_0_05_s_file_without_the_paper_rows(file_005: Path, tmp_path: Path) -> None:
    res = CliRunner().invoke(app, ["run", "--reference", str(file_005), "--duration", "8",
                                   "--out", str(tmp_path / "o"), "--no-plots"])
    assert res.exit_code == 0, res.output
    assert "(paper)" not in res.output
    bad = CliRunner().invoke(app, ["run", "--reference", str(file_005), "--dt", "0.1",
                                   "--out", str(tmp_path / "p")])
    assert bad.exit_code == 2 and "--dt" in bad.output


# --- the time base reaches the controller (issue 20) ------------------------------------------

def _convert(ref, dt: float):
    """``ref`` converted to period ``dt`` the way a planner would have written it: v and ω of
    the step into each sample interpolated, the pose integrated with the paper's convention
    θ(k) = θ(k−1) + ω(k)T, x(k) = x(k−1) + v(k) cos θ(k) T (SPEC §10)."""
    from tsmpc.planning.planner import integrate_pose
    from tsmpc.planning.reference import Reference

    t = ref.t[0] + np.arange(0.0, ref.duration + 1e-9, dt)
    mid_src = ref.t - 0.5 * ref.dt
    v = np.interp(t - 0.5 * dt, mid_src, ref.v)
    w = np.interp(t - 0.5 * dt, mid_src, ref.omega)
    x, y, th = integrate_pose(ref.x[0], ref.y[0], ref.theta[0], v, w, dt)
    return Reference(t, x, y, th, v, w, np.where(v > 1e-6, w / np.maximum(v, 1e-6), 0.0))


def test_heading_lag_is_half_the_references_own_period() -> None:
    """Under the planners' convention θ_d lags the tangent by T/2 of the period the reference
    was *made* at, also after resampling; a reference whose θ_d is the tangent has no lag."""
    from tsmpc.planning.circuit import builtin_circuit
    from tsmpc.planning.reference import Reference

    for dt in (0.02, 0.05, 0.1):
        ref = builtin_circuit(dt=dt)
        assert ref.heading_lag() == pytest.approx(dt / 2, rel=0.02)
        assert ref.resample(0.1).heading_lag() == pytest.approx(dt / 2, rel=0.02)
    # a circle of radius 50 m at 10 m/s whose heading is the exact tangent
    t = np.arange(0, 20, 0.1)
    a = t * 10 / 50
    exact = Reference(t, 50 * np.sin(a), 50 - 50 * np.cos(a), a, np.full(t.size, 10.0),
                      np.full(t.size, 0.2), np.full(t.size, 0.02))
    assert abs(exact.heading_lag()) < 1e-9
    np.testing.assert_allclose(exact.tangent_heading(), a, atol=1e-12)
    # its step averages: the chord of each step and the tangent's turn over it
    avg = exact.step_averages()
    np.testing.assert_allclose(avg.omega, 0.2, rtol=1e-9)
    np.testing.assert_allclose(avg.v[:-1], 2 * 50 * np.sin(0.02 / 2) / 0.1, rtol=1e-9)


@pytest.mark.slow
@pytest.mark.parametrize("source", ["builtin", "paper"])
def test_the_same_path_at_20_50_100_ms_tracks_alike(source: str, paper_reference_path: Path) -> None:
    """Issue 20: a path sampled at 20, 50 or 100 ms (the controller resamples it to T_c) is
    tracked with RMSE y within 15 % of the 100 ms run (the tangent heading and the MPC's step
    averages come from the geometry, not from the sample period). ``paper``: the paper's own file
    at 100 ms, converted to 50 and 20 ms as a planner would have written them."""
    from tsmpc.planning.circuit import builtin_circuit
    from tsmpc.scenarios import paper_friction_profile
    from tsmpc.sim.metrics import compute_metrics
    from tsmpc.sim.simulator import Method, Scenario, simulate

    cfg = Config()
    base = load_paper_reference(paper_reference_path) if source == "paper" else None
    rmse = {}
    for dt in (0.1, 0.05, 0.02):
        if source == "builtin":
            ref = builtin_circuit(dt=dt)
        else:
            ref = base if dt == 0.1 else _convert(base, dt)
        m = compute_metrics(simulate(cfg, Method.REF, Scenario(f"{source}-{dt}", ref,
                                                               paper_friction_profile())))
        assert m["termination"] == "completed"
        rmse[dt] = m["rmse"]["y"]
    for dt in (0.05, 0.02):
        # A time-base error makes the finer-sampled run *worse* (the lag of θ_d was a steady offset
        # in every corner: 2.5× at 50 ms). Better is allowed by more: the paper file converted to
        # 50/20 ms interpolates v and ω between its samples, a slightly smoother path than the
        # 100 ms file's steps (Δω std 0.0032 vs 0.0035 rad/s), tracked 12–17 % tighter (measured
        # over seeds 0–4: 50 ms −17.2, −13.7, −13.6, −14.6, −15.2 %; 20 ms −11.6 … −15.5 %).
        assert -0.25 <= rmse[dt] / rmse[0.1] - 1 <= 0.15, rmse
    assert rmse[0.1] < (0.006 if source == "paper" else 0.004), rmse  # measured 0.0048 / 0.0027
