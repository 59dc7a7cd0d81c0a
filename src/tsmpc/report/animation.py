"""Animation of a run: the car driving its reference, with the MPC's predicted path.

At most :data:`MAX_FRAMES` frames by default: one every ``every`` MPC steps, ``every`` the
smallest that keeps within it (the built-in circuit's 1344 steps play as 448 frames, a
fast-forward at 10 fps; ``every=1`` renders every step). With the palette trimmed to the colours
used, the default GIF stays under 3 MB on the built-in circuit and on a race track (one frame per
step and an untrimmed palette made 14 MB and 31 MB). The top-left panel follows the car: the
track borders (when known), the reference, the driven path, the car as a rotated rectangle and
the path the MPC predicted at that step (its predicted errors x_pred mapped back to poses along
the reference window, inverting :func:`tsmpc.models.kinematic.pose_to_errors`). The top-right
panel shows the whole path; the strip below shows e_y and v over the run with a cursor.

Rendering is blitted: the static parts are drawn once and every frame redraws only the moving
artists, so a 127 s run (1344 frames at 10 fps) renders in well under a minute. GIF through
Pillow; MP4 through ffmpeg when it is on the PATH.
"""

from __future__ import annotations

import shutil
import subprocess
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.patches import Polygon
from numpy.typing import NDArray
from PIL import Image, ImageDraw, ImageFont

from tsmpc.config import VehicleParams
from tsmpc.errors import ConfigError
from tsmpc.extras import install_hint
from tsmpc.planning.tracks import Track
from tsmpc.sim.log import RunLog

__all__ = ["MAX_FRAMES", "AnimationResult", "animate_run", "car_outline", "predicted_poses"]

#: Most frames of an animation by default (``every=None``): about 2.5 MB of GIF at 800×600.
MAX_FRAMES = 500


@dataclass(frozen=True)
class AnimationResult:
    """What :func:`animate_run` wrote and how long it took."""

    gif: Path | None  #: None when only an MP4 was asked for (``out`` ending in .mp4)
    mp4: Path | None
    frames: int
    render_s: float  #: wall time of drawing the frames and encoding the files [s]


def ffmpeg_executable() -> str | None:
    """The ffmpeg that writes MP4s: the one on the PATH, else the binary of the pip-installable
    ``imageio-ffmpeg`` (the ``[video]`` extra); None when neither exists."""
    exe = shutil.which("ffmpeg")
    if exe is not None:
        return exe
    try:
        import imageio_ffmpeg
    except ImportError:
        return None
    try:
        return str(imageio_ffmpeg.get_ffmpeg_exe())
    except RuntimeError:  # the package without its binary (an unsupported platform)
        return None


#: How to get an MP4 writer, for error messages.
FFMPEG_HINT = ("MP4 needs ffmpeg: put it on the PATH, or install imageio-ffmpeg (a bundled ffmpeg, the "
               f"[video] extra): {install_hint('video')}; or write a GIF (--out NAME.gif)")


def predicted_poses(log: RunLog, k: int) -> NDArray[np.float64]:
    """(n, 3) poses X, Y, θ of the MPC's prediction at step ``k``.

    ``log.x_pred[k, j]`` are the predicted errors against the reference at step k + j
    (e = R(θ)ᵀ (p_d − p), e_θ = θ_d − θ), so p = p_d − R(θ) e with θ = θ_d − e_θ. Steps beyond the
    logged reference (the last N steps of a run) are dropped.
    """
    n = min(log.x_pred.shape[1], log.n_outer - k)
    e = log.x_pred[k, :n]
    ref = log.ref[k:k + n]
    th = ref[:, 2] - e[:, 2]
    c, s = np.cos(th), np.sin(th)
    X = ref[:, 0] - (c * e[:, 0] - s * e[:, 1])
    Y = ref[:, 1] - (s * e[:, 0] + c * e[:, 1])
    return np.stack([X, Y, th], axis=1)


def car_outline(x: float, y: float, theta: float, vehicle: VehicleParams,
                overhang: float = 0.35, width: float = 1.5) -> NDArray[np.float64]:
    """(4, 2) corners of the car body: axles at a (front) and b (rear) from the CoG plus overhangs."""
    front, rear = vehicle.a + overhang, -(vehicle.b + overhang)
    body = np.array([[rear, -width / 2], [front, -width / 2], [front, width / 2], [rear, width / 2]])
    c, s = np.cos(theta), np.sin(theta)
    return body @ np.array([[c, s], [-s, c]]) + np.array([x, y])


def _offset(xy: NDArray[np.float64], theta: NDArray[np.float64], d: float) -> NDArray[np.float64]:
    """Polyline offset by ``d`` to the left of the heading θ."""
    return xy + d * np.stack([-np.sin(theta), np.cos(theta)], axis=1)


def animate_run(
    log: RunLog,
    out: str | Path,
    *,
    vehicle: VehicleParams | None = None,
    track: Track | None = None,
    road_width: float | None = None,
    fps: float = 10.0,
    every: int | None = None,
    start_s: float = 0.0,
    duration_s: float | None = None,
    view_m: float = 30.0,
    size_px: tuple[int, int] = (800, 600),
    mp4: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> AnimationResult:
    """Render ``log`` as a GIF at ``out`` (and an MP4 beside it when ffmpeg exists and ``mp4``),
    or as an MP4 only when ``out`` ends in ``.mp4`` (then ffmpeg is required: never a GIF under
    an MP4's name).

    Args:
        log: the run (one method).
        out: GIF path (``.gif``) or MP4 path (``.mp4``).
        vehicle: body dimensions of the car (paper defaults if None).
        track: race track whose borders are drawn (when the run is on one).
        road_width: draw borders at ± road_width/2 around the reference instead (no track) [m].
        fps: frames per second of the files; with ``every = 1`` and fps = 1/T_c it plays in real time.
        every: one frame every ``every`` MPC steps (None: the fewest steps that keep the
            animation within :data:`MAX_FRAMES` frames).
        start_s: first simulated second rendered [s].
        duration_s: seconds rendered (None: to the end) [s].
        view_m: width of the car-following view [m].
        size_px: (width, height) of the frames [px].
        mp4: also write an MP4 beside the GIF when ffmpeg is available (:func:`ffmpeg_executable`).
        progress: called with (frame, frames).

    Raises:
        ConfigError: an argument is out of range, the window selects no step, ``out`` is neither a
            .gif nor a .mp4, or an MP4 is asked for without ffmpeg (before rendering anything).
        OSError: ffmpeg failed to write the MP4 asked for.
    """
    if not (fps > 0 and np.isfinite(fps)):
        raise ConfigError(f"animate: fps must be positive, got {fps}")
    if every is not None and every < 1:
        raise ConfigError(f"animate: every must be >= 1, got {every}")
    if view_m <= 0 or (road_width is not None and road_width <= 0):
        raise ConfigError("animate: view_m and road_width must be positive")
    vehicle = vehicle or VehicleParams()
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise ConfigError(f"animate: {out}: the file name must end in .gif or .mp4")
    ffmpeg = ffmpeg_executable()
    only_mp4 = suffix == ".mp4"
    if only_mp4 and ffmpeg is None:
        raise ConfigError(f"animate: {out}: {FFMPEG_HINT}")
    t0 = time.perf_counter()
    k0 = max(0, round(start_s / log.Tc))
    k1 = log.n_outer if duration_s is None else min(log.n_outer, k0 + round(duration_s / log.Tc))
    if every is None:  # the default keeps the GIF small (~5 kB a frame): at most MAX_FRAMES frames
        every = max(1, -(-(k1 - k0) // MAX_FRAMES))
    steps = np.arange(k0, k1, every)
    if steps.size == 0:
        raise ConfigError(f"animate: no MPC step in [{start_s}, {start_s + (duration_s or 0)}] s "
                          f"(the run has {log.simulated_s:.1f} s)")
    out.parent.mkdir(parents=True, exist_ok=True)
    mp4_path = out if only_mp4 else (out.with_suffix(".mp4") if mp4 and ffmpeg else None)
    video = _Mp4Writer(mp4_path, fps, ffmpeg or "ffmpeg") if mp4_path is not None else None
    # Frames are quantized as they come (a full run of RGB frames would take gigabytes).
    palette: Image.Image | None = None
    frames: list[Image.Image] = []
    n_frames = 0
    try:
        for rgb in _render(log, steps, vehicle, track, road_width, view_m, size_px, progress):
            if palette is None:  # the first frame shows every colour of the animation
                palette = rgb.quantize(colors=128, method=Image.Quantize.MEDIANCUT,
                                       dither=Image.Dither.NONE)
            n_frames += 1
            if not only_mp4:
                frames.append(rgb.quantize(palette=palette, dither=Image.Dither.NONE))
            if video is not None:
                video.write(rgb)
    finally:
        ok = video.close() if video is not None else False
    if only_mp4:
        if not ok:
            raise OSError(f"animate: ffmpeg ({ffmpeg}) failed to write {out}")
        return AnimationResult(None, out, n_frames, time.perf_counter() - t0)
    _write_gif(frames, out, fps)
    return AnimationResult(out, mp4_path if ok else None, len(frames), time.perf_counter() - t0)


def _static_layers(log: RunLog, steps: NDArray[np.int64], track: Track | None, road_width: float | None,
                   view_m: float, half_w: float, half_h: float, ax: Any, ov: Any, ae: Any,
                   av: Any) -> list[NDArray[np.float64]]:
    """What every frame shares: the overview, the e_y and v strips, the follow view's frame and
    scale bar; returns the road's borders (the track's, or a road of constant width around the
    reference; none without either)."""
    ref, st = log.ref, log.state_outer
    # Borders: the track's, or a road of constant width around the reference.
    borders: list[NDArray[np.float64]] = []
    if track is not None:
        borders = list(track.borders())
        borders = [np.vstack([b, b[:1]]) for b in borders]
    elif road_width is not None:
        borders = [_offset(ref[:, :2], ref[:, 2], s * road_width / 2) for s in (-1.0, 1.0)]

    # Static: overview, strips, the follow view's frame and scale bar.
    for b in borders:
        ov.plot(b[:, 0], b[:, 1], color="0.55", lw=0.6)
    ov.plot(ref[:, 0], ref[:, 1], "k--", lw=0.8)
    ov.plot(st[:, 0], st[:, 1], color="tab:blue", lw=0.8)
    ov.set_aspect("equal", adjustable="datalim")
    ov.set_xticks([])
    ov.set_yticks([])
    ov.set_title("whole run", fontsize=9)
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_xlim(-half_w, half_w)
    ax.set_ylim(-half_h, half_h)
    ax.set_facecolor("#f4f6f4")
    ax.set_title(f"{log.method} on {log.scenario}", fontsize=10)
    bar = 10.0 if view_m >= 25 else 5.0
    ax.plot([0.04, 0.04 + bar / view_m], [0.05, 0.05], color="k", lw=2, transform=ax.transAxes)
    ax.text(0.04, 0.07, f"{bar:.0f} m", transform=ax.transAxes, fontsize=8)
    t = log.t_outer
    e_y = log.errors[:, 1]
    ae.plot(t, e_y, color="tab:blue", lw=0.8)
    ae.axhline(0, color="k", lw=0.5)
    ae.set_ylabel("e_y [m]", fontsize=8)
    av.plot(t, ref[:, 3], "k--", lw=0.8, label="v_d")
    av.plot(t, st[:, 3], color="tab:blue", lw=0.8, label="v")
    av.set_ylabel("v [m/s]", fontsize=8)
    av.set_xlabel("t [s]", fontsize=8)
    av.legend(fontsize=7, loc="lower right", ncol=2)
    for a in (ae, av):
        a.tick_params(labelsize=7)
        a.grid(alpha=0.3)
        a.set_xlim(t[steps[0]], t[steps[-1]] + log.Tc)
    plt.setp(ae.get_xticklabels(), visible=False)
    return borders


def _render(
    log: RunLog, steps: NDArray[np.int64], vehicle: VehicleParams, track: Track | None,
    road_width: float | None, view_m: float, size_px: tuple[int, int],
    progress: Callable[[int, int], None] | None,
) -> Iterator[Image.Image]:
    dpi = 100
    w, h = size_px
    fig = plt.figure(figsize=(w / dpi, h / dpi), dpi=dpi)
    gs = fig.add_gridspec(3, 2, height_ratios=[3.2, 1, 1], width_ratios=[1.55, 1],
                          left=0.11, right=0.98, top=0.95, bottom=0.08, hspace=0.35, wspace=0.12)
    ax = fig.add_subplot(gs[0, 0])
    ov = fig.add_subplot(gs[0, 1])
    ae = fig.add_subplot(gs[1, :])
    av = fig.add_subplot(gs[2, :], sharex=ae)
    ref, st = log.ref, log.state_outer
    half_w = view_m / 2
    bbox = ax.get_position()
    half_h = half_w * (bbox.height * h) / (bbox.width * w)

    borders = _static_layers(log, steps, track, road_width, view_m, half_w, half_h, ax, ov, ae, av)
    t = log.t_outer
    e_y = log.errors[:, 1]

    # Moving artists (drawn with draw_artist on top of the cached background).
    moving = []
    border_lines = [ax.plot([], [], color="0.35", lw=1.4, animated=True)[0] for _ in borders]
    ref_line, = ax.plot([], [], "k--", lw=1.0, animated=True, label="reference")
    trail, = ax.plot([], [], color="tab:blue", lw=1.6, animated=True, label="driven")
    pred, = ax.plot([], [], "-o", color="tab:red", lw=1.4, ms=2.2, animated=True, label="MPC prediction")
    car = Polygon(car_outline(0, 0, 0, vehicle), closed=True, fc="tab:blue", ec="k", lw=1.0, animated=True)
    ax.add_patch(car)
    # The per-frame numbers are drawn by Pillow: matplotlib's glyph rendering would cost ~10 ms a frame.
    font = _font(max(10, round(11 * h / 600)))
    box_xy = (int(ax.bbox.x0) + 6, int(h - ax.bbox.y1) + 6)
    ax.legend(handles=[ref_line, trail, pred], loc="upper right", fontsize=7)
    dot, = ov.plot([], [], "o", color="tab:red", ms=5, animated=True)
    cur_e = ae.axvline(float(t[steps[0]]), color="tab:red", lw=1.0, animated=True)
    cur_v = av.axvline(float(t[steps[0]]), color="tab:red", lw=1.0, animated=True)
    moving = [*border_lines, ref_line, trail, pred, car, dot, cur_e, cur_v]

    fig.canvas.draw()
    canvas = cast(FigureCanvasAgg, fig.canvas)  # (the Agg backend, selected above: stubs can't know)
    background = canvas.copy_from_bbox(fig.bbox)
    pad = max(half_w, half_h) * 1.5
    for i, k in enumerate(steps):
        X, Y, th = st[k, 0], st[k, 1], st[k, 2]
        canvas.restore_region(background)
        ax.set_xlim(X - half_w, X + half_w)
        ax.set_ylim(Y - half_h, Y + half_h)
        # Only the points near the car: the whole path would cost a redraw per frame.
        near = np.flatnonzero((np.abs(ref[:, 0] - X) < pad) & (np.abs(ref[:, 1] - Y) < pad))
        ref_line.set_data(ref[near, 0], ref[near, 1])
        for line, b in zip(border_lines, borders, strict=True):
            sel = (np.abs(b[:, 0] - X) < pad) & (np.abs(b[:, 1] - Y) < pad)
            pts = np.where(sel[:, None], b, np.nan)  # NaN breaks the line where it leaves the view
            line.set_data(pts[:, 0], pts[:, 1])
        trail.set_data(st[max(0, k - 80):k + 1, 0], st[max(0, k - 80):k + 1, 1])  # ≤ 80·T_c·v_max m
        p = predicted_poses(log, int(k))
        pred.set_data(p[:, 0], p[:, 1])
        car.set_xy(car_outline(X, Y, th, vehicle))
        dot.set_data([X], [Y])
        cur_e.set_xdata([t[k], t[k]])
        cur_v.set_xdata([t[k], t[k]])
        for a in moving:
            if a.axes is not None:  # (every one was drawn on an axes)
                a.axes.draw_artist(a)
        if progress is not None:
            progress(i + 1, steps.size)
        # a copy: the canvas buffer is reused by the next frame (Pillow's stubs omit memoryview,
        # a buffer frombuffer takes)
        img = Image.frombuffer("RGBA", canvas.get_width_height(), canvas.buffer_rgba(),  # pyright: ignore[reportArgumentType]
                               "raw", "RGBA", 0, 1).convert("RGB")
        draw = ImageDraw.Draw(img)
        text = f"t   = {t[k]:6.1f} s\nv   = {st[k, 3]:6.2f} m/s\ne_y = {e_y[k]:+6.3f} m"
        x0, y0, x1, y1 = draw.multiline_textbbox(box_xy, text, font=font)
        draw.rectangle((x0 - 4, y0 - 3, x1 + 4, y1 + 3), fill="white", outline=(170, 170, 170))
        draw.multiline_text(box_xy, text, fill="black", font=font)
        yield img
    plt.close(fig)


def _font(size: int) -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """matplotlib's bundled DejaVu Sans Mono (always there), Pillow's default font otherwise."""
    from matplotlib import font_manager

    try:
        path = font_manager.findfont(font_manager.FontProperties(family="DejaVu Sans Mono"),
                                     fallback_to_default=True)
        return ImageFont.truetype(path, size)
    except (OSError, ValueError):
        return ImageFont.load_default()


def _write_gif(frames: list[Image.Image], path: Path, fps: float) -> None:
    """Quantized frames (one shared palette, no dithering: no flicker) to a temporary file, renamed."""
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        # optimize: Pillow trims the palette to the colours used, which shortens the LZW codes
        # (a quarter of the size; the shared palette's colours are unchanged: no flicker).
        frames[0].save(tmp, format="GIF", save_all=True, append_images=frames[1:],
                       duration=round(1000 / fps), loop=0, optimize=True, disposal=1)
        tmp.replace(path)
    finally:
        tmp.unlink(missing_ok=True)


class _Mp4Writer:
    """H.264 through ffmpeg, frames piped as raw RGB (cropped to even sizes for yuv420p).

    A failing ffmpeg is not an error: the GIF is the deliverable, the MP4 a convenience."""

    def __init__(self, path: Path, fps: float, exe: str = "ffmpeg") -> None:
        self.path = path
        self.fps = fps
        self.exe = exe
        self.tmp = path.with_name(f".{path.stem}.tmp.mp4")
        self.proc: subprocess.Popen[bytes] | None = None
        self.size = (0, 0)
        self.failed = False

    def write(self, frame: Image.Image) -> None:
        if self.failed:
            return
        if self.proc is None:
            w, h = frame.size
            self.size = (w - w % 2, h - h % 2)
            cmd = [self.exe, "-loglevel", "error", "-y", "-f", "rawvideo", "-pix_fmt", "rgb24",
                   "-s", f"{self.size[0]}x{self.size[1]}", "-r", f"{self.fps}", "-i", "-",
                   "-pix_fmt", "yuv420p", "-vcodec", "libx264", str(self.tmp)]
            try:
                self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE)
            except OSError:
                self.failed = True
                return
        assert self.proc.stdin is not None
        try:
            self.proc.stdin.write(np.asarray(frame)[:self.size[1], :self.size[0]].tobytes())
        except OSError:  # ffmpeg exited (broken pipe)
            self.failed = True

    def close(self) -> bool:
        """Finish the file; True when the MP4 was written."""
        try:
            if self.proc is None:
                return False
            if self.proc.stdin is not None:
                try:
                    self.proc.stdin.close()
                except OSError:
                    self.failed = True
            rc = self.proc.wait()
            if rc == 0 and not self.failed:
                self.tmp.replace(self.path)
                return True
            return False
        finally:
            self.tmp.unlink(missing_ok=True)
