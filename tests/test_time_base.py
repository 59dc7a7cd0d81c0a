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
