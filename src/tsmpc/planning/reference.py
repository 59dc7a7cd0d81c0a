"""Reference trajectories: one typed object for the planner's output (the paper's scenario).

A :class:`Reference` is uniformly sampled. θ is unwrapped (continuous). Integration convention
(the paper planner's): θ(k) = θ(k−1) + ω(k)T, x(k) = x(k−1) + v(k) cos θ(k) T.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from tsmpc.errors import DataFormatError

__all__ = [
    "CSV_HEADER", "MAX_COORDINATE_M", "MAX_CURVATURE", "MAX_HALF_WIDTH_M", "MAX_HEADING_STEP_RAD",
    "POSE_TOLERANCE_M", "Reference", "check_consistency", "check_coordinates", "check_window",
    "read_csv_meta",
]

#: Largest mismatch [m] accepted between a step of the position and v_d·T (plus 10 % of v_d·T).
POSE_TOLERANCE_M = 0.05
#: Largest mismatch [rad] accepted between a step of θ_d and ω_d·T (plus 10 % of |ω_d|·T).
HEADING_TOLERANCE_RAD = 0.02

#: Largest |x|, |y| of any reference, track or waypoint [m]. Decision (issue 24): coordinates are
#: refused beyond it, not silently recentred — a double keeps ~2e-9 m resolution at 1e7 m (any
#: Earth-local metric frame, e.g. UTM, fits), while at 1e12 m the plant's 1 ms position steps lose
#: ~1e-4 m each and the tracking error grows a hundredfold. Shift such data to a local origin.
MAX_COORDINATE_M = 1e7
#: Largest |κ| of a reference file [1/m] (a 0.1 m turning radius).
MAX_CURVATURE = 10.0
#: Largest half-width of a track a planned CSV may carry [m].
MAX_HALF_WIDTH_M = 100.0
#: Largest heading change between two samples of a reference [rad]: coarser sampling is not a
#: path (linear interpolation between samples cuts the corners; `plan --dt 10` on a 200 m ring).
MAX_HEADING_STEP_RAD = 0.2

CSV_HEADER = "t,x,y,theta,v,omega,kappa"
_SIGNALS = ("t", "x", "y", "theta", "v", "omega", "kappa")


@dataclass(frozen=True)
class Reference:
    """Uniformly sampled reference trajectory.

    Attributes:
        t: (n,) time [s], uniform step.
        x: (n,) position X [m].
        y: (n,) position Y [m].
        theta: (n,) heading [rad], unwrapped.
        v: (n,) speed [m/s].
        omega: (n,) yaw rate [rad/s].
        kappa: (n,) curvature [1/m].
        closed: True for a closed lap (windows past the end wrap around).
    """

    t: NDArray[np.float64]
    x: NDArray[np.float64]
    y: NDArray[np.float64]
    theta: NDArray[np.float64]
    v: NDArray[np.float64]
    omega: NDArray[np.float64]
    kappa: NDArray[np.float64]
    closed: bool = False

    def __post_init__(self) -> None:
        n = None
        for name in _SIGNALS:
            a = np.ascontiguousarray(getattr(self, name), dtype=float).reshape(-1)
            if n is None:
                n = a.size
            if a.size != n:
                raise DataFormatError(f"reference: {name} has {a.size} samples, t has {n}")
            if not np.all(np.isfinite(a)):
                raise DataFormatError(f"reference: {name} contains NaN or inf")
            a.setflags(write=False)
            object.__setattr__(self, name, a)
        if n is None or n < 2:
            raise DataFormatError("reference: needs at least 2 samples")
        check_coordinates(self.x, self.y, "reference")
        d = np.diff(self.t)
        if np.any(d <= 0):
            raise DataFormatError("reference: time must be strictly increasing")
        if np.max(np.abs(d - d.mean())) > 1e-6 * max(1.0, d.mean()):
            raise DataFormatError("reference: time must be uniformly sampled")

    def __len__(self) -> int:
        return int(self.t.size)

    @property
    def dt(self) -> float:
        """Sample time [s]."""
        return float((self.t[-1] - self.t[0]) / (self.t.size - 1))

    @property
    def duration(self) -> float:
        """``t[-1] − t[0]`` [s]."""
        return float(self.t[-1] - self.t[0])

    @staticmethod
    def _trusted(arrays: dict[str, NDArray[np.float64]]) -> Reference:
        """An open Reference from pieces of validated arrays, skipping the checks."""
        ref = object.__new__(Reference)
        for name, a in arrays.items():
            object.__setattr__(ref, name, a)
        object.__setattr__(ref, "closed", False)
        return ref

    def _replace(self, **arrays: NDArray[np.float64]) -> Reference:
        data = {f.name: getattr(self, f.name) for f in fields(self)}
        data.update(arrays)
        return Reference(**data)

    def slice(self, start: int, stop: int) -> Reference:
        """Samples start..stop−1 (an open piece: ``closed`` is False)."""
        idx = np.arange(len(self))[start:stop]
        out = {n: getattr(self, n)[idx] for n in _SIGNALS}
        return Reference(**out, closed=False)

    def window(self, k: int, n: int) -> Reference:
        """n samples from k. Past the end a closed lap wraps around (θ continued by whole turns,
        time continued); an open reference holds v, ω, κ and continues the pose along them."""
        L = len(self)
        if 0 <= k and k + n <= L and n >= 2:
            # Called every T_c in the loop: read-only views of checked data need no new checks.
            return self._trusted({s: getattr(self, s)[k:k + n] for s in _SIGNALS})
        idx = np.arange(k, k + n)
        if idx[-1] < L:
            return Reference(**{s: getattr(self, s)[idx] for s in _SIGNALS}, closed=False)
        dt = self.dt
        t = self.t[0] + idx * dt
        if self.closed:
            lap, j = np.divmod(idx, L)
            turn = self.theta[-1] - self.theta[0] + self.omega[0] * dt
            turn = 2 * np.pi * np.round(turn / (2 * np.pi))
            return Reference(t, self.x[j], self.y[j], self.theta[j] + lap * turn, self.v[j],
                             self.omega[j], self.kappa[j], closed=False)
        inside = idx < L
        ji = np.minimum(idx, L - 1)
        x, y, th = self.x[ji].copy(), self.y[ji].copy(), self.theta[ji].copy()
        v, w = self.v[-1], self.omega[-1]
        for i in np.flatnonzero(~inside):  # at most n steps, only at the very end of a run
            th[i] = th[i - 1] + w * dt if i > 0 else self.theta[-1] + w * dt
            px, py = (x[i - 1], y[i - 1]) if i > 0 else (self.x[-1], self.y[-1])
            x[i] = px + v * np.cos(th[i]) * dt
            y[i] = py + v * np.sin(th[i]) * dt
        return Reference(t, x, y, th, self.v[ji], self.omega[ji], self.kappa[ji], closed=False)

    def heading_lag(self) -> float:
        """How long θ_d lags the path's tangent [s], measured from the geometry.

        Under the planners' convention (θ(k) = θ(k−1) + ω(k)T, x(k) = x(k−1) +
        v(k) cos θ(k) T) θ_d(k) is the heading of the step *into* sample k, half a source period
        T_src/2 behind the tangent — whatever the reference was resampled to since; a reference
        whose θ_d is the tangent itself has no lag. The lag τ is the least-squares fit of
        chord(k) − θ_d(k) = τ θ̇_d(k) over the whole reference (chord: direction from sample k−1
        to k+1, the tangent on a circular arc): one number, so the rounding of the positions in a
        file (the paper's has 5 significant digits: 1 cm at 800 m) averages out. Bounded to
        [−T, T]; 0 for a straight reference."""
        n = len(self)
        if n < 3:
            return 0.0
        dt = self.dt
        k = np.arange(1, n - 1)
        dx, dy = self.x[k + 1] - self.x[k - 1], self.y[k + 1] - self.y[k - 1]
        moving = np.hypot(dx, dy) > 1e-6
        off = (np.arctan2(dy, dx) - self.theta[k] + np.pi) % (2 * np.pi) - np.pi
        rate = (self.theta[k + 1] - self.theta[k - 1]) / (2 * dt)
        rate, off = rate[moving], off[moving]
        den = float(np.sum(rate * rate))
        if not den > 1e-12:
            return 0.0
        return float(np.clip(np.sum(rate * off) / den, -dt, dt))

    def tangent_heading(self) -> NDArray[np.float64]:
        """(n,) heading of the path's tangent at each sample [rad]: θ_d moved forward by its
        :meth:`heading_lag` τ, θ_d(k) + τ (θ_d(k+1) − θ_d(k)) / T (linear interpolation of θ_d at
        t + τ; the last sample of an open reference uses the previous step's rate). Independent
        of the sample period: a path sampled at 20, 50 or 100 ms gets the correction of its own
        convention."""
        tau = self.heading_lag()
        th = self.theta
        if len(self) < 2 or tau == 0.0:
            return th.copy()
        step = np.diff(th)
        if self.closed:  # the lap's first sample follows its last one (θ continued by a turn)
            turn = th[-1] - th[0] + self.omega[0] * self.dt
            turn = 2 * np.pi * np.round(turn / (2 * np.pi))
            step = np.append(step, th[0] + turn - th[-1])
        else:
            step = np.append(step, step[-1])
        return th + tau * step / self.dt

    def step_averages(self) -> Reference:
        """The reference as the path's geometry over each step: θ the tangent heading
        (:meth:`tangent_heading`), ω(k) = (θ_tan(k+1) − θ_tan(k)) / T and v(k) = |p(k+1) − p(k)| / T,
        the averages over the step *from* sample k (κ = ω / v). Positions and time unchanged.

        An MPC whose step k → k+1 takes (v_d(k), ω_d(k)) then sees the same motion whatever the
        reference's source period and heading convention: the planners' own samples describe the
        step *into* the sample, a lag of T_src/2 in θ and of a whole step in ω, v at T_c."""
        th = self.tangent_heading()
        ext = self.window(0, len(self) + 1)  # one more sample: the lap's start, or continued
        th_next = np.append(th[1:], th[-1] + (ext.theta[-1] - self.theta[-1]))
        if self.closed:  # the lap's first tangent, continued by a whole turn
            th_next[-1] = th[0] + (ext.theta[-1] - self.theta[0])
        dt = self.dt
        omega = (th_next - th) / dt
        v = np.hypot(np.diff(ext.x), np.diff(ext.y)) / dt
        kappa = np.where(v > 1e-6, omega / np.maximum(v, 1e-6), self.kappa)
        return Reference(self.t, self.x, self.y, th, v, omega, kappa, closed=self.closed)

    def repeat(self, laps: int) -> Reference:
        """``laps`` consecutive laps of a closed reference (itself closed: the look-ahead past
        the last lap wraps into the next one)."""
        if laps < 1 or (laps > 1 and not self.closed):
            raise DataFormatError(f"laps = {laps}: must be ≥ 1, and > 1 only for a closed lap")
        if laps == 1:
            return self
        w = self.window(0, laps * len(self))
        return Reference(w.t, w.x, w.y, w.theta, w.v, w.omega, w.kappa, closed=True)

    def resample(self, dt: float) -> Reference:
        """Resample to step ``dt`` (linear interpolation of every signal; θ is unwrapped so this
        is continuous)."""
        if not dt > 0:
            raise DataFormatError(f"dt must be positive, got {dt}")
        n = int(np.floor(self.duration / dt + 1e-9)) + 1
        t = self.t[0] + np.arange(n) * dt
        return Reference(t=t, **{s: np.interp(t, self.t, getattr(self, s)) for s in _SIGNALS[1:]},
                         closed=self.closed)

    def to_csv(self, path: str | Path, meta: dict[str, object] | None = None) -> None:
        """Write ``t,x,y,theta,v,omega,kappa`` rows (atomically).

        A ``# key=value;...`` line after the header carries ``closed`` and any ``meta`` (e.g. the
        track's ``half_width_m``): what the samples alone cannot say."""
        from tsmpc.io import atomic_write_text

        data = np.stack([getattr(self, s) for s in _SIGNALS], axis=1)
        info = {"closed": str(self.closed).lower(), **(meta or {})}
        # repr: the shortest text that reads back to the same double (full precision, any size).
        lines = [CSV_HEADER, "# " + ";".join(f"{k}={v}" for k, v in info.items())]
        lines += [",".join(repr(float(v)) for v in row) for row in data]
        atomic_write_text(path, "\n".join(lines) + "\n")

    @classmethod
    def from_csv(cls, path: str | Path, closed: bool | None = None, *,
                 text: str | None = None) -> Reference:
        """Read a CSV written by :meth:`to_csv` (header ``t,x,y,theta,v,omega,kappa``; ``#`` lines
        are metadata); values must be finite, speeds ≥ 0 and the pose consistent with v and ω
        (:func:`check_consistency`). ``closed`` None: as the file says (open when it does not
        say). ``text``: the file's content when the caller has read it already."""
        from tsmpc.textfile import read_text

        p = Path(path)
        if text is None:
            text = read_text(p, "reference")
        lines = [ln for ln in text.splitlines() if ln.strip()]
        if not lines or lines[0].replace(" ", "") != CSV_HEADER:
            raise DataFormatError(f"{p}: expected the header '{CSV_HEADER}'")
        meta = _parse_meta(lines[1:])
        rows = [ln for ln in lines[1:] if not ln.lstrip().startswith("#")]
        first = 1 + len(lines) - len(rows)  # line number of the first data row (1-based)
        from tsmpc.textfile import number

        for i, ln in enumerate(rows):
            if ln.count(",") != 6:
                raise DataFormatError(f"{p}: line {i + first}: expected 7 columns per row "
                                      f"(t,x,y,theta,v,omega,kappa), got {ln.count(',') + 1}")
        try:
            data = np.array([[number(v) for v in ln.split(",")] for ln in rows])
        except ValueError as err:
            raise DataFormatError(f"{p}: non-numeric value ({err})") from None
        if data.ndim != 2 or data.shape[1] != 7:
            raise DataFormatError(f"{p}: expected 7 columns per row (t,x,y,theta,v,omega,kappa)")
        if not np.all(np.isfinite(data)):
            r, c = np.argwhere(~np.isfinite(data))[0]
            raise DataFormatError(f"{p}: line {r + first}: {_SIGNALS[c]} is {data[r, c]} (must be finite)")
        big = np.flatnonzero(np.abs(data[:, 6]) > MAX_CURVATURE)
        if big.size:
            r = int(big[0])
            raise DataFormatError(f"{p}: line {r + first}: kappa = {data[r, 6]:.4g} 1/m; |kappa| must "
                                  f"be <= {MAX_CURVATURE:g} 1/m (a {1 / MAX_CURVATURE:g} m radius)")
        _check_meta(meta, p)
        if closed is None:
            closed = meta.get("closed", "false").strip().lower() == "true"
        try:
            ref = cls(**dict(zip(_SIGNALS, data.T, strict=True)), closed=closed)
        except DataFormatError as err:
            raise DataFormatError(f"{p}: {err}") from None
        check_consistency(ref, str(p), first_sample=first, what="line")
        return ref


def _check_meta(meta: dict[str, str], p: Path) -> None:
    """The metadata a run acts on must be valid: ``closed`` true/false, ``half_width_m`` a finite
    half-width in (0, MAX_HALF_WIDTH_M] (an ``inf`` would switch the divergence check off)."""
    closed = meta.get("closed")
    if closed is not None and closed.strip().lower() not in ("true", "false"):
        raise DataFormatError(f"{p}: metadata closed={closed[:40]!r}: must be true or false")
    hw = meta.get("half_width_m")
    if hw is not None:
        from tsmpc.textfile import number

        try:
            w = number(hw)
        except ValueError:
            w = float("nan")
        if not 0.0 < w <= MAX_HALF_WIDTH_M:  # also refuses nan and inf
            raise DataFormatError(f"{p}: metadata half_width_m={hw[:40]!r}: must be a finite "
                                  f"half-width in (0, {MAX_HALF_WIDTH_M:g}] m")


def check_coordinates(x: NDArray[np.float64], y: NDArray[np.float64], source: str) -> None:
    """|x|, |y| <= :data:`MAX_COORDINATE_M` (refused beyond: see there). Raises
    :class:`DataFormatError` naming ``source`` and the first offending point (1-based)."""
    big = np.flatnonzero((np.abs(x) > MAX_COORDINATE_M) | (np.abs(y) > MAX_COORDINATE_M))
    if big.size:
        k = int(big[0])
        raise DataFormatError(
            f"{source}: point {k + 1} at ({x[k]:.4g}, {y[k]:.4g}) m lies beyond "
            f"±{MAX_COORDINATE_M:g} m (metres expected; shift the data to a local origin: "
            "far from the origin doubles lose the precision the loop needs)")


def _parse_meta(lines: list[str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for ln in lines:
        if ln.lstrip().startswith("#"):
            for item in ln.lstrip()[1:].split(";"):
                if "=" in item:
                    k, v = item.split("=", 1)
                    out[k.strip()] = v.strip()
    return out


def read_csv_meta(path: str | Path) -> dict[str, str]:
    """The ``# key=value`` metadata of a planned CSV (empty for files without any)."""
    from tsmpc.errors import TsmpcError
    from tsmpc.textfile import read_head

    try:
        lines = read_head(path, "reference").splitlines()[:4]
    except TsmpcError:
        return {}
    return _parse_meta(lines[1:])


def check_window(
    window: tuple[int, int], n: int, source: str, unit: str = "column"
) -> tuple[int, int]:
    """Check 1-based inclusive ``window`` = (FIRST, LAST) against ``n`` samples."""
    a, b = window
    if not 1 <= a < b <= n:
        why = ("FIRST must be < LAST" if a >= b else f"allowed {unit}s are 1..{n}")
        raise DataFormatError(f"{source}: --window {a},{b}: {why} (1-based {unit}s FIRST,LAST)")
    return a, b


def check_consistency(ref: Reference, source: str, *, first_sample: int = 1,
                      what: str = "sample") -> None:
    """Speeds ≥ 0 and the pose consistent with v_d and ω_d under the paper's integration
    (x(k) − x(k−1) ≈ v(k) T along θ(k), θ(k) − θ(k−1) ≈ ω(k) T) within
    :data:`POSE_TOLERANCE_M` / :data:`HEADING_TOLERANCE_RAD` + 10 %; the previous sample's
    speed is accepted too (planners differ in that convention). Raises :class:`DataFormatError`
    naming the first bad ``what`` (line / column number)."""
    def where(k: int) -> str:
        return f"{source}: {what} {first_sample + k}"

    neg = np.flatnonzero(ref.v < 0)
    if neg.size:
        k = int(neg[0])
        raise DataFormatError(f"{where(k)}: v = {ref.v[k]:.6g} m/s; speeds must be >= 0")
    dt = ref.dt
    step = np.hypot(np.diff(ref.x), np.diff(ref.y))
    err = np.minimum(np.abs(step - ref.v[1:] * dt), np.abs(step - ref.v[:-1] * dt))
    tol = POSE_TOLERANCE_M + 0.1 * np.maximum(ref.v[1:], ref.v[:-1]) * dt
    bad = np.flatnonzero(err > tol)
    if bad.size:
        k = int(bad[0]) + 1
        raise DataFormatError(
            f"{where(k)}: the position moves {step[k - 1]:.4g} m in one step but v*T = "
            f"{ref.v[k] * dt:.4g} m (tolerance {tol[k - 1]:.3g} m): x, y and v are inconsistent")
    dth = np.diff(ref.theta)
    err = np.minimum(np.abs(dth - ref.omega[1:] * dt), np.abs(dth - ref.omega[:-1] * dt))
    tol = HEADING_TOLERANCE_RAD + 0.1 * np.maximum(np.abs(ref.omega[1:]), np.abs(ref.omega[:-1])) * dt
    bad = np.flatnonzero(err > tol)
    if bad.size:
        k = int(bad[0]) + 1
        raise DataFormatError(
            f"{where(k)}: theta changes {dth[k - 1]:.4g} rad in one step but omega*T = "
            f"{ref.omega[k] * dt:.4g} rad (tolerance {tol[k - 1]:.3g} rad): theta and omega "
            "are inconsistent")
    turn = np.abs(dth)
    if turn.size and turn.max() > MAX_HEADING_STEP_RAD:
        k = int(np.argmax(turn)) + 1
        raise DataFormatError(
            f"{where(k)}: theta turns {turn[k - 1]:.3g} rad in one sample (at most "
            f"{MAX_HEADING_STEP_RAD:g}): the sampling ({dt:g} s) is too coarse for the geometry; "
            "plan the reference with a smaller --dt")
    moving = np.flatnonzero(step > 0.1)
    if moving.size:
        hd = np.arctan2(np.diff(ref.y), np.diff(ref.x))[moving]
        off = np.abs(np.angle(np.exp(1j * (hd - ref.theta[moving + 1]))))
        if off.max() > 0.35:
            k = int(moving[int(np.argmax(off > 0.35))]) + 1
            raise DataFormatError(
                f"{where(k)}: the position moves at {np.degrees(hd[np.argmax(off > 0.35)]):.0f} deg "
                f"but theta = {np.degrees(ref.theta[k]):.0f} deg (tolerance 20 deg): pose and "
                "heading are inconsistent (reversing or mislabelled columns?)")
