"""The rough edges a newcomer hit following README → getting started → paper → own vehicle →
planning → sweeps (issue 23): each friction fixed, each with its test."""

from __future__ import annotations

import ast
import json
import re
from dataclasses import replace as dc_replace
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.cli._outdir import claim_default_out
from tsmpc.config import Config, load_config
from tsmpc.sim.compare import compare, load_scenario
from tsmpc.sim.simulator import Method

ROOT = Path(__file__).resolve().parents[1]


# -- 1. default output folders never collide; the folder is printed -------------------------

def test_default_output_folders_are_new_each_time(tmp_path: Path) -> None:
    root = tmp_path / "results"
    (root / "compare").mkdir(parents=True)  # e.g. `tsmpc compare --out results/compare` before
    (root / "compare" / "metrics.json").write_text("{}")
    a, b = claim_default_out("compare", root), claim_default_out("compare", root)
    assert (a.name, b.name) == ("compare-2", "compare-3") and a.is_dir() and b.is_dir()
    assert claim_default_out("run", root).name == "run"


@pytest.mark.slow
def test_run_without_out_writes_a_new_folder_and_prints_it(tmp_path: Path,
                                                           monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(tmp_path)
    args = ["run", "--duration", "1", "--no-plots"]
    first, second = CliRunner().invoke(app, args), CliRunner().invoke(app, args)
    assert first.exit_code == 0 and second.exit_code == 0, first.output + second.output
    assert (tmp_path / "results" / "run" / "metrics.json").is_file()
    assert (tmp_path / "results" / "run-2" / "metrics.json").is_file()
    last = second.output.strip().splitlines()[-1]
    assert "wrote" in last and "results/run-2" in last  # the folder, at the end


def test_sweep_suggests_an_option_it_has(tmp_path: Path) -> None:
    out = tmp_path / "busy"
    out.mkdir()
    (out / "x").write_text("x")
    res = CliRunner().invoke(app, ["sweep", str(ROOT / "examples" / "sweep.toml"), "--out", str(out),
                                   "--dry-run"])
    assert res.exit_code == 2 and "--resume" in res.output and "--overwrite" not in res.output
    again = CliRunner().invoke(app, ["sweep", str(ROOT / "examples" / "sweep.toml"), "--resume"])
    assert again.exit_code == 2 and "--resume needs --out" in again.output


# -- 5. reports of diverged runs and their labels ----------------------------------------------

@pytest.fixture(scope="module")
def diverged() -> dict:
    """REF and NL from a 2 m offset with a 2.03 m bound: both diverge at 0.4 s (|e_y| peaks at 2.06 m)."""
    cfg = Config()
    sc = dc_replace(load_scenario(cfg), initial_error=(2.0, 0.2), divergence_bound_m=2.03,
                    meta={"paper_reference": True})
    res = compare(cfg, sc, [Method.REF, Method.NL], None, max_steps=30)
    assert res.metrics["methods"]["REF"]["status"] == "diverged"
    return {"metrics": res.metrics, "logs": res.logs}


def test_report_of_a_diverged_run_reads_like_the_terminal(diverged: dict) -> None:
    from tsmpc.report.html import render_report

    page = render_report(diverged["metrics"], {})
    rmse = page[page.index('id="table-rmse"'):page.index("</table>", page.index('id="table-rmse"'))]
    assert "nan" not in rmse.lower() and "<td>diverged</td>" in rmse
    assert "Table 5 rows" not in page  # no paper row beside a diverged run
    assert "tsmpc compare — " in page and "oracle = " not in page
    assert "the inner loop on the MHE-UIO estimate" in page
    one = {**diverged["metrics"], "methods": {"REF": diverged["metrics"]["methods"]["REF"]}}
    assert "<title>tsmpc run — " in render_report(one, {})
    oracle = render_report({**diverged["metrics"], "oracle": True}, {})
    assert "oracle: the inner loop on the true plant state" in oracle


def test_zoom_of_a_diverged_run_shows_the_car(diverged: dict) -> None:
    import matplotlib.pyplot as plt

    from tsmpc.report.figures import circuit_figure

    log = diverged["logs"]["REF"]
    fig = circuit_figure({"REF": log})
    zoom = fig.axes[1]
    k = int(np.argmax(np.abs(log.errors[:, 1])))
    (x0, x1), (y0, y1) = zoom.get_xlim(), zoom.get_ylim()
    for x, y in (log.state_outer[k, :2], log.ref[k, :2]):  # the car and its reference point
        assert x0 <= x <= x1 and y0 <= y <= y1
    plt.close(fig)


def test_figures_titles_and_legends_say_what_they_show(diverged: dict) -> None:
    import matplotlib.pyplot as plt

    from tsmpc.report.figures import control_figure, differences_figure, errors_figure, friction_figure

    logs = diverged["logs"]
    calm = {k: dc_replace(v, saturated=np.zeros_like(v.saturated)) for k, v in logs.items()}
    busy = {k: dc_replace(v, saturated=np.ones_like(v.saturated)) for k, v in logs.items()}
    assert "never saturated" in control_figure(calm)._suptitle.get_text()
    assert "shaded" in control_figure(busy)._suptitle.get_text()
    # the differences' legends sit beside the axes: they cannot hide a peak
    fig = differences_figure(logs)
    for ax in fig.axes:
        legend = ax.get_legend()
        fig.canvas.draw()
        box = legend.get_window_extent().transformed(ax.transAxes.inverted())
        assert box.x0 >= 1.0, "legend inside the axes"
    # the friction figure explains a negative F_fr (the road resists less than the models)
    log = logs["REF"]
    f = log.F_fr_true.copy()
    f[len(f) // 2] = -2680.0
    text = " ".join(t.get_text() for t in friction_figure({"REF": dc_replace(log, F_fr_true=f)})
                    .axes[0].texts)
    assert "2680 N less than the models assume" in text
    # a long run gets a second column zoomed on its first seconds
    assert len(errors_figure(logs).axes) == 5  # 3 s: nothing to zoom
    long = {k: dc_replace(v, t_outer=v.t_outer * 200.0) for k, v in logs.items()}
    zoomed = errors_figure(long)
    assert len(zoomed.axes) == 10 and zoomed.axes[1].get_title() == "the first 10 s"
    plt.close("all")


def test_config_toml_of_a_multi_method_run_names_the_methods(tmp_path: Path) -> None:
    cfg = Config()
    compare(cfg, load_scenario(cfg), [Method.FZN, Method.REF], tmp_path, max_steps=3, plots=False)
    text = (tmp_path / "config.toml").read_text()
    assert re.search(r'(?m)^mode = "REF"  # this run: FZN, REF', text)
    assert load_config(tmp_path / "config.toml") == cfg


# -- 6. Ctrl-C keeps the methods already finished ------------------------------------------------

def test_interrupt_keeps_the_finished_methods(tmp_path: Path) -> None:
    from tsmpc.cli._common import Interrupted

    def factory(name: str, _total: int):
        def update(k: int, _kt: int) -> None:
            if name == "REF" and k == 3:
                raise Interrupted(2)  # SIGINT during the second method
        return update

    cfg = Config()
    with pytest.raises(KeyboardInterrupt):
        compare(cfg, load_scenario(cfg), [Method.FZN, Method.REF], tmp_path, max_steps=10,
                progress_factory=factory)
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    assert list(metrics["methods"]) == ["FZN"]
    assert metrics["interrupted"] == {"finished": ["FZN"], "not_finished": ["REF"]}
    assert np.load(tmp_path / "timeseries.npz")["FZN_state"].shape[0] == 100


# -- 7. presets are case-insensitive ---------------------------------------------------------------

def test_presets_are_case_insensitive_like_methods(tmp_path: Path) -> None:
    assert Config.preset("Paper") == Config.preset("paper")
    assert load_config(None, " PAPER-as-run ") == Config.preset("paper-as-run")
    f = tmp_path / "c.toml"
    f.write_text('preset = "Paper"\n')
    assert load_config(f) == Config.preset("paper")
    res = CliRunner().invoke(app, ["run", "--preset", "Paper", "--duration", "0.5", "--no-plots",
                                   "--out", str(tmp_path / "o")])
    assert res.exit_code == 0, res.output
    assert load_config(tmp_path / "o" / "config.toml").lqr.speed_feedback is False


# -- 8. the checkout stays clean -------------------------------------------------------------------

def _bash_blocks(text: str) -> list[str]:
    return re.findall(r"^```bash\n(.*?)^```", text, re.S | re.M)


def test_the_readme_test_command_is_ci_and_builds_its_venv_outside_the_checkout() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    cmd = next(b.strip() for b in _bash_blocks(readme) if "pytest" in b)
    assert cmd in (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    venv = re.search(r"venv --clear (\S+)", cmd).group(1)
    assert venv.startswith(('"$', "/", "${")) and "TMPDIR" in cmd, venv


def test_documented_commands_write_only_under_results() -> None:
    """Every `--out` of a documented command is under results/ (git-ignored)."""
    bad = []
    for page in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for block in _bash_blocks(page.read_text(encoding="utf-8")):
            code = "\n".join(line.split(" #")[0] for line in block.splitlines())  # not comments
            for out in re.findall(r"--out[ =](\S+)", code):
                if not out.startswith("results/"):
                    bad.append(f"{page.name}: --out {out}")
    assert not bad, bad


# -- 9. the wide ablation table fits a page ---------------------------------------------------------

def test_published_tables_have_short_cells() -> None:
    """The ablation is two narrow tables (at 1400 px the site's content column holds about seven
    short columns; the one wide table scrolled and its rows were four lines tall)."""
    from generator.blocks import BlockId, read_block

    for page in ("README.md", "docs/paper.md"):
        text = (ROOT / page).read_text(encoding="utf-8")
        for name in ("table", "effort"):
            rows = [r.split(" | ") for r in read_block(text, BlockId("ablation", name)).strip().splitlines()]
            assert rows and all(len(r) <= 7 for r in rows), (page, name)
            longest = max((c for r in rows for c in r), key=len)
            assert len(longest) <= 45, longest


# -- 11. benchmarks limit BLAS threads like the CLI ---------------------------------------------------

@pytest.mark.parametrize("script", sorted((ROOT / "benchmarks").glob("*.py")), ids=lambda p: p.name)
def test_benchmarks_limit_blas_threads_before_measuring(script: Path) -> None:
    tree = ast.parse(script.read_text(encoding="utf-8"))
    main = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == "main")
    calls = [n.func.id for n in ast.walk(main) if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)]
    assert "limit_blas_threads" in calls, f"{script.name}: main() does not call limit_blas_threads()"

