"""``tsmpc animate RUN_DIR``: a GIF (and an MP4 when ffmpeg exists) of a compare/run output."""

from __future__ import annotations

from pathlib import Path

import typer

from tsmpc.cli._app import app
from tsmpc.cli._common import check_out_file, console, data_path, fail, refuse_ineffective


@app.command("animate")
def animate_cmd(
    run_dir: Path = typer.Argument(..., help="Output folder of tsmpc compare / tsmpc run."),
    method: str | None = typer.Option(None, "--method", help="Method (default: REF, else the first)."),
    out: Path | None = typer.Option(None, "--out", help="GIF path, or an MP4 path (needs ffmpeg: the "
                                    "[video] extra); default: RUN_DIR/animation_M.gif."),
    track: Path | None = typer.Option(None, "--track", help="TUMFTM track file (or a track name: "
                                      "monza, …) whose borders are drawn."),
    road_width: float | None = typer.Option(
        None, "--road-width", min=0.1, help="Draw borders at ± width/2 around the reference [m] (no --track)."
    ),
    fps: float = typer.Option(10.0, "--fps", min=0.1, max=100.0, help="Frames per second of the files."),
    every: int | None = typer.Option(None, "--every", min=1, help="One frame every N MPC steps "
                                     "(default: at most 500 frames, a GIF under 3 MB; 1: every step)."),
    start: float = typer.Option(0.0, "--start", min=0.0, help="First simulated second shown [s]."),
    duration: float | None = typer.Option(None, "--duration", min=0.1, help="Seconds shown [s]."),
    view: float = typer.Option(30.0, "--view", min=2.0, help="Width of the car-following view [m]."),
    width: int = typer.Option(800, "--width", min=200, max=4000, help="Frame width [px]."),
    height: int = typer.Option(600, "--height", min=150, max=4000, help="Frame height [px]."),
    no_mp4: bool = typer.Option(False, "--no-mp4", help="With a GIF: skip the MP4 beside it even when "
                                "ffmpeg is present."),
) -> None:
    """Animate a run: the car on its track with the MPC's predicted path, e_y and v below."""
    from tsmpc.errors import TsmpcError
    from tsmpc.planning.tracks import load_tumftm
    from tsmpc.report.animation import animate_run
    from tsmpc.sim.run_dir import load_run

    refuse_ineffective({"road_width": (track is not None, "--track draws the track's own borders")})
    track = data_path(track, "--track")  # `--track monza`: a downloaded track
    try:
        run = load_run(run_dir)
        name = (method.upper() if method else ("REF" if "REF" in run.logs else next(iter(run.logs))))
        if name not in run.logs:
            raise ValueError(f"{run_dir}: no method {name} in this run (it has {', '.join(run.logs)})")
        trk = load_tumftm(track) if track is not None else None
        target = out if out is not None else run_dir / f"animation_{name}.gif"
    except (TsmpcError, ValueError, OSError) as err:
        fail(err)
    check_out_file(target, option="--out")
    try:
        res = animate_run(run.logs[name], target, vehicle=run.config.vehicle, track=trk,
                          road_width=road_width, fps=fps, every=every, start_s=start, duration_s=duration,
                          view_m=view, size_px=(width, height), mp4=not no_mp4)
    except (TsmpcError, ValueError) as err:
        fail(err)
    except OSError as err:  # disk full, a name too long: one line, no half-written file kept
        fail(f"animate failed: cannot write {err.filename or target}: {err.strerror or err}", code=1)
    files = [str(f) for f in (res.gif, res.mp4) if f is not None]
    console().print(f"wrote {' and '.join(files)}" + f": {res.frames} frames in {res.render_s:.1f} s")
