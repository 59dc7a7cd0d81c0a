"""A plan the vehicle cannot drive is capped (one line) or, with --strict-plan, refused before any
work (issue 36 item 2; tsmpc.planning.feasibility)."""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from _paths import circle_window
from tsmpc.cli import app
from tsmpc.config import Config
from tsmpc.errors import ConfigError
from tsmpc.planning.feasibility import GRIP_MARGIN, check_plan, feasible_plan
from tsmpc.planning.reference import Reference
from tsmpc.planning.retime import force_budget_acceleration, path_curvature
from tsmpc.scenarios import paper_friction_profile
from tsmpc.sim import experiment

runner = CliRunner()
R, V = 20.0, 14.0  # a 20 m circle at 14 m/s: 9.8 m/s² lateral, above 0.6 x 0.9 g = 5.3 m/s²


def _circle(n: int = 300, v: float = V) -> Reference:
    w = circle_window(R, v, 0.1, n, tangent_convention=False)
    return Reference(np.arange(n) * 0.1, w.x, w.y, w.theta, w.v, w.omega, w.kappa)


def _feasible(ref: Reference, cfg: Config, **kw: object) -> tuple[Reference, object, str]:
    return feasible_plan(ref, cfg.vehicle, cfg.tyre, cfg.lqr, paper_friction_profile(), **kw)  # type: ignore[arg-type]


def test_lateral_grip_beyond_the_margin_is_capped_along_the_same_path(cfg: Config) -> None:
    ref = _circle()
    check = check_plan(ref, cfg.vehicle, cfg.tyre, cfg.lqr, paper_friction_profile())
    a_lat = GRIP_MARGIN * cfg.tyre.mu_tyre * cfg.vehicle.g
    assert check.limit == "lateral grip" and check.demand == pytest.approx(V * V / R)
    assert check.allowed == pytest.approx(a_lat)
    out, _, line = _feasible(ref, cfg)
    assert "\n" not in line and line.startswith("plan capped") and "lateral grip" in line
    lat = out.v * out.v * np.abs(path_curvature(out))
    assert lat.max() <= a_lat * 1.01  # the resampling keeps peaks within a per cent (feasibility._TOL)
    assert out.v.max() == pytest.approx(np.sqrt(a_lat * R), rel=1e-3)
    # the same path: every capped sample lies on the circle, or on a chord between two of the
    # original samples (linear resampling: the sagitta ds²/8R of a 1.4 m step)
    assert np.abs(np.hypot(out.x, out.y - R) - R).max() <= (V * 0.1) ** 2 / (8 * R) * 1.01
    assert check_plan(out, cfg.vehicle, cfg.tyre, cfg.lqr, paper_friction_profile()).ok


def test_the_capped_plan_brakes_before_a_corner_no_harder_than_the_plan(cfg: Config) -> None:
    """A straight braking at 2 m/s² from 17.8 to 14 m/s, then 14 m/s into the 20 m circle: the speed
    comes down to the corner's cap on the straight, braking at most as hard as the plan itself
    (2 m/s²), and the corner is within the cap."""
    vs = np.concatenate([np.linspace(V + 3.8, V, 20), np.full(30, V)])  # 0.2 m/s per 0.1 s step
    xs = np.concatenate([[0.0], np.cumsum(0.5 * (vs[1:] + vs[:-1]) * 0.1)])
    xs -= xs[-1] + V * 0.1  # the straight ends one step before the circle's start at x = 0
    c = _circle(300)
    z = np.zeros(vs.size)
    v = np.concatenate([vs, c.v])
    k = np.concatenate([z, c.kappa])
    ref = Reference(np.arange(v.size) * 0.1, np.concatenate([xs, c.x]), np.concatenate([z, c.y]),
                    np.concatenate([z, c.theta]), v, v * k, k)
    out, _, line = _feasible(ref, cfg)
    assert line.startswith("plan capped")
    dv = np.diff(out.v) / out.dt
    assert dv.min() >= -2.0 * 1.01  # the plan's own hardest braking
    cap = np.sqrt(GRIP_MARGIN * 0.9 * 9.81 * R)
    on_circle = out.x > 0.0
    assert (out.v[on_circle] <= cap * 1.01).all()
    assert out.v[0] > cap + 3.0  # the straight starts fast: it brakes along it, not at the corner


def test_braking_inside_a_corner_shares_the_grip_with_the_corner(cfg: Config) -> None:
    """The friction circle: on the 20 m circle, 10 m/s (5.0 m/s² lateral, within the 5.3 m/s²
    margin) braking at 2.5 m/s² to 8 m/s, then 8 m/s: together 5.6 m/s², beyond it. The check names
    the combined grip; the capped plan keeps sqrt(lateral² + longitudinal²) within the margin on
    every sample (without the friction circle in the re-timing it kept the corner's braking)."""
    c = _circle(300)
    v = np.concatenate([np.linspace(10.0, 8.0, 9), np.full(291, 8.0)])  # 0.25 m/s per 0.1 s step
    s = np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * 0.1)])
    ang = s / R  # the same circle, driven at these speeds
    ref = Reference(np.arange(v.size) * 0.1, R * np.sin(ang), R - R * np.cos(ang), ang, v, v / R,
                    np.full(v.size, 1.0 / R))
    a_lat = GRIP_MARGIN * cfg.tyre.mu_tyre * cfg.vehicle.g
    check = check_plan(ref, cfg.vehicle, cfg.tyre, cfg.lqr, paper_friction_profile())
    assert check.limit == "combined grip" and check.demand == pytest.approx(np.hypot(5.0, 2.5), rel=1e-3)
    out, _, line = _feasible(ref, cfg)
    assert line.startswith("plan capped") and "combined grip" in line
    lat = out.v * out.v * np.abs(path_curvature(out))
    along = np.diff(out.v) / out.dt
    assert np.hypot(lat[:-1], along).max() <= a_lat * 1.02
    assert check_plan(out, cfg.vehicle, cfg.tyre, cfg.lqr, paper_friction_profile()).ok
    assert out.v.max() < 10.0 and c.kappa[0] == pytest.approx(1.0 / R)


class _Patch:
    """μ(road) 0.9 with 0.3 on 60 m ≤ s < 100 m of the path (and 0.1 for 0.5 s at t = 5 s)."""

    def mu(self, t: float, s: float = 0.0) -> float:
        return 0.3 if 60.0 <= s < 100.0 else (0.1 if 5.0 <= t < 5.5 else 0.9)


def test_grip_that_follows_the_road_caps_where_the_road_is_slippery_only(cfg: Config) -> None:
    """A 40 m patch of μ 0.3 on a 20 m circle at 7 m/s (2.45 m/s², within 0.6 x 0.9 g but not
    0.6 x 0.3 g): capped on the patch and on the way into it, not elsewhere; a 0.5 s dip (shorter
    than SUSTAINED_S) changes nothing."""
    slow = _circle(300, V / 2)
    tyre = cfg.tyre.model_copy(update={"scale_grip_with_road": True})
    out, check, line = feasible_plan(slow, cfg.vehicle, tyre, cfg.lqr, _Patch())  # type: ignore[arg-type]
    assert check.limit == "lateral grip" and check.mu_grip == pytest.approx(0.3)
    assert "(0.6 x mu 0.3 x g)" in line
    s_out = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(out.x), np.diff(out.y)))])
    # within one original step (0.7 m) of either edge a resampled sample interpolates across it
    on = (s_out >= 60.7) & (s_out < 99.3)
    assert (out.v[on] <= np.sqrt(GRIP_MARGIN * 0.3 * 9.81 * R) * 1.01).all()
    assert out.v[s_out < 30.0].min() == pytest.approx(7.0)
    assert out.v[s_out > 130.0].min() == pytest.approx(7.0)
    dip_only = feasible_plan(slow, cfg.vehicle, tyre, cfg.lqr,
                             type("Dip", (), {"mu": lambda self, t, s=0.0: 0.1 if 5.0 <= t < 5.5 else 0.9})())
    assert dip_only[0] is slow and dip_only[1].ok  # type: ignore[attr-defined]


def test_a_plan_within_the_limits_is_returned_unchanged_in_every_preset() -> None:
    slow = _circle()
    slow = Reference(slow.t, slow.x, slow.y, slow.theta, slow.v * 0.5, slow.omega * 0.5, slow.kappa)
    for preset in ("default", "paper", "paper-as-run"):
        c = Config.preset(preset)
        out, check, line = _feasible(slow, c)
        assert out is slow and check.ok and line == ""  # type: ignore[attr-defined]


def test_strict_refuses_naming_the_limit(cfg: Config) -> None:
    with pytest.raises(ConfigError, match=re.escape("lateral grip: lateral acceleration 9.80 m/s² > 5.30")):
        _feasible(_circle(), cfg, strict=True)


def test_acceleration_beyond_the_force_budget_is_capped(cfg: Config) -> None:
    n = 200
    v = np.minimum(1.0 + 6.0 * np.arange(n) * 0.1, 14.0)  # 6 m/s², the budget is 4.3
    x = np.concatenate([[0.0], np.cumsum(v[1:] * 0.1)])
    z = np.zeros(n)
    ref = Reference(np.arange(n) * 0.1, x, z, z, v, z, z)
    out, check, line = _feasible(ref, cfg)
    assert check.limit == "force budget" and "force budget" in line  # type: ignore[attr-defined]
    # at each speed at most the force budget on the run's highest mu(road) (the paper's 0.9 + 0.002)
    a = force_budget_acceleration(cfg.vehicle, cfg.lqr, 0.902)
    allowed = np.array([a(float(s)) for s in out.v[:-1]])
    assert (np.diff(out.v) / out.dt <= allowed * 1.01).all()
    assert out.v.max() == pytest.approx(14.0) and out.duration > ref.duration


def test_the_published_reference_is_exempt(paper_reference_path: Path) -> None:
    """Its single-sample speed jump (8 m/s² at 2.5 s) exceeds the force budget: tracked as published."""
    exp = experiment.prepare(Config(), ["ref"], reference=paper_reference_path, duration=1.0)
    assert "tracked as it is" in exp.plan_note and "force budget" in exp.plan_note
    assert "plan_capped" not in exp.scenario.meta


def _write(tmp_path: Path) -> Path:
    path = tmp_path / "circle.csv"
    _circle().to_csv(path)
    return path


def test_prepare_caps_and_records_it(tmp_path: Path) -> None:
    exp = experiment.prepare(Config(), ["ref"], reference=_write(tmp_path))
    assert exp.plan_note.startswith("plan capped") and "lateral grip" in exp.plan_note
    assert exp.scenario.meta["plan_capped"]["limit"] == "lateral grip"
    assert exp.scenario.reference.v.max() < V


def test_run_caps_with_one_unwrapped_line(tmp_path: Path) -> None:
    out = tmp_path / "out"
    res = runner.invoke(app, ["run", "--reference", str(_write(tmp_path)), "--duration", "1", "--no-plots",
                              "--out", str(out)])
    assert res.exit_code == 0, res.output
    capped = [ln for ln in res.output.splitlines() if "plan capped" in ln]
    assert len(capped) == 1 and capped[0].startswith("plan capped to the vehicle's limits: lateral grip")
    assert capped[0].endswith("--strict-plan refuses instead"), res.output  # one line, not wrapped


def test_run_strict_plan_refuses_before_any_work(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    def no_work(*_a: object, **_k: object) -> None:
        raise AssertionError("design or compile work before the plan check")

    import tsmpc.cli.compare as cli_compare
    from tsmpc import kernels

    monkeypatch.setattr(cli_compare, "design_status", no_work)
    monkeypatch.setattr(kernels, "warmup", no_work)
    out = tmp_path / "out"
    t0 = time.perf_counter()
    res = runner.invoke(app, ["run", "--reference", str(_write(tmp_path)), "--strict-plan", "--no-plots",
                              "--out", str(out)])
    seconds = time.perf_counter() - t0
    assert res.exit_code == 2, res.output
    err = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(err) == 1 and "--strict-plan" in err[0] and "lateral grip" in err[0], res.output
    assert not out.exists()
    assert seconds < 10.0, seconds  # a refusal before the designs and kernels: no compile


def test_plan_caps_with_one_line_or_refuses(tracks_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "zandvoort.csv"
    args = ["plan", str(tracks_dir / "Zandvoort.csv"), "--out", str(out), "--v-max", "30", "--a-lat", "8"]
    res = runner.invoke(app, args)
    assert res.exit_code == 0, res.output
    capped = [ln for ln in res.output.splitlines() if "plan capped" in ln]
    assert len(capped) == 1 and "lateral grip" in capped[0], res.output
    ref = Reference.from_csv(out)
    assert (ref.v**2 * np.abs(path_curvature(ref))).max() <= GRIP_MARGIN * 0.9 * 9.81 * 1.01
    # the file it wrote passes the check `run` makes again (capped once, not twice)
    assert check_plan(ref, Config().vehicle, Config().tyre, Config().lqr, paper_friction_profile()).ok
    # it slows down before a capped corner, no harder than the planner's limits (2.6, 3 m/s²)
    dv = np.diff(ref.v) / ref.dt
    assert dv.max() <= 2.6 * 1.01 and dv.min() >= -3.0 * 1.01
    res = runner.invoke(app, [*args[:3], str(tmp_path / "strict.csv"), *args[4:], "--strict-plan"])
    assert res.exit_code == 2 and "lateral grip" in res.output and not (tmp_path / "strict.csv").exists()
