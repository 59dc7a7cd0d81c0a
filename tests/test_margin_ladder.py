"""The margin ladder of the LMI designs (tsmpc.synthesis.sdp.solve_with_margin) on a stand-in
problem whose feasibility and certificate outcome per margin are scripted: the order of the
margins tried, what is returned, what is raised, and that no margin is solved twice."""

from __future__ import annotations

import pytest

from tsmpc.errors import CertificateError
from tsmpc.synthesis.certificates import TARGET_MARGIN, Certificate
from tsmpc.synthesis.sdp import LADDER_DOWN, LADDER_UP, Infeasible, solve_with_margin


def _cert(holds: bool) -> Certificate:
    return Certificate(name="stand-in", margin=-1e-3 if holds else 1e-3, relative=-1e-3 if holds else 1e-3)


def _run(outcomes: dict[float, str]) -> tuple[object, list[float]]:
    """outcomes: margin -> "infeasible" | "fails" | "holds"; returns (result or exception, tried)."""
    tried: list[float] = []

    def attempt(t: float) -> float:
        tried.append(t)
        if outcomes[t] == "infeasible":
            raise Infeasible("infeasible")
        return t

    def certify(t: float) -> list[Certificate]:
        return [_cert(outcomes[t] == "holds")]

    try:
        return solve_with_margin(attempt, certify, "stand-in design"), tried
    except (Infeasible, CertificateError) as exc:
        return exc, tried


def test_the_target_margin_is_taken_when_it_certifies() -> None:
    res, tried = _run({t: "holds" for t in (*LADDER_DOWN, *LADDER_UP)})
    assert tried == [TARGET_MARGIN] and res[2] == TARGET_MARGIN  # type: ignore[index]


def test_an_infeasible_target_steps_down_to_the_first_feasible_margin() -> None:
    out = {LADDER_DOWN[0]: "infeasible", LADDER_DOWN[1]: "holds", LADDER_DOWN[2]: "holds"}
    res, tried = _run(out)
    assert tried == list(LADDER_DOWN[:2]) and res[2] == LADDER_DOWN[1]  # type: ignore[index]


def test_an_inaccurate_answer_steps_up_to_a_stricter_margin() -> None:
    out = {LADDER_DOWN[0]: "fails", LADDER_UP[0]: "fails", LADDER_UP[1]: "holds"}
    res, tried = _run(out)
    assert tried == [LADDER_DOWN[0], *LADDER_UP] and res[2] == LADDER_UP[1]  # type: ignore[index]


def test_a_design_that_never_certifies_solves_each_margin_once_and_names_the_failure() -> None:
    """Every margin feasible, none certifying: each is solved once (the stricter margins are the
    same after each step down), and the error lists the first feasible answer's failures."""
    res, tried = _run({t: "fails" for t in (*LADDER_DOWN, *LADDER_UP)})
    assert isinstance(res, CertificateError) and "stand-in design" in str(res)
    assert sorted(tried) == sorted({*LADDER_DOWN, *LADDER_UP})
    assert tried[:3] == [LADDER_DOWN[0], *LADDER_UP]


def test_an_sdp_infeasible_at_every_margin_raises_the_last_status() -> None:
    res, tried = _run({t: "infeasible" for t in (*LADDER_DOWN, *LADDER_UP)})
    assert isinstance(res, Infeasible) and tried == list(LADDER_DOWN)


@pytest.mark.parametrize("step", [1, 2])
def test_a_later_step_down_can_still_certify(step: int) -> None:
    out = {t: "fails" for t in (*LADDER_DOWN, *LADDER_UP)}
    out[LADDER_DOWN[step]] = "holds"
    res, tried = _run(out)
    assert res[2] == LADDER_DOWN[step]  # type: ignore[index]
    assert len(tried) == len(set(tried))
