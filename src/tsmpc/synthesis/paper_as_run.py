"""The dynamic TS-LMI-LQR as the published run solved it (SPEC §14): a quirk of that run, not a
recommendation (``dynamic_lmi.formulation = "feasibility-euler"``, the ``paper-as-run`` preset).

Problem. The Apkarian-augmented model ``[v, α, ω, F_f, δ_f, ζ]`` of :mod:`tsmpc.models.dynamic`
discretised by **Euler** at ``T_d`` (the published run: 1 ms) at the **8 vertices** of the box
(δ, v, α) only, one common ``Y = P⁻¹`` and one ``W_i`` per vertex, the paper's LQR-LMI at each
vertex (the Schur form of ``(A_i + B K_i)ᵀ P (A_i + B K_i) − P + Q + K_iᵀ R K_i ≺ 0``,
``K_i = W_i Y⁻¹``, as in :mod:`tsmpc.synthesis.kinematic`) and **no objective**: a feasibility
problem. Clarabel (interior point) returns a point deep inside the feasible set, so the answer is
reproducible, but it is one point of many: the published gains are unknown (SPEC §14), and the
gains this design returns are documented where they matter (the steering row's δ_f and ζ entries
set the start-up transient of the ``paper-as-run`` preset).

What is *not* certified, by construction of the published design: the interpolated loop between
the vertices (the model is not affine in the premises, SPEC §6) and, with the as-run law's
unclipped memberships, anything outside the box. :func:`grid_report` measures the former on a
dense grid (Euler model) and reports it; it does not reject the design. The numerical conditioning
uses the state and input scaling of :mod:`tsmpc.synthesis.dynamic` (reused by import).

Certificates (numpy, recomputed from the stored K and P, also on every cache load): P ≻ 0 and the
Riccati inequality at each vertex relative to P — what the SDP imposed, with the relative margin of
:mod:`tsmpc.synthesis.sdp` built into the LMIs (still no objective) so that the certificates hold
on any machine.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tsmpc.config import Config, DynamicBox, DynamicLMISettings, VehicleParams
from tsmpc.errors import SolverError, TsmpcError
from tsmpc.models.dynamic import Discretization, augment_apkarian, continuous_matrices, discretize
from tsmpc.models.polytope import SchedulingBox
from tsmpc.synthesis.certificates import Certificate, check, definite_certificate, lmi_certificate
from tsmpc.synthesis.dynamic import INPUT_SCALE, STATE_SCALE, check_grid
from tsmpc.synthesis.sdp import LADDER_FLOOR, Infeasible, SDPSolver, solve, solve_with_margin

__all__ = [
    "FeasibilityDesign",
    "certify_vertices",
    "design_feasibility",
    "grid_report",
    "load_or_design_feasibility",
    "vertex_models",
]


#: Margins tried for the published run's design: the smallest that certifies on any machine
#: first (the published LMI was only marginally feasible: a larger margin moves its gains).
AS_RUN_LADDER = (LADDER_FLOOR,)


@dataclass(frozen=True)
class FeasibilityDesign:
    """The published run's dynamic design (vertex order of
    :class:`~tsmpc.models.dynamic.DynamicTS`); the fields of
    :class:`~tsmpc.synthesis.dynamic.DynamicDesign`, so ``tsmpc design`` prints either.

    ``K[i]`` (2 × 6) maps ``[v, α, ω, F_f, δ_f, ζ]`` to the filter input ``[F_xR, δ]`` (u = K x,
    physical units)."""

    K: NDArray[np.float64]  #: (8, 2, 6)
    P: NDArray[np.float64]  #: (6, 6) common Lyapunov matrix, physical units
    Td: float
    bandwidth: float
    certificates: tuple[Certificate, ...]  #: P ≻ 0 and the 8 vertex LMIs, recomputed
    grid_max_rho: float  #: informational: largest spectral radius of the interpolated loop on the grid
    grid_max_decrease: float  #: informational: largest λ(P⁻¹A_clᵀPA_cl) on the grid (< 1: decrease)
    solve_time_s: float
    status: str
    formulation: str = ("feasibility LMI (no objective), common P, 8 vertices, Euler "
                        "(the published run's; a quirk, not a recommendation)")
    inputs_hash: str = ""
    margin_imposed: float = 0.0  #: relative margin t of the vertex LMIs (sdp.solve_with_margin)
    solver: str = "CLARABEL"


def _premise_box(box: DynamicBox) -> SchedulingBox:
    return SchedulingBox(("delta", "v", "alpha"), (box.delta[0], box.v[0], box.alpha[0]),
                         (box.delta[1], box.v[1], box.alpha[1]))


def vertex_models(
    box: DynamicBox, vehicle: VehicleParams, Td: float, bandwidth: float
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Euler-discretised augmented (A (8, 6, 6), B (8, 6, 2)) at the 8 vertices of ``box``."""
    return _euler_augmented(_premise_box(box).vertices(), vehicle, Td, bandwidth)


def _euler_augmented(z: NDArray[np.float64], vehicle: VehicleParams, Td: float, bandwidth: float
                     ) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    z = np.asarray(z, float)
    Ac, Bc = continuous_matrices(z[..., 1], z[..., 0], vehicle)
    Aa, Ba = augment_apkarian(Ac, Bc, bandwidth)
    return discretize(Aa, np.broadcast_to(Ba, (*Aa.shape[:-2], 6, 2)), Td, Discretization.EULER)


def _scaled_weights(settings: DynamicLMISettings) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """(Q, R) in the scaled coordinates, normalised by their largest entry (feasibility of the
    Riccati inequality is invariant to a common scale of Q and R: P scales with them)."""
    Tx, Tu = np.diag(STATE_SCALE), np.diag(INPUT_SCALE)
    Q = Tx @ np.diag(settings.Q) @ Tx
    R = Tu @ np.diag(settings.R) @ Tu
    s = 1.0 / max(Q.max(), R.max())
    return Q * s, R * s


def design_feasibility(
    box: DynamicBox, vehicle: VehicleParams, settings: DynamicLMISettings, Td: float,
    inputs_hash: str = "",
) -> FeasibilityDesign:
    """Solve the published run's feasibility LMI with cvxpy + Clarabel and certify its vertices.

    Raises :class:`SolverError` when Clarabel finds no feasible point and
    :class:`~tsmpc.errors.CertificateError` when a recomputed vertex certificate fails.
    """
    import cvxpy as cp

    t0 = time.perf_counter()
    lam = settings.filter_bandwidth
    A, B = vertex_models(box, vehicle, Td, lam)
    Tx, Tu = np.diag(STATE_SCALE), np.diag(INPUT_SCALE)
    Txi = np.diag(1.0 / STATE_SCALE)
    As, Bs = Txi @ A @ Tx, Txi @ B @ Tu
    Qs, Rs = _scaled_weights(settings)
    Qh, Rh = np.sqrt(Qs), np.sqrt(Rs)
    n, m = 6, 2
    what = f"feasibility TS-LMI-LQR at Td={Td}"

    def attempt(t: float) -> tuple[NDArray[np.float64], NDArray[np.float64], str]:
        # The paper's vertex LMI with the certificates' relative margin t ((1 − t) Y in the
        # corner, see tsmpc.synthesis.sdp): still a feasibility problem, no objective.
        Y = cp.Variable((n, n), symmetric=True)
        W = [cp.Variable((m, n)) for _ in range(A.shape[0])]
        Zn, Znm = np.zeros((n, n)), np.zeros((n, m))
        cons = []
        for i in range(A.shape[0]):
            AY = As[i] @ Y + Bs[i] @ W[i]
            M = cp.bmat([
                [(1.0 - t) * Y, AY.T, (Qh @ Y).T, (Rh @ W[i]).T],
                [AY, Y, Zn, Znm],
                [Qh @ Y, Zn, np.eye(n), Znm],
                [Rh @ W[i], Znm.T, Znm.T, np.eye(m)],
            ])
            cons.append(0.5 * (M + M.T) >> 0)
        status = solve(cp.Problem(cp.Minimize(0), cons), SDPSolver.CLARABEL, what)
        if Y.value is None or any(w.value is None for w in W):
            raise Infeasible(status)
        Ys = 0.5 * (Y.value + Y.value.T)
        Ps = np.linalg.inv(Ys)
        K = Tu @ np.array([w.value @ Ps for w in W]) @ Txi
        P = Txi @ Ps @ Txi
        return K, 0.5 * (P + P.T), status

    try:
        (K, P, status), certs, t_imp = solve_with_margin(
            attempt, lambda r: certify_vertices(A, B, settings, r[0], r[1]),
            f"feasibility dynamic design (Td={Td})", ladder=AS_RUN_LADDER)
    except Infeasible as exc:
        raise SolverError(f"{what}: Clarabel returned {exc.status!r} (the published run's LMI is "
                          "only marginally feasible)") from None
    rho, dec = grid_report(K, P, box, vehicle, Td, lam, settings.grid_points)
    return FeasibilityDesign(K=K, P=P, Td=float(Td), bandwidth=lam, certificates=tuple(certs),
                             grid_max_rho=rho, grid_max_decrease=dec,
                             solve_time_s=time.perf_counter() - t0, status=status,
                             inputs_hash=inputs_hash, margin_imposed=t_imp)


def certify_vertices(
    A: NDArray[np.float64], B: NDArray[np.float64], settings: DynamicLMISettings,
    K: NDArray[np.float64], P: NDArray[np.float64],
) -> list[Certificate]:
    """Recompute with numpy what the SDP imposed: P ≻ 0 and, at every vertex i,
    ``Y [(A_i + B_i K_i)ᵀ P (A_i + B_i K_i) − P + Q + K_iᵀ R K_i] Y ≺ 0`` (Y = P⁻¹), in the
    scaled coordinates of the solve; relative margins with respect to P (scale-free)."""
    Tx, Tu = np.diag(STATE_SCALE), np.diag(INPUT_SCALE)
    Txi, Tui = np.diag(1.0 / STATE_SCALE), np.diag(1.0 / INPUT_SCALE)
    Qs, Rs = _scaled_weights(settings)
    Ps = Tx @ P @ Tx
    Ps = 0.5 * (Ps + Ps.T)
    certs = [definite_certificate("P positive definite (scaled states)", Ps)]
    if not certs[0].holds:
        return certs
    As, Bs = Txi @ A @ Tx, Txi @ B @ Tu
    Ks = Tui @ K @ Tx
    for i in range(A.shape[0]):
        Acl = As[i] + Bs[i] @ Ks[i]
        ric = Acl.T @ Ps @ Acl - Ps + Qs + Ks[i].T @ Rs @ Ks[i]
        certs.append(lmi_certificate(f"LQR decrease, vertex {i}", ric, Ps))
    return certs


def grid_report(
    K: NDArray[np.float64], P: NDArray[np.float64], box: DynamicBox, vehicle: VehicleParams,
    Td: float, bandwidth: float, n: int,
) -> tuple[float, float]:
    """Informational dense-grid check of the interpolated loop (Euler model, memberships inside
    the box): (max spectral radius, max generalised eigenvalue of (A_clᵀPA_cl, P)). Values ≥ 1
    mean the vertex-only design does not certify the loop there — a property of the published
    design, reported, not raised."""
    pb = _premise_box(box)
    z = check_grid(box, n)
    A, B = _euler_augmented(z, vehicle, Td, bandwidth)
    Kg = np.tensordot(pb.memberships(z), K, axes=(1, 0))
    Acl = A + B @ Kg
    rho = float(np.max(np.abs(np.linalg.eigvals(Acl))))
    Li = np.linalg.inv(np.linalg.cholesky(P))
    G = Li @ np.swapaxes(Acl, -1, -2) @ P @ Acl @ Li.T
    dec = float(np.max(np.linalg.eigvalsh(0.5 * (G + np.swapaxes(G, -1, -2)))))
    return rho, dec


# -- cache (the files of tsmpc.synthesis.cache, own record type) ------------------------------
def _to_dict(d: FeasibilityDesign) -> dict[str, Any]:
    out: dict[str, Any] = {"type": type(d).__name__}
    for f in fields(d):
        value = getattr(d, f.name)
        if isinstance(value, np.ndarray):
            out[f.name] = value.tolist()
        elif f.name == "certificates":
            out[f.name] = [{**asdict(c), "holds": c.holds} for c in value]
        else:
            out[f.name] = value
    return out


def _from_dict(data: dict[str, Any]) -> FeasibilityDesign:
    if data.get("type") != FeasibilityDesign.__name__:
        raise ValueError("not a feasibility design")
    kw: dict[str, Any] = {}
    for f in fields(FeasibilityDesign):
        value = data[f.name]
        if f.name == "certificates":
            value = tuple(Certificate(c["name"], float(c["margin"]), float(c["relative"]))
                          for c in value)
        elif isinstance(value, list):
            value = np.asarray(value, dtype=float)
        kw[f.name] = value
    return FeasibilityDesign(**kw)


def load_or_design_feasibility(
    cfg: Config, directory: Path | None = None, *, use_cache: bool = True
) -> FeasibilityDesign:
    """The feasibility design of ``cfg`` from the design cache (keyed like every dynamic design,
    :func:`tsmpc.synthesis.cache.dynamic_key`), solved and stored when missing. The vertex
    certificates are recomputed on load; a stale or tampered entry is re-solved."""
    from tsmpc.io import atomic_write_text
    from tsmpc.synthesis.cache import cache_dir, dynamic_key

    key = dynamic_key(cfg)
    path = (directory or cache_dir()) / f"dynamic-{key[:32]}.json"
    lmi = cfg.dynamic_lmi
    if use_cache and path.exists():
        try:
            d = _from_dict(json.loads(path.read_text()))
            if d.inputs_hash == key:
                A, B = vertex_models(cfg.dynamic_box, cfg.vehicle, d.Td, d.bandwidth)
                check(certify_vertices(A, B, lmi, d.K, d.P), "cached feasibility design")
                return d
        except (TsmpcError, KeyError, ValueError, TypeError, np.linalg.LinAlgError,
                json.JSONDecodeError):
            pass  # unreadable or stale entry: re-solve and overwrite it
    d = design_feasibility(cfg.dynamic_box, cfg.vehicle, lmi, cfg.rates.Td, inputs_hash=key)
    if use_cache:
        try:
            atomic_write_text(path, json.dumps(_to_dict(d)))
        except OSError:
            pass  # a read-only home must not stop a run
    return d
