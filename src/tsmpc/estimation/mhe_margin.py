"""The MHE-UIO's yaw-model margin (issue 35; beyond the paper): the yaw-rate process covariance
grows when the window shows that the model's slip dynamics do not fit the car.

Why. The MHE-UIO (paper eq. "MHE") weighs the model's three state equations against the two
measurements with the fixed process covariance Q = diag(10, 10, 2). With the model's yaw inertia,
cornering stiffnesses or centre of gravity tens of per cent off the car's, the yaw equation
ω_{k+1} = ω_k + T_d (a F_yF − b F_yR) / I no longer fits the gyro, and the cheapest explanation the
window's QP finds is a body slip α̂ that makes the yaw moment fit: the slip the inner loop then
acts on is the model's error, and on the generalisation benchmark's worst draws the cascade
oscillated in yaw at ten times the oracle-tuned controller's RMSE of ω. A larger Q_ω lets the
window follow the gyro (σ 1e-4 rad/s at 100 Hz) instead, but costs the car the model does fit:
the yaw equation is then what ties α̂ to the measured yaw rate (Q_ω = 4 already costs the nominal
paper run 5 % of max |e_y|).

What. The margin is an adaptive process covariance (Mehra 1972's covariance matching, on the MHE's
own window): after each window solved within its bounds (:data:`~tsmpc.kernels.mhe.MHE_OK`), the
mean square of the slip equation's process residual over the window,
ŵ_α,k = α̂_{k+1} − [A_k x̂_k + B_k u_k + E_k F̂]_α, is compared with its reference
``slip_rate`` · T_d (``mhe.margin_slip_rate``: on the paper reference with the model's own car the
residual's RMS is about 0.007 rad/s, from the tyres' nonlinearity; with the worst draws' yaw
models 0.1–0.2 rad/s). The ratio is smoothed — up within ``rise_s``, down within ``decay_s``
(a wrong model stays wrong; a margin that dropped as soon as it had removed the symptom would
let the oscillation return) — and Q_ω is the configured one times the smoothed ratio, between 1
and ``f_max``. A window that fits keeps the paper's Q_ω exactly.

The block is one function over the estimator's own arrays (the margin's parameters in ``mp``,
its state in ``ms``), in numba's nopython subset: :mod:`tsmpc.kernels.mhe` registers it
(``register_jitable``) into the compiled window step (:func:`tsmpc.kernels.mhe.mhe_solve`, hence the
cascade, the run engine and the batch's scalar lanes) and the batch's vector lanes
(``tsmpc.kernels.batch``) compile it too; the dense QP's numpy path
(:class:`~tsmpc.estimation.mhe_uio.MHEUIO`) calls it as Python. This module imports no numba (the
estimator imports it), and is in the engine's cache key (``tsmpc.kernels.jit.BLOCK_MODULES``).

Only windows whose axle slips stay within ``margin_linear_share`` of the model's saturation slip
μ_o F_z / C count: beyond it the residual is the tyres' nonlinearity, which the TS model does not
have whatever the car, and there the yaw equation still carries what it carries (on the held-back
race tracks at 30 m/s, counted, they raised max |e_y| by 5–13 %).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

__all__ = ["MP_MARGIN", "MS_MARGIN", "N_MARGIN_MP", "margin_apply", "margin_params", "margin_residual",
           "margin_update"]

#: The margin's parameters in the estimator's ``mp`` (after the window's, tsmpc.kernels.mhe's
#: N_MP = 30): [slip residual reference per step [rad], f_max, rise gain T_d/rise_s, decay gain
#: T_d/decay_s, the configured yaw-rate process weight 1/Q_ω, the linear tyres' share of the
#: saturation slip]. A reference of 0 is off.
MP_MARGIN = 30
N_MARGIN_MP = 6
#: The margin's state in the estimator's ``ms``: the smoothed ratio (0 after a reset).
MS_MARGIN = 7
#: The yaw-rate process weight's slot in ``mp`` (tsmpc.kernels.mhe's MP_Q + 2).
_MP_QW = 2
#: The model's M, C_f, C_r, a, b, μ_o g in ``mp`` (tsmpc.kernels.mhe's MP_M …; the numpy path's
#: ``mp`` carries them too)
_MP_M, _MP_CF, _MP_CR, _MP_A, _MP_B, _MP_MUG = 21, 23, 24, 25, 26, 27
#: F̂'s slot in ``ms`` (tsmpc.kernels.mhe's MS_F): the unknown input's column of the window model.
_MS_F = 3


def margin_params(slip_rate: float, f_max: float, rise_s: float, decay_s: float, Q_omega: float,
                  Td: float, linear_share: float) -> list[float]:
    """The margin's ``mp`` entries (:data:`MP_MARGIN` on) of the config's ``mhe.margin_*``, the
    configured Q_ω and T_d (``slip_rate`` 0: off)."""
    return [slip_rate * Td, f_max, min(Td / rise_s, 1.0), min(Td / decay_s, 1.0), 1.0 / Q_omega,
            linear_share]


def margin_update(mp: NDArray[np.float64], ms: NDArray[np.float64], XS: NDArray[np.float64],
                  A: NDArray[np.float64], B: NDArray[np.float64], U: NDArray[np.float64], n: int) -> None:
    """One window solved within its bounds (x̂_0 … x̂_n in ``XS``, the model along it in ``A``,
    ``B`` — only their slip rows are read — the inputs in ``U``, F̂ in ``ms``): the smoothed
    ratio of the slip residual's mean square to its reference into ``ms``, the yaw-rate process
    weight it gives into ``mp`` (:func:`margin_residual`, then :func:`margin_apply`). Off
    (reference 0): nothing."""
    if not mp[MP_MARGIN] > 0.0 or n < 1:
        return
    msq, linear = margin_residual(mp, ms[_MS_F], XS, A, B, U, n)
    margin_apply(mp, ms, msq, linear)


def margin_residual(mp: NDArray[np.float64], F: float, XS: NDArray[np.float64], A: NDArray[np.float64],
                    B: NDArray[np.float64], U: NDArray[np.float64], n: int) -> tuple[float, bool]:
    """The window's arithmetic (n ≥ 1; F̂ = ``F``): (the mean square of the slip equation's
    process residual over the window's n transitions, whether every sample's axle slips stay
    within the linear tyres' share of the saturation slip — always, at share 0). The batch's
    lanes compute the same in their own form (``tsmpc.kernels.batch``, compared in
    tests/test_mhe_margin.py)."""
    lin = mp[MP_MARGIN + 5]
    if lin > 0.0:  # only windows where the model's tyres are linear (see the module docstring)
        L = mp[_MP_A] + mp[_MP_B]
        sat_f = mp[_MP_MUG] * mp[_MP_M] * mp[_MP_B] / (L * mp[_MP_CF])
        sat_r = mp[_MP_MUG] * mp[_MP_M] * mp[_MP_A] / (L * mp[_MP_CR])
        for k in range(n + 1):
            v = max(XS[k, 0], 1.0)
            d = U[min(k, n - 1), 1]
            a_f = d - XS[k, 1] - mp[_MP_A] * XS[k, 2] / v
            a_r = mp[_MP_B] * XS[k, 2] / v - XS[k, 1]
            if abs(a_f) > lin * sat_f or abs(a_r) > lin * sat_r:
                return 0.0, False
    acc = 0.0
    for k in range(n):
        pred = (A[k, 1, 0] * XS[k, 0] + A[k, 1, 1] * XS[k, 1] + A[k, 1, 2] * XS[k, 2]
                + B[k, 1, 0] * (U[k, 0] - F) + B[k, 1, 1] * U[k, 1])  # (E = −B[:, 0])
        w = XS[k + 1, 1] - pred
        acc += w * w
    return acc / n, True


def margin_apply(mp: NDArray[np.float64], ms: NDArray[np.float64], msq: float, linear: bool) -> None:
    """The margin's step on a window's residual mean square ``msq`` (counted when ``linear``):
    the smoothed ratio to the reference's square into ``ms``, the yaw-rate weight into ``mp``."""
    ref = mp[MP_MARGIN]
    if not linear or not ref > 0.0:
        return
    ratio = msq / (ref * ref)
    f = ms[MS_MARGIN]
    g = mp[MP_MARGIN + 2] if ratio > f else mp[MP_MARGIN + 3]
    f += g * (ratio - f)
    ms[MS_MARGIN] = f
    mp[_MP_QW] = mp[MP_MARGIN + 4] / min(max(f, 1.0), mp[MP_MARGIN + 1])
