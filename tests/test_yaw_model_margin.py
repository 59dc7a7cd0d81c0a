"""The MHE's yaw-rate process covariance as a design margin (issue 35): the default ``mhe.Q[2]`` is
larger than the paper's so that a yaw inertia and CoG unlike the model's are taken up as process
noise of the yaw equation, not as slip. With the paper's Q on a plant of the generalisation class
(draw d44's vehicle: I_z −27 %, C_f +39 %, CoG 5.3 % of the wheelbase rearward, mass −19 %;
calibrated sensors), the MHE explains the yaw response it does not expect with α̂ and the inner loop
oscillates at ≈ 2.5 Hz from ≈ 6 s on at 13 m/s (RMSE ω 0.03 rad/s against 0.004 with the
true vehicle); with the default it does not."""

from __future__ import annotations

from pathlib import Path

import pytest

from tsmpc.config import PAPER_MHE_Q, Config

PLANT = ("plant = { cornering_front_scale = 1.388328, cornering_rear_scale = 1.041662, "
         "mass_scale = 0.810187, inertia_scale = 0.726317, cog_to_front_scale = 1.126581 }")


def _omega_rmse(tmp_path: Path, q: tuple[float, ...] | None) -> float:
    from tsmpc.sweep import expand, load_sweep, run_task

    ctl = "" if q is None else f"\n[controllers.paperQ]\nmhe = {{ Q = {list(q)} }}\n"
    text = (f'name = "yaw"\nduration_s = 15.0\n[grid]\ntrack = ["paper"]\n'
            f'controller = ["{"default" if q is None else "paperQ"}"]\nmethod = ["ref"]\ncase = ["d44"]\n'
            f"seed = [1]\n{ctl}\n[cases.d44]\n{PLANT}\n")
    path = tmp_path / f"yaw{q is None}.toml"
    path.write_text(text, encoding="utf-8")
    (task,) = expand(load_sweep(path))
    rec = run_task(task)
    assert rec["status"] == "completed", rec["reason"]
    return float(rec["metrics"]["rmse"]["omega"])


def test_the_paper_q_is_kept_by_the_paper_presets_and_the_default_is_larger() -> None:
    assert Config.preset("paper").mhe.Q == PAPER_MHE_Q
    assert Config.preset("paper-as-run").mhe.Q == PAPER_MHE_Q
    assert Config().mhe.Q[2] > PAPER_MHE_Q[2] and Config().mhe.Q[:2] == PAPER_MHE_Q[:2]


@pytest.mark.usefixtures("paper_reference_path")
def test_an_inertia_unlike_the_model_does_not_make_the_inner_loop_oscillate(tmp_path: Path) -> None:
    default = _omega_rmse(tmp_path, None)
    paper_q = _omega_rmse(tmp_path, PAPER_MHE_Q)
    assert paper_q > 0.015, paper_q  # the failure this margin removes is still there without it
    assert default < 0.008, default
