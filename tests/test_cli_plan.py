"""``tsmpc plan`` and ``tsmpc show-reference`` (SPEC §10)."""

from __future__ import annotations

from pathlib import Path

from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.planning.paper_format import load_paper_reference
from tsmpc.planning.reference import Reference

runner = CliRunner()


def test_plan_track_csv_and_paper(tracks_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "zandvoort.csv"
    res = runner.invoke(app, ["plan", str(tracks_dir / "Zandvoort.csv"), "--out", str(out), "--v-max", "12"])
    assert res.exit_code == 0, res.output
    ref = Reference.from_csv(out)
    assert ref.v.max() <= 12 + 1e-6 and len(ref) > 1000
    paper = tmp_path / "zandvoort_paper.csv"
    res = runner.invoke(app, ["plan", str(tracks_dir / "Zandvoort.csv"), "--out", str(paper),
                              "--format", "paper"])
    assert res.exit_code == 0, res.output
    assert len(load_paper_reference(paper, window=None)) > 1000


def test_plan_waypoints_and_show(tmp_path: Path) -> None:
    wp = tmp_path / "wp.csv"
    wp.write_text("x,y\n0,0\n60,5\n120,40\n150,100\n", encoding="utf-8")
    out = tmp_path / "ref.csv"
    res = runner.invoke(app, ["plan", str(wp), "--out", str(out), "--open", "--tail", "4"])
    assert res.exit_code == 0, res.output
    ref = Reference.from_csv(out)
    assert ref.v[0] == 1.0
    png = tmp_path / "ref.png"
    res = runner.invoke(app, ["show-reference", str(out), "--out", str(png)])
    assert res.exit_code == 0, res.output
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plan_errors(tmp_path: Path) -> None:
    bad = tmp_path / "bad.csv"
    bad.write_text("x,y\n0,zero\n", encoding="utf-8")
    res = runner.invoke(app, ["plan", str(bad), "--out", str(tmp_path / "o.csv")])
    assert res.exit_code == 2 and "numeric" in res.output
    res = runner.invoke(app, ["plan", str(bad), "--out", str(tmp_path / "o.csv"), "--v-max", "-1"])
    assert res.exit_code == 2 and "--v-max" in res.output
