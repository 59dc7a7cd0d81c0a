"""Metrics and tables on a synthetic log with known errors (SPEC §11)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tsmpc.report.tables import rmse_csv, rmse_latex, rmse_markdown
from tsmpc.sim.log import RunLog, save_logs_mat, save_logs_npz
from tsmpc.sim.metrics import PAPER_TABLE5, compute_metrics, timing_stats


def _log(K: int = 100, n_in: int = 10) -> RunLog:
    M = K * n_in
    t = np.arange(K) * 0.1
    ref = np.zeros((K, 5))
    ref[:, 3] = 10.0
    ref[:, 4] = 0.1
    state_outer = np.zeros((K, 6))
    state_outer[:, 3] = 10.0 - 0.3 * np.where(np.arange(K) % 2, 1, -1)  # |v_d − v| = 0.3
    state_outer[:, 5] = 0.1
    errors = np.zeros((K, 3))
    errors[:, 0] = 0.5
    errors[:, 1] = np.where(np.arange(K) % 2, 0.2, -0.2)
    errors[-1, 1] = -0.9
    state = np.zeros((M, 6))
    state[:, 4] = 0.01
    est = np.zeros((M, 3))
    est[:, 1] = 0.01 + 0.002
    s = np.full(K, "optimal", dtype="<U16")
    s[3] = "soft"
    return RunLog(
        method="REF", scenario="synthetic", Tc=0.1, Td=0.01, t_outer=t, ref=ref,
        state_outer=state_outer, errors=errors, errors_measured=errors, u_c=np.zeros((K, 2)),
        x_pred=np.zeros((K, 41, 3)), mpc_time_s=np.linspace(1e-4, 2e-4, K), mpc_status=s,
        mpc_iterations=np.ones(K, dtype=np.int64), mpc_qp_iterations=np.ones(K, dtype=np.int64),
        mpc_clipped=np.zeros(K, dtype=np.int64), t_inner=np.arange(M) * 0.01, state=state,
        estimate=est, measurement=np.zeros((M, 2)), F_fr_hat=np.full(M, 2700.0),
        F_fr_true=np.full(M, 2680.0), F_fr_raw=np.zeros(M), mu_road=np.full(M, 0.9),
        command=np.zeros((M, 2)), saturated=np.zeros(M, dtype=bool), mhe_time_s=np.full(M, 1e-4),
        lqr_time_s=np.full(M, 1e-5), mhe_status=np.full(M, "ok", dtype="<U16"), wall_s=2.0,
        events={"mpc_soft": 1},
    )


def test_metrics_of_known_errors() -> None:
    m = compute_metrics(_log())
    assert m["rmse"]["x"] == pytest.approx(0.5)
    assert m["rmse"]["y"] == pytest.approx(np.sqrt((99 * 0.04 + 0.81) / 100))
    assert m["rmse"]["v"] == pytest.approx(0.3)
    assert m["rmse"]["omega"] == pytest.approx(0.0)
    assert m["max_abs_lateral_m"] == pytest.approx(0.9)
    assert m["friction_rmse_N"] == pytest.approx(20.0)
    assert m["slip_rmse_rad"] == pytest.approx(0.002)
    assert m["realtime_factor"] == pytest.approx(10.0 / 2.0)
    assert m["mpc_ms"]["median"] == pytest.approx(0.15)
    assert m["events"] == {"mpc_soft": 1}


def test_timing_stats_in_ms() -> None:
    st = timing_stats(np.arange(1, 101) * 1e-3)
    assert st["median"] == pytest.approx(50.5) and st["max"] == pytest.approx(100.0)
    assert st["p99"] == pytest.approx(99.01)


def test_tables_put_paper_rows_beside_ours() -> None:
    metrics = {"methods": {"REF": compute_metrics(_log())}}
    csv = rmse_csv(metrics, with_paper=True).splitlines()
    assert csv[0] == "approach,x,y,theta,v,omega"
    assert csv[2].startswith("REF (paper),0.501")
    assert len(rmse_csv(metrics, with_paper=False).splitlines()) == 2
    md = rmse_markdown(metrics, with_paper=True)
    assert f"| REF (paper) | {PAPER_TABLE5['REF']['x']:.3f}" in md
    assert r"\begin{tabular}" in rmse_latex(metrics, with_paper=True)


def test_time_series_writers(tmp_path: Path) -> None:
    import scipy.io

    log = _log()
    save_logs_npz({"REF": log}, tmp_path / "ts.npz")
    save_logs_mat({"REF": log}, tmp_path / "ts.mat")
    npz = np.load(tmp_path / "ts.npz")
    np.testing.assert_array_equal(npz["REF_errors"], log.errors)
    mat = scipy.io.loadmat(tmp_path / "ts.mat", squeeze_me=True, struct_as_record=False)
    np.testing.assert_allclose(mat["REF"].errors, log.errors)
    assert not list(tmp_path.glob(".*.tmp"))  # atomic writes leave no temporary files
