"""``tsmpc plan`` (planner: track or waypoints → reference CSV) and ``tsmpc show-reference``
(the paper's scenario)."""

from __future__ import annotations

import os
from enum import StrEnum
from pathlib import Path
from typing import TYPE_CHECKING

import typer

from tsmpc.cli._app import app
from tsmpc.cli._common import check_laps, check_out_file, data_path, fail, finite, refuse_ineffective
from tsmpc.errors import ConfigError

if TYPE_CHECKING:
    import numpy as np
    from numpy.typing import NDArray

    from tsmpc.planning.reference import Reference

__all__ = ["OutputFormat"]


class OutputFormat(StrEnum):
    """File format of ``tsmpc plan --out``."""

    csv = "csv"
    paper = "paper"


def _read_waypoints(path: Path) -> tuple[NDArray[np.float64], NDArray[np.float64] | None]:
    """(x, y) waypoints and the optional speed caps (:func:`tsmpc.planning.waypoints.read_waypoints`)."""
    from tsmpc.planning.waypoints import read_waypoints

    return read_waypoints(path)


@app.command("plan")
def plan(
    source: Path = typer.Argument(..., help="TUMFTM track CSV (recognised by its header), a track name "
                                  "(monza, spa, …: tsmpc data fetch tracks) or an x,y waypoints CSV "
                                  "(optional column v: speed cap to the next point)."),
    out_text: str = typer.Option(..., "--out", "-o", help="Reference file to write (a file name: "
                                 "a folder, or a name ending in '/', is refused)."),
    v_max: float = typer.Option(14.7, help="Maximum speed [m/s]."),
    a_lat: float = typer.Option(3.0, help="Lateral acceleration limit [m/s^2]."),
    a_lon: float = typer.Option(2.6, help="Longitudinal acceleration limit [m/s^2]."),
    a_brake: float = typer.Option(3.0, help="Braking deceleration limit [m/s^2]."),
    v_start: float | None = typer.Option(None, help="Start speed of an open path [m/s] "
                                         "[default: 1.0]."),
    dt: float = typer.Option(0.1, help="Sample time [s]."),
    laps: int = typer.Option(1, min=1, help="Laps (closed paths)."),
    tail: float = typer.Option(0.0, help="Extra look-ahead time at the end [s]."),
    closed: bool | None = typer.Option(None, "--closed/--open",
                                       help="Closed lap or open path [default: closed for tracks]."),
    fmt: OutputFormat = typer.Option(OutputFormat.csv, "--format",
                                     help="csv: t,x,y,theta,v,omega,kappa rows; paper: 6-row format."),
    overwrite: bool = typer.Option(False, "--overwrite", help="Replace an existing --out file."),
    strict_plan: bool = typer.Option(False, "--strict-plan", help="Refuse a plan whose lateral "
                                     "acceleration or acceleration exceeds the default vehicle's grip or "
                                     "force budget (with their margins; docs/planning.md) instead of "
                                     "capping its speed profile along the same path."),
) -> None:
    """Plan a smooth reference (continuous curvature, limited speed profile) from a track or waypoints;
    a plan beyond the default vehicle's grip or force budget is capped (one line says so)."""
    from pydantic import ValidationError

    from tsmpc.config import PlannerSettings
    from tsmpc.errors import TsmpcError
    from tsmpc.planning.paper_format import save_paper_format
    from tsmpc.planning.planner import plan_path
    from tsmpc.planning.tracks import is_tumftm, load_tumftm

    out = _file_option(out_text, example=f"{Path(source).stem or 'reference'}.csv")
    finite("--dt", dt, lo=0.0, lo_open=True, hi=10.0)
    finite("--tail", tail, lo=0.0, hi=3600.0)
    check_laps(laps)
    source = data_path(source, "SOURCE") or source  # `tsmpc plan monza`: a downloaded track
    is_track = is_tumftm(source)
    is_closed = (True if closed is None else closed) if is_track else bool(closed)
    if v_start is not None and is_closed:  # an option that would be ignored is refused
        fail(ConfigError("--v-start has no effect on a closed lap (flying start); drop it or "
                         "plan an open path with --open"))
    try:
        settings = PlannerSettings(v_max=v_max, a_lat_max=a_lat, a_lon_max=a_lon,
                                   a_brake_max=a_brake, v_start=1.0 if v_start is None else v_start)
    except ValidationError as err:
        e = err.errors()[0]
        opt = {"v_max": "--v-max", "a_lat_max": "--a-lat", "a_lon_max": "--a-lon",
               "a_brake_max": "--a-brake", "v_start": "--v-start"}.get(str(e["loc"][0]), e["loc"][0])
        fail(ConfigError(f"{opt} = {e.get('input')!r}: {e['msg']}"))
    check_out_file(out, overwrite=overwrite)
    meta: dict[str, object] = {}
    try:
        if is_track:
            track = load_tumftm(source)
            ref = plan_path(track.centre, settings, closed=is_closed, dt=dt, laps=laps, tail_s=tail)
            # The narrowest half-width: beyond it the car has left the road somewhere on the lap.
            half = float(min(track.w_left.min(), track.w_right.min()))
            meta = {"source": source.name, "half_width_m": f"{half:.3f}"}
        else:
            wp, cap = _read_waypoints(source)
            ref = plan_path(wp, settings, closed=is_closed, dt=dt, laps=laps, tail_s=tail, v_cap=cap)
        ref, limit, note = _feasible(ref, strict_plan)  # before writing: capped, or refused (--strict-plan)
        if note:
            meta["plan_capped"] = limit.replace(" ", "_")
        if fmt is OutputFormat.paper:
            save_paper_format(ref, out)
        else:
            ref.to_csv(out, meta)
    except TsmpcError as err:
        msg = str(err)
        fail(msg if msg.startswith(str(source)) else f"{source}: {msg}")
    except OSError as err:
        fail(f"--out {out}: cannot write ({err.strerror or err})")
    typer.echo(f"{out}: {len(ref)} samples, {ref.duration:.1f} s, max v {ref.v.max():.2f} m/s, "
               f"max |omega| {abs(ref.omega).max():.3f} rad/s")
    if note:
        typer.secho(note, err=True, fg=typer.colors.YELLOW)
    _warn_envelope(ref)


def _feasible(ref: Reference, strict: bool) -> tuple[Reference, str, str]:
    """The plan checked against the default vehicle (:func:`tsmpc.planning.feasibility.feasible_plan_for`):
    (the capped plan, the limit, one line) or (the plan, "", "") when it is within the limits;
    ``strict`` refuses it (a ConfigError naming the limit: exit 2)."""
    from tsmpc.config import Config
    from tsmpc.planning.feasibility import feasible_plan_for

    out, check, line = feasible_plan_for(Config(), ref, strict=strict)
    return out, check.limit, line


def _names_folder(text: str) -> bool:
    """Does the ``--out`` text name a folder by its form (a trailing separator, ``.``, ``..``)?
    ``Path`` drops a trailing ``/``, so the text is read as typed."""
    return text.replace(os.sep, "/").rsplit("/", 1)[-1] in ("", ".", "..")


def _file_option(text: str, *, example: str, option: str = "--out") -> Path:
    """``plan --out``: the reference *file* to write. A name that reads as a folder
    (``out/new/``) is refused, exit 2 (an existing folder is refused by check_out_file): the
    file was once written under the folder's own name."""
    if not text.strip():
        fail(ConfigError(f"{option}: empty; give the file to write, e.g. {example}"))
    if _names_folder(text):
        fail(ConfigError(f"{option} {text}: names a folder (it ends in '/'); give the file to "
                         f"write, e.g. {text.rstrip('/' + os.sep) or '.'}/{example}"))
    return Path(text)


def _warn_envelope(ref: object) -> None:
    """Warn when the plan leaves the default design box (beyond the paper): runs will widen it."""
    from tsmpc.config import Config
    from tsmpc.envelope import reference_ranges, shortfalls

    cfg = Config()
    short = shortfalls(cfg, reference_ranges(ref, cfg))  # type: ignore[arg-type]
    if short:
        by_what: dict[str, list[str]] = {}
        for sf in short:
            by_what.setdefault(sf.what, []).append(f"{sf.field} {sf.have:g}")
        items = "; ".join(f"{w} > {', '.join(f)}" for w, f in by_what.items())
        typer.secho(f"warning: the plan exceeds the default design box ({items}): compare/run "
                    "widen the boxes and re-certify the designs (--strict-box refuses)",
                    err=True, fg=typer.colors.YELLOW)


@app.command("show-reference")
def show_reference(
    file: Path = typer.Argument(..., help="Reference (planned CSV or paper format), TUMFTM track, or "
                                "a dataset name (paper, monza, …: tsmpc data fetch)."),
    out_text: str | None = typer.Option(None, "--out", "-o", help="PNG to write, or a folder (an "
                                        "existing one, or a name ending in '/': writes "
                                        "FOLDER/FILE-stem.png) [default: FILE.png]."),
    window: str | None = typer.Option(None, help="Paper-format columns 'FIRST,LAST' (1-based) "
                                      "[default: all]."),
) -> None:
    """Write a PNG of the path, v_d and ω_d of a reference (a track is planned with the defaults)."""
    from tsmpc.config import PlannerSettings
    from tsmpc.errors import TsmpcError
    from tsmpc.planning.paper_format import load_reference
    from tsmpc.planning.tracks import is_tumftm, load_tumftm, plan_track
    from tsmpc.report.reference_plot import save_reference_figure

    win = None
    if window is not None:
        try:
            a, b = (int(v) for v in window.split(","))
        except ValueError:
            fail(ConfigError(f"--window must be 'FIRST,LAST' (1-based columns), got {window!r}"))
        win = (a, b)
    if out_text is not None and not out_text.strip():
        fail(ConfigError("--out: empty; give a PNG file or a folder"))
    out = Path(out_text) if out_text is not None else None
    png_path = out or file.with_suffix(".png")
    if out is not None and out_text is not None and (out.is_dir() or _names_folder(out_text)):
        png_path = out / f"{file.stem}.png"  # the folder is made by check_out_file
    title = file.stem
    file = data_path(file, "FILE") or file  # a dataset name: its PNG goes to the working folder
    refuse_ineffective({"window": (is_tumftm(file), "a track is planned whole: --window picks "
                                   "columns of a paper-format file or rows of a planned CSV")})
    check_out_file(png_path)
    track = None
    try:
        if is_tumftm(file):
            track = load_tumftm(file)
            ref = plan_track(track, PlannerSettings())
        else:
            ref = load_reference(file, window=win)
        png = save_reference_figure(ref, png_path, track=track, title=title)
    except (TsmpcError, ValueError) as err:
        fail(err)
    except OSError as err:
        fail(f"--out {png_path}: cannot write ({err.strerror or err})", code=1)
    typer.echo(f"wrote {png}")
