"""Report outputs of a run (issue 17): report.html, figures, the run folder read back, the animation,
sweep plots coloured by a second axis."""

from __future__ import annotations

import base64
import json
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from PIL import Image
from typer.testing import CliRunner

from tsmpc.cli import app
from tsmpc.config import Config
from tsmpc.models.kinematic import pose_to_errors
from tsmpc.report.animation import car_outline, predicted_poses
from tsmpc.report.figures import FIGURES
from tsmpc.report.html import FIGURE_CAPTIONS
from tsmpc.report.sweep_plots import colour_axis, save_sweep_plots
from tsmpc.sim.compare import compare, load_scenario
from tsmpc.sim.run_dir import load_run
from tsmpc.sim.simulator import Method

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """REF and NL over the first 6 s of the built-in circuit, every output written."""
    cfg = Config()
    out = tmp_path_factory.mktemp("run")
    compare(cfg, load_scenario(cfg), [Method.REF, Method.NL], out, max_steps=60)
    return out


class _Page(HTMLParser):
    """Collects what a self-contained page must (and must not) reference."""

    def __init__(self) -> None:
        super().__init__()
        self.imgs: list[dict[str, str | None]] = []
        self.figures: list[str] = []
        self.tables: list[str] = []
        self.links: list[str] = []
        self.external: list[str] = []
        self.scripts = 0
        self.styles: list[str] = []
        self._in_style = False

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        for key in ("src", "href", "srcset", "data", "poster", "action"):
            v = (a.get(key) or "").strip().lower()
            if v.startswith(("http:", "https:", "//", "ftp:")):
                self.external.append(f"{tag} {key}={v[:60]}")
        if tag == "img":
            self.imgs.append(a)
        elif tag == "figure":
            self.figures.append(a.get("id") or "")
        elif tag == "table":
            self.tables.append(a.get("id") or "")
        elif tag == "a":
            self.links.append(a.get("href") or "")
        elif tag == "script":
            self.scripts += 1
        elif tag == "link":
            self.external.append(f"link {a}")
        elif tag == "style":
            self._in_style = True

    def handle_endtag(self, tag: str) -> None:
        if tag == "style":
            self._in_style = False

    def handle_data(self, data: str) -> None:
        if self._in_style:
            self.styles.append(data)


@pytest.mark.slow
def test_report_html_is_self_contained_with_every_figure_and_table(run_dir: Path) -> None:
    page = _Page()
    page.feed((run_dir / "report.html").read_text(encoding="utf-8"))
    # Every figure the run wrote is embedded as a decodable PNG, in its own <figure>.
    assert set(FIGURE_CAPTIONS) == set(FIGURES)
    assert sorted(page.figures) == sorted(f"fig-{name}" for name in FIGURES)
    assert len(page.imgs) == len(FIGURES)
    for img in page.imgs:
        src = img["src"] or ""
        assert src.startswith("data:image/png;base64,"), src[:40]
        png = base64.b64decode(src.split(",", 1)[1], validate=True)
        assert png.startswith(PNG_MAGIC)
        assert png == (run_dir / f"{img['alt']}.png").read_bytes()
    assert set(page.tables) == {"table-rmse", "table-timing", "table-comfort", "table-events",
                                "table-scenario", "table-versions"}
    # Nothing from the network, no script, no url() in the style sheet.
    assert page.external == []
    assert page.scripts == 0
    assert "url(" not in "".join(page.styles) and "@import" not in "".join(page.styles)
    # Relative links to data files that exist.
    data_links = [h for h in page.links if not h.startswith("#")]
    assert {"metrics.json", "timeseries.npz", "rmse.csv", "config.toml"} <= set(data_links)
    for href in data_links:
        assert (run_dir / href).is_file(), href


@pytest.mark.slow
def test_report_tables_carry_the_metrics(run_dir: Path) -> None:
    text = (run_dir / "report.html").read_text(encoding="utf-8")
    metrics = json.loads((run_dir / "metrics.json").read_text())
    for name, m in metrics["methods"].items():
        assert f"<td>{name}</td><td>{m['rmse']['y']:.3f}</td>" not in text  # x comes first
        assert f"<td>{name}</td><td>{m['rmse']['x']:.3f}</td><td>{m['rmse']['y']:.3f}</td>" in text
    assert metrics["versions"]["numpy"] in text


@pytest.mark.slow
def test_run_folder_reads_back_into_the_same_logs(run_dir: Path) -> None:
    run = load_run(run_dir)
    assert list(run.logs) == ["REF", "NL"]
    with np.load(run_dir / "timeseries.npz") as z:
        for name, log in run.logs.items():
            for key, arr in log.arrays().items():
                np.testing.assert_array_equal(arr, z[f"{name}_{key}"])
            assert log.Tc == pytest.approx(0.1) and log.scenario == "builtin-circuit"
    assert run.config == Config()


@pytest.mark.slow
def test_predicted_path_maps_back_to_the_predicted_errors(run_dir: Path) -> None:
    """Independent check of the inversion: pose_to_errors of the reconstructed poses against
    the reference window gives back x_pred."""
    log = load_run(run_dir).logs["REF"]
    for k in (0, 10, 25):
        p = predicted_poses(log, k)
        n = p.shape[0]
        ref = log.ref[k:k + n]
        e = pose_to_errors(p[:, 0], p[:, 1], p[:, 2], ref[:, 0], ref[:, 1], ref[:, 2])
        np.testing.assert_allclose(e, log.x_pred[k, :n], atol=1e-9)
    # Near the end the window is cut to the logged reference.
    assert predicted_poses(log, log.n_outer - 3).shape == (3, 3)


def test_car_outline_is_the_body_rotated_about_the_cog() -> None:
    cfg = Config()
    c = car_outline(10.0, 5.0, np.pi / 2, cfg.vehicle, overhang=0.0, width=1.0)
    # Heading +Y: front corners at Y = 5 + a, rear at Y = 5 − b; width along X.
    np.testing.assert_allclose(sorted(set(np.round(c[:, 1], 9))), [5.0 - cfg.vehicle.b, 5.0 + cfg.vehicle.a])
    np.testing.assert_allclose(sorted(set(np.round(c[:, 0], 9))), [9.5, 10.5])


@pytest.mark.slow
def test_cli_animate_writes_a_gif_of_the_window(run_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "a.gif"
    res = CliRunner().invoke(app, ["animate", str(run_dir), "--method", "nl", "--out", str(out),
                                   "--start", "1", "--duration", "2", "--road-width", "4", "--no-mp4",
                                   "--width", "400", "--height", "300"])
    assert res.exit_code == 0, res.output
    with Image.open(out) as im:
        assert im.size == (400, 300)
        assert im.n_frames == 20
        assert im.info["duration"] == 100
        # Frames differ (the car moves): not one picture repeated.
        im.seek(0)
        a = np.asarray(im.convert("RGB"), dtype=int)
        im.seek(19)
        b = np.asarray(im.convert("RGB"), dtype=int)
        assert np.abs(a - b).sum() > 0


@pytest.mark.parametrize("args, needle", [
    (["/nonexistent/run"], "not a folder"),
    (["RUN", "--method", "fzn"], "no method FZN"),
    (["RUN", "--start", "500"], "no MPC step"),
])
def test_cli_animate_rejects_bad_input_with_exit_2(args: list[str], needle: str, run_dir: Path) -> None:
    args = [str(run_dir) if a == "RUN" else a for a in args]
    res = CliRunner().invoke(app, ["animate", *args, "--no-mp4"])
    assert res.exit_code == 2, res.output
    assert needle in res.output
    assert "Traceback" not in res.output


def test_sweep_plots_colour_by_a_second_axis(tmp_path: Path) -> None:
    rows = [{"method": m, "noise_scale": s, "friction": f, "status": "completed", "rmse_x": 0.03,
             "rmse_y": 0.09, "max_abs_lateral_m": 0.3, "mpc_median_ms": 0.3, "mpc_p99_ms": 1.0}
            for m in ("REF", "NL") for s in (0.5, 2.0, 10.0) for f in ("dry", "wet")]
    table = pd.DataFrame(rows)
    assert colour_axis(table, "noise_scale") == "method"
    assert colour_axis(table, "method") == "friction"  # fewest levels among the others (2 < 3)
    assert colour_axis(table[table["method"] == "REF"][["noise_scale", "status"]], "noise_scale") is None
    files = save_sweep_plots(table, tmp_path)
    assert {p.name for p in files} == {"by_method.png", "by_noise_scale.png", "by_friction.png",
                                       "solve_times.png"}
    assert all(p.read_bytes().startswith(PNG_MAGIC) for p in files)


@pytest.mark.slow
def test_animate_writes_an_mp4_with_the_pip_installable_ffmpeg(run_dir: Path, tmp_path: Path) -> None:
    """The [test] and [video] extras bring imageio-ffmpeg: wherever it is installed (the README's
    test command installs it) the MP4 is written and checked; a lookup that misses it fails."""
    import importlib.util

    from tsmpc.report.animation import animate_run, ffmpeg_executable

    if ffmpeg_executable() is None:
        if importlib.util.find_spec("imageio_ffmpeg") is not None:
            pytest.fail("imageio-ffmpeg is installed but tsmpc found no ffmpeg")
        pytest.skip("no ffmpeg: pip install 'tsmpc[video]'")
    log = load_run(run_dir).logs["REF"]
    res = animate_run(log, tmp_path / "a.gif", duration_s=1.0, size_px=(321, 241))
    assert res.frames == 10 and res.gif == tmp_path / "a.gif" and res.gif.read_bytes()[:3] == b"GIF"
    assert res.mp4 == tmp_path / "a.mp4"
    assert res.mp4.read_bytes()[4:8] == b"ftyp"  # an MP4 container (odd sizes cropped to even)
    only = animate_run(log, tmp_path / "b.mp4", duration_s=1.0, size_px=(320, 240))
    assert only.gif is None and only.mp4 == tmp_path / "b.mp4" and only.frames == 10
    assert only.mp4.read_bytes()[4:8] == b"ftyp" and not (tmp_path / "b.gif").exists()
    assert not list(tmp_path.glob(".*tmp*"))  # no temporary file left behind


def test_an_mp4_without_ffmpeg_is_refused_never_a_gif_named_mp4(run_dir: Path, tmp_path: Path,
                                                               monkeypatch: pytest.MonkeyPatch) -> None:
    from tsmpc.errors import ConfigError
    from tsmpc.report import animation

    monkeypatch.setattr(animation, "ffmpeg_executable", lambda: None)
    log = load_run(run_dir).logs["REF"]
    with pytest.raises(ConfigError, match=r"a\.mp4: MP4 needs ffmpeg: .*pip install -e \"\.\[video\]\""):
        animation.animate_run(log, tmp_path / "a.mp4", duration_s=0.5)
    assert not list(tmp_path.iterdir())  # refused before rendering: nothing written
    res = animation.animate_run(log, tmp_path / "a.gif", duration_s=0.5, size_px=(320, 240))
    assert res.gif == tmp_path / "a.gif" and res.mp4 is None  # the GIF alone, no error
    with pytest.raises(ConfigError, match=r"must end in \.gif or \.mp4"):
        animation.animate_run(log, tmp_path / "a.avi", duration_s=0.5)
    out = CliRunner().invoke(app, ["animate", str(run_dir), "--out", str(tmp_path / "c.mp4")])
    assert out.exit_code == 2 and "MP4 needs ffmpeg" in out.output and not (tmp_path / "c.mp4").exists()
