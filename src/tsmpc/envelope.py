"""Operating envelope: do the designs' scheduling boxes cover the reference a run follows?
(beyond the paper: the operating envelope; issue 15.)

A TS design is certified on its scheduling box only; outside it the memberships are clipped and
neither the exactness of the TS model nor the LMI certificates say anything.
Before a run the reference's ranges are compared with every box and bound that must contain
them:

==========================  ==========================================================
reference range             boxes / bounds that must cover it
==========================  ==========================================================
v_d                         kinematic box v_d, dynamic box v, MPC u_max[v], terminal-set
                            ū[v], MHE x_max[v]
ω_d = v_d κ                 kinematic box ω, MPC u bounds[ω], terminal-set ū[ω], MHE ω bounds
δ, α implied by (v_d, ω_d)  dynamic box δ and α, MHE α bounds (steady state of the nominal
                            model, the inner loop's equilibrium)
==========================  ==========================================================

(the curvature enters through ω_d = v_d κ and the implied δ; the lateral acceleration v_d ω_d is
reported: the tyres, not a box, limit it — a plan beyond their grip diverges and is reported so.)

:func:`fit_envelope` widens what does not cover the reference by a margin (default 10 %) and
returns the new config — its designs are then solved and certified once and cached like any other;
``strict=True`` refuses instead, naming the range and the option. Only *upper* speed bounds are
widened: the low-speed floors of the boxes are the documented low-speed behaviour (the paper's dynamic model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from tsmpc.config import Config, replace
from tsmpc.errors import TsmpcError
from tsmpc.planning.reference import Reference

__all__ = ["EnvelopeError", "EnvelopeFit", "ReferenceRanges", "Shortfall", "fit_envelope",
           "reference_ranges", "shortfalls"]

#: Default relative margin added to the reference's ranges when boxes are widened.
MARGIN = 0.10


class EnvelopeError(TsmpcError, ValueError):
    """The reference leaves the designs' scheduling boxes and they may not (or cannot) be widened."""


@dataclass(frozen=True)
class ReferenceRanges:
    """Extremes of a reference and of the steady state it implies (nominal model)."""

    v_max: float  #: max v_d [m/s]
    omega_max: float  #: max |ω_d| [rad/s]
    kappa_max: float  #: max |κ| [1/m]
    a_lat_max: float  #: max |v_d ω_d| [m/s²]
    delta_max: float  #: max |δ| of the steady state at (v_d, ω_d) [rad]
    alpha_max: float  #: max |α| of the steady state at (v_d, ω_d) [rad]

    def describe(self) -> str:
        """One line of the ranges."""
        return (f"v_d ≤ {self.v_max:.1f} m/s, |ω_d| ≤ {self.omega_max:.2f} rad/s, "
                f"|κ| ≤ {self.kappa_max:.3f} 1/m, a_lat ≤ {self.a_lat_max:.1f} m/s², "
                f"|δ| ≤ {math.degrees(self.delta_max):.1f}°, |α| ≤ {self.alpha_max:.3f} rad")


@dataclass(frozen=True)
class Shortfall:
    """One bound that does not cover the reference: the range needed and the config field."""

    what: str  #: the reference's range, e.g. "v_d up to 25.0 m/s"
    field: str  #: the config field, e.g. "kinematic_box.v_d"
    have: float  #: its current (upper / symmetric) bound
    need: float  #: the bound the reference needs, margin included


@dataclass(frozen=True)
class EnvelopeFit:
    """Result of :func:`fit_envelope`: the config to run and what was changed."""

    config: Config
    ranges: ReferenceRanges
    widened: tuple[Shortfall, ...]

    @property
    def message(self) -> str:
        """One line for the user ('' when nothing was widened)."""
        if not self.widened:
            return ""
        fields = ", ".join(sorted({s.field for s in self.widened}))
        return (f"scheduling boxes widened to cover the reference ({self.ranges.describe()}): "
                f"{fields}; their designs are solved and certified next (cached)")


def reference_ranges(ref: Reference, cfg: Config) -> ReferenceRanges:
    """Ranges of ``ref`` and the steady-state δ, α of the nominal model along it."""
    from tsmpc.models.dynamic import steady_states

    v = np.asarray(ref.v, dtype=float)
    w = np.asarray(ref.omega, dtype=float)
    # Steady states on a coarse grid of the (v, |ω|) pairs met (symmetry in ω): cheap and tight.
    pairs = np.unique(np.round(np.stack([np.maximum(v, 0.5), np.abs(w)], axis=1), 2), axis=0)
    alpha, delta = steady_states(pairs[:, 0], pairs[:, 1], cfg.vehicle)
    d_max, a_max = float(np.abs(delta).max(initial=0.0)), float(np.abs(alpha).max(initial=0.0))
    return ReferenceRanges(
        v_max=float(v.max()), omega_max=float(np.abs(w).max()),
        kappa_max=float(np.abs(ref.kappa).max()), a_lat_max=float(np.abs(v * w).max()),
        delta_max=d_max, alpha_max=a_max,
    )


def _ceil(x: float, step: float) -> float:
    return round(math.ceil(x / step - 1e-9) * step, 6)


def shortfalls(cfg: Config, r: ReferenceRanges, margin: float = MARGIN) -> list[Shortfall]:
    """Every box or bound of ``cfg`` that does not contain the ranges ``r`` (with ``margin``)."""
    k = 1.0 + margin
    # Rounded up to a coarse grid so that similar plans share their (cached) designs.
    v, w = _ceil(r.v_max * k, 0.5), _ceil(r.omega_max * k, 0.05)
    d, a = _ceil(r.delta_max * k, math.radians(1.0)), _ceil(r.alpha_max * k, 0.01)
    vs = f"v_d up to {r.v_max:.1f} m/s"
    ws = f"|ω_d| up to {r.omega_max:.2f} rad/s"
    ds = f"steady-state |δ| up to {math.degrees(r.delta_max):.1f}°"
    als = f"steady-state |α| up to {r.alpha_max:.3f} rad"
    kb, db, mpc, mhe, lmi = cfg.kinematic_box, cfg.dynamic_box, cfg.mpc, cfg.mhe, cfg.kinematic_lmi
    # Bounds that must exceed the reference only when it reaches past them (no margin on
    # boxes that already cover it: an unchanged config keeps its cached designs).
    checks = [
        (vs, "kinematic_box.v_d", kb.v_d[1], r.v_max, v),
        (vs, "dynamic_box.v", db.v[1], r.v_max, v),
        (vs, "mpc.u_max[v]", mpc.u_max[0], r.v_max, v),
        (vs, "kinematic_lmi.u_bar[v]", lmi.u_bar[0], r.v_max, v),
        (vs, "mhe.x_max[v]", mhe.x_max[0], r.v_max, v),
        (ws, "kinematic_box.omega", min(-kb.omega[0], kb.omega[1]), r.omega_max, w),
        (ws, "mpc.u_max[ω]", min(-mpc.u_min[1], mpc.u_max[1]), r.omega_max, w),
        (ws, "kinematic_lmi.u_bar[ω]", lmi.u_bar[1], r.omega_max, w),
        (ws, "mhe.x_max[ω]", min(-mhe.x_min[2], mhe.x_max[2]), r.omega_max, w),
        (ds, "dynamic_box.delta", min(-db.delta[0], db.delta[1]), r.delta_max, d),
        (als, "dynamic_box.alpha", min(-db.alpha[0], db.alpha[1]), r.alpha_max, a),
        (als, "mhe.x_max[α]", min(-mhe.x_min[1], mhe.x_max[1]), r.alpha_max, a),
    ]
    return [Shortfall(what, field, have, need) for what, field, have, raw, need in checks
            if raw > have]


def _widened(cfg: Config, short: list[Shortfall]) -> Config:
    need = {s.field: s.need for s in short}

    def up(pair: tuple[float, float], key: str) -> tuple[float, float]:
        return (pair[0], max(pair[1], need[key])) if key in need else pair

    def sym(pair: tuple[float, float], key: str) -> tuple[float, float]:
        if key not in need:
            return pair
        return (min(pair[0], -need[key]), max(pair[1], need[key]))

    kb, db, mpc, mhe, lmi = cfg.kinematic_box, cfg.dynamic_box, cfg.mpc, cfg.mhe, cfg.kinematic_lmi
    u_lo, u_hi = list(mpc.u_min), list(mpc.u_max)
    u_hi[0] = up((u_lo[0], u_hi[0]), "mpc.u_max[v]")[1]
    u_lo[1], u_hi[1] = sym((u_lo[1], u_hi[1]), "mpc.u_max[ω]")
    x_lo, x_hi = list(mhe.x_min), list(mhe.x_max)
    x_hi[0] = up((x_lo[0], x_hi[0]), "mhe.x_max[v]")[1]
    x_lo[1], x_hi[1] = sym((x_lo[1], x_hi[1]), "mhe.x_max[α]")
    x_lo[2], x_hi[2] = sym((x_lo[2], x_hi[2]), "mhe.x_max[ω]")
    ubar = (max(lmi.u_bar[0], need.get("kinematic_lmi.u_bar[v]", 0.0)),
            max(lmi.u_bar[1], need.get("kinematic_lmi.u_bar[ω]", 0.0)))
    return replace(
        cfg,
        kinematic_box=replace(kb, v_d=up(kb.v_d, "kinematic_box.v_d"),
                              omega=sym(kb.omega, "kinematic_box.omega")),
        dynamic_box=replace(db, v=up(db.v, "dynamic_box.v"), delta=sym(db.delta, "dynamic_box.delta"),
                            alpha=sym(db.alpha, "dynamic_box.alpha")),
        mpc=replace(mpc, u_min=tuple(u_lo), u_max=tuple(u_hi)),
        mhe=replace(mhe, x_min=tuple(x_lo), x_max=tuple(x_hi)),
        kinematic_lmi=replace(lmi, u_bar=ubar),
    )


def fit_envelope(cfg: Config, ref: Reference, *, strict: bool = False,
                 margin: float = MARGIN) -> EnvelopeFit:
    """Check ``ref`` against the boxes of ``cfg``; widen what does not cover it (``strict``:
    refuse, naming the range and the option). A steering angle beyond the actuator's limit
    cannot be fixed by a box: always refused. The designs of the returned config still have
    to be solved and certified (:func:`tsmpc.synthesis.cache.load_or_design_kinematic`, ...)."""
    r = reference_ranges(ref, cfg)
    short = shortfalls(cfg, r, margin)
    if not short:
        return EnvelopeFit(cfg, r, ())
    if r.delta_max > cfg.lqr.delta_max:
        raise EnvelopeError(
            f"reference needs |δ| up to {math.degrees(r.delta_max):.1f}° in steady state, beyond the "
            f"steering limit {math.degrees(cfg.lqr.delta_max):.1f}° (lqr.delta_max): re-plan with "
            "lower speeds in tight corners")
    if strict:
        s = short[0]
        more = f" (and {len(short) - 1} more bound(s))" if len(short) > 1 else ""
        raise EnvelopeError(
            f"reference leaves the design box: {s.what} exceeds {s.field} = {s.have:g}{more}; "
            f"set {s.field} ≥ {s.need:.3g} in --config, or drop --strict-box to widen the boxes "
            "automatically")
    return EnvelopeFit(_widened(cfg, short), r, tuple(short))
