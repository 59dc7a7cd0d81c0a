"""The mismatch benchmark's acceptance table (tsmpc.report.mismatch) on a hand-made sweep table:
the issue's ratio rule, the "physics" label and how a diverged run is reported."""

from __future__ import annotations

import pandas as pd

from tsmpc.report.mismatch import acceptance, verdict_table

TRACK = "ref.csv"


def _row(case: str, ctrl: str, scale: float = 1.0, status: str = "completed", reason: str = "") -> dict:
    return {"track": TRACK, "case": case, "controller": ctrl, "status": status, "reason": reason,
            "rmse_x": 0.02 * scale, "rmse_y": 0.005 * scale, "rmse_theta": 0.006 * scale,
            "rmse_v": 0.06 * scale, "rmse_omega": 0.004 * scale, "max_abs_lateral_m": 0.02 * scale,
            "events_inner_saturated": 30.0}


def _table() -> pd.DataFrame:
    gone = "diverged: |e_y| = 6.48 m > 5 m at t = 8.2 s"
    rows = [_row("nominal", c) for c in ("paper", "default", "oracle-tuned")]
    rows += [_row("soft", "default", 1.4), _row("soft", "oracle-tuned"), _row("soft", "paper", 9.0)]
    rows += [_row("softer", "default", 1.6), _row("softer", "oracle-tuned"), _row("softer", "paper")]
    # the oracle-tuned controller leaves the road, the paper preset does not: not physics
    rows += [_row("ice", "default", 50, "diverged", gone), _row("ice", "oracle-tuned", 50, "diverged", gone),
             _row("ice", "paper", 3.0)]
    # nobody stays on the road: physics
    rows += [_row("wall", c, 50, "diverged", gone) for c in ("paper", "default", "oracle-tuned")]
    return pd.DataFrame(rows)


def test_ratio_rule_physics_label_and_divergence_time() -> None:
    v = {x.case: x for x in acceptance(_table(), TRACK, ["nominal", "soft", "softer", "ice", "wall"])}
    assert v["nominal"].passed and v["soft"].passed
    assert not v["softer"].passed and v["softer"].worst_ratio == 1.6
    assert not v["ice"].physics and v["ice"].completes == ("paper",) and not v["ice"].passed
    assert v["ice"].diverged_at == "8.2 s"
    assert v["wall"].physics and not v["wall"].passed
    text = verdict_table(list(v.values()))
    assert ("| ice | 1.00 | x [m] | 1.00 | no: paper completes | **no** | **no** (diverged at t = 8.2 s) |"
            in text)
    assert "| wall | 1.00 | x [m] | 1.00 | yes | n/a (physics) | **no** (diverged at t = 8.2 s) |" in text
