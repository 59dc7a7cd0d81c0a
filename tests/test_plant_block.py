"""The plant's block (issue 34, one definition): the single-track right-hand side and its RK4 steps
(tsmpc.vehicle.single_track.plant_rhs / rk4_steps over the record PlantParams), called by Plant as Python
and compiled into tsmpc.kernels.plant.rk4_block (the Python loop with the kernels on, the run engine,
the batch's exact path); VehiclePlant's friction force and step count, which the engine calls too.

By hand, as Python and compiled: every term of the right-hand side on a linear-tyre state, the
Pacejka force, the friction ellipse and the grip that follows the road, one RK4 step against its
formula. Python = compiled on random inputs. And the batch's lane-vectorised RK4 (rk4_lanes, the
only second form: its polynomial transcendentals round differently) against the scalar block on
random states of every tyre variant."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from tsmpc import kernels
from tsmpc.config import Config, TyreParams
from tsmpc.vehicle.plant import Plant, VehiclePlant, rk4_count
from tsmpc.vehicle.single_track import PlantParams, friction_force, plant_params, plant_rhs, rk4_steps

#: round numbers: M 1000, I 2000, a 1, b 1.5, C_f 40000, drag 0.5, v_floor 0.5, v_eps 0.05, M g 10000,
#: loads 6000/4000, Pacejka C 1.5, E -1, μ_tyre 0.8, linear, C_r 50000
LIN = PlantParams(1000.0, 2000.0, 1.0, 1.5, 40000.0, 0.5, 0.5, 0.05, 10000.0, 6000.0, 4000.0, 1.5, -1.0, 0.8,
                  0.0, True, 50000.0, False)
PAC = LIN._replace(linear=False)



def test_linear_tyre_right_hand_side_by_hand(way) -> None:
    f = way(plant_rhs)
    th, v, al, om, F, d, mu = 0.3, 10.0, 0.02, 0.1, 1500.0, 0.05, 0.4
    fyf = 40000.0 * (d - al - 1.0 * om / v)  # C_f (δ − α − a ω / v)
    fyr = 50000.0 * (1.5 * om / v - al)  # C_r (b ω / v − α)
    res = mu * 10000.0 * math.tanh(v / 0.05)
    out = f(LIN, th, v, al, om, F, d, mu, math.cos(d))
    assert out[0] == pytest.approx(v * math.cos(th + al), rel=1e-15)
    assert out[1] == pytest.approx(v * math.sin(th + al), rel=1e-15)
    assert out[2] == om
    assert out[3] == pytest.approx((F * math.cos(al) - fyf * math.sin(d - al) + fyr * math.sin(al)
                                    - 0.5 * v * v - res) / 1000.0, rel=1e-13)
    assert out[4] == pytest.approx((-F * math.sin(al) + fyf * math.cos(d - al) + fyr * math.cos(al))
                                   / (1000.0 * v) - om, rel=1e-13)
    assert out[5] == pytest.approx((1.0 * fyf * math.cos(d) - 1.5 * fyr) / 2000.0, rel=1e-13)


def test_low_speed_floor_and_resistance(way) -> None:
    f = way(plant_rhs)
    out = f(LIN, 0.0, 0.1, 0.0, 0.2, 0.0, 0.0, 0.5, 1.0)
    fyf, fyr = 40000.0 * (-0.2 / 0.5), 50000.0 * (1.5 * 0.2 / 0.5)  # 1/v at the floor v = 0.5
    assert out[3] == pytest.approx((-0.5 * 0.01 - 0.5 * 10000.0 * math.tanh(2.0)) / 1000.0, rel=1e-13)
    assert out[4] == pytest.approx((fyf + fyr) / (1000.0 * 0.5) - 0.2, rel=1e-13)
    stopped = f(LIN, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.9, 1.0)
    assert stopped[3] == 0.0  # the resistance does not push a stopped car


def _pacejka(C: float, D: float, slip: float) -> float:
    """The magic formula of PAC's tyres: −D sin(C_s atan(B s − E (B s − atan B s))), B = C / (C_s D)."""
    bs = C / (1.5 * D) * slip
    return -D * math.sin(1.5 * math.atan(bs + 1.0 * (bs - math.atan(bs))))


def test_pacejka_force_grip_scale_and_ellipse(way) -> None:
    f = way(plant_rhs)
    v, om = 10.0, 0.5
    fyf = _pacejka(40000.0, 0.8 * 6000.0, math.atan2(1.0 * om, v))  # D = μ_tyre F_z
    fyr = _pacejka(50000.0, 0.8 * 4000.0, math.atan2(-1.5 * om, v))
    out = f(PAC, 0.0, v, 0.0, om, 0.0, 0.0, 0.0, 1.0)
    assert out[4] == pytest.approx((fyf + fyr) / (1000.0 * v) - om, rel=1e-13)
    assert out[5] == pytest.approx((1.0 * fyf - 1.5 * fyr) / 2000.0, rel=1e-13)
    # grip that follows the road: μ_t = μ(road) · grip_scale (here 0.4 · 2 = μ_tyre); none at μ = 0
    assert f(PAC._replace(grip_scale=2.0), 0.0, v, 0.0, om, 0.0, 0.0, 0.4, 1.0)[5] == pytest.approx(
        out[5], rel=1e-13)
    assert f(PAC._replace(grip_scale=1.0), 0.0, v, 0.0, om, 0.0, 0.0, 0.0, 1.0)[5] == 0.0
    # combined slip: the traction F_t = F − F_res (here F_res = 0: μ = 0) shares the rear grip
    # D_R = 3200 N: at F_t = D_R / 2 the lateral force shrinks by sqrt(1 − 1/4); beyond D_R it clips
    comb = PAC._replace(combined=True)
    half = f(comb, 0.0, v, 0.0, om, 1600.0, 0.0, 0.0, 1.0)
    assert half[5] == pytest.approx((1.0 * fyf - 1.5 * fyr * math.sqrt(0.75)) / 2000.0, rel=1e-13)
    assert half[3] == pytest.approx((1600.0 - 0.5 * v * v) / 1000.0, rel=1e-13)
    big = f(comb, 0.0, v, 0.0, 0.0, 1e6, 0.0, 0.0, 1.0)
    assert big[3] == pytest.approx((3200.0 - 0.5 * v * v) / 1000.0, rel=1e-13)
    brake = f(comb, 0.0, v, 0.0, 0.0, -1e6, 0.0, 0.0, 1.0)
    assert brake[3] == pytest.approx((-3200.0 - 0.5 * v * v) / 1000.0, rel=1e-13)
    # no grip at all (the road's μ = 0 with the grip following it): no traction, drag only
    none = f(comb._replace(grip_scale=1.0), 0.0, v, 0.0, 0.0, 1e4, 0.0, 0.0, 1.0)
    assert none[3] == -0.5 * v * v / 1000.0


def test_one_rk4_step_by_hand(way) -> None:
    rhs, step = way(plant_rhs), way(rk4_steps)
    x, F, d, mu, h = (1.0, 2.0, 0.3, 10.0, 0.02, 0.1), 1500.0, 0.05, 0.4, 0.01
    c = math.cos(d)
    k1 = rhs(LIN, *x[2:], F, d, mu, c)
    k2 = rhs(LIN, *(x[i + 2] + h / 2 * k1[i + 2] for i in range(4)), F, d, mu, c)
    k3 = rhs(LIN, *(x[i + 2] + h / 2 * k2[i + 2] for i in range(4)), F, d, mu, c)
    k4 = rhs(LIN, *(x[i + 2] + h * k3[i + 2] for i in range(4)), F, d, mu, c)
    want = [x[i] + h / 6 * (k1[i] + 2 * (k2[i] + k3[i]) + k4[i]) for i in range(6)]
    assert list(step(LIN, *x, F, d, mu, 1, h)) == want
    two = step(LIN, *step(LIN, *x, F, d, mu, 1, h), F, d, mu, 1, h)
    assert step(LIN, *x, F, d, mu, 2, h) == two


def test_friction_force_and_step_count() -> None:
    assert friction_force(0.02, 10000.0, 0.5) == (0.5 - 0.02) * 10000.0
    assert rk4_count(0.01, 0.001) == 10
    assert rk4_count(0.0105, 0.001) is None and rk4_count(0.0, 0.001) is None


def _random(rng: np.random.Generator) -> tuple:
    """A random state (low speed, reversing included), input and road."""
    x = (*rng.normal(0, 50, 2), rng.normal(0, 3), rng.uniform(-1, 20), rng.normal(0, 0.1), rng.normal(0, 0.5))
    return tuple(float(v) for v in x), float(rng.normal(0, 4000)), float(rng.uniform(-0.45, 0.45)), \
        float(rng.uniform(0.0, 1.0))


_VARIANTS = [dict(model="pacejka"), dict(model="linear"), dict(model="pacejka", combined_slip=True),
             dict(model="pacejka", scale_grip_with_road=True, combined_slip=True)]


@pytest.mark.parametrize("tyre", _VARIANTS)
def test_compiled_equals_python(cfg: Config, tyre: dict) -> None:
    """The compiled block (rk4_block) and the same functions as Python, on random inputs: equal to
    the bit (CPython's math and the compiled code call the same libm)."""
    kp = kernels.load("plant")
    if kp is None:
        pytest.skip("compiled kernels unavailable")
    p = plant_params(cfg.vehicle, TyreParams(**tyre))
    cst = kp.pack(Plant(cfg.vehicle, TyreParams(**tyre), cfg.rates.h))
    assert list(cst) == [float(v) for v in p]
    rng = np.random.default_rng(5)
    for _ in range(200):
        x, F, d, mu = _random(rng)
        n = int(rng.integers(1, 12))
        out, ok = kp.rk4_block(np.array(x), F, d, mu, n, cfg.rates.h, cst)
        assert ok
        assert tuple(out) == rk4_steps(p, *x, F, d, mu, n, cfg.rates.h)


@pytest.mark.parametrize("tyre", _VARIANTS)
def test_lane_rk4_equals_the_scalar_block(cfg: Config, tyre: dict) -> None:
    """The batch's vector RK4 (rk4_lanes: every tyre variant computed and selected, polynomial
    sin/cos/atan/tanh) against the scalar block on LANES random lanes: equal to ≤ 1e-10 relative
    over 10 steps of 1 ms (measured ≤ 2e-13)."""
    kp = kernels.load("plant")
    if kp is None:
        pytest.skip("compiled kernels unavailable")
    from tsmpc.kernels import batch as kb
    from tsmpc.kernels import engine as ke

    plant = Plant(cfg.vehicle, TyreParams(**tyre), cfg.rates.h)
    rng = np.random.default_rng(17)
    pw = np.zeros(kb.PW_ROWS * kb.LANES)
    lanes = []
    for j in range(kb.LANES):
        x, F, d, mu = _random(rng)
        sc = np.zeros(ke.N_SC)
        sc[ke.SC_OF], sc[ke.SC_OD], sc[ke.SC_MU] = F, d, mu
        kb._plant_gather(pw, j, np.array(x), sc, plant._cst)
        lanes.append((x, F, d, mu))
    n = 10
    kb.rk4_lanes(pw, n, cfg.rates.h)
    for j, (x, F, d, mu) in enumerate(lanes):
        want, ok = kp.rk4_block(np.array(x), F, d, mu, n, cfg.rates.h, plant._cst)
        assert ok
        got = np.array([pw[(kb.PW_X + i) * kb.LANES + j] for i in range(6)])
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-10, err_msg=f"lane {j}")


def test_vehicle_plant_reports_the_blocks(cfg: Config) -> None:
    vp = VehiclePlant(cfg.vehicle, cfg.tyre, cfg.rates.h)
    vp.reset(np.array([0.0, 0.0, 0.0, 10.0, 0.0, 0.0]))
    vp.step((800.0, 0.01), cfg.rates.Td, 0.6)
    assert vp.friction_force == friction_force(cfg.vehicle.mu_nominal, cfg.vehicle.mass * cfg.vehicle.g, 0.6)
    with pytest.raises(ValueError, match="multiple of h"):
        vp.step((800.0, 0.01), 0.0105, 0.6)


def test_the_plant_kernels_cache_entries_follow_the_block_source(tmp_path: Path,
                                                                  monkeypatch: pytest.MonkeyPatch) -> None:
    """numba keys kernels/plant.py's entries by that file only, yet they contain
    vehicle/single_track.py's arithmetic: entries stamped with another version of it are deleted,
    entries of this version are kept (the stamp read through tsmpc.textfile)."""
    import hashlib

    from tsmpc.kernels import plant as kplant

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    folder = kernels._tree_folder(tmp_path)
    folder.mkdir(parents=True)
    entry = folder / "plant.rk4_block-1.py311.nbi"
    entry.write_bytes(b"old")
    (folder / "plant.blocks-sha256").write_text("another version\n")
    kplant._forget_stale_entries()
    assert not entry.exists()
    source = Path(kplant.__file__).resolve().parents[1] / "vehicle" / "single_track.py"
    digest = hashlib.sha256(source.read_bytes()).hexdigest()
    assert (folder / "plant.blocks-sha256").read_text() == digest
    entry.write_bytes(b"current")
    kplant._forget_stale_entries()
    assert entry.read_bytes() == b"current"
