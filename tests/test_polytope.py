"""Scheduling box and memberships: partition of unity, vertex order, multilinear exactness."""

from __future__ import annotations

import numpy as np
import pytest

from tsmpc.models.polytope import SchedulingBox


@pytest.fixture()
def box() -> SchedulingBox:
    return SchedulingBox(("a", "b", "c"), (-1.0, 2.0, 0.5), (1.0, 5.0, 1.0))


def test_vertex_order_is_documented(box: SchedulingBox) -> None:
    v = box.vertices()
    assert v.shape == (8, 3)
    # First premise is the most significant bit; 0 = lower bound.
    np.testing.assert_array_equal(v[0], box.lower)
    np.testing.assert_array_equal(v[7], box.upper)
    np.testing.assert_array_equal(v[4], [1.0, 2.0, 0.5])
    np.testing.assert_array_equal(v[1], [-1.0, 2.0, 1.0])


def test_memberships_partition_of_unity_and_vertices(box: SchedulingBox) -> None:
    rng = np.random.default_rng(0)
    z = rng.uniform(box.lower, box.upper, size=(1000, 3))
    mu = box.memberships(z)
    assert np.all(mu >= 0.0)
    np.testing.assert_allclose(mu.sum(axis=-1), 1.0, atol=1e-14)
    np.testing.assert_allclose(box.memberships(box.vertices()), np.eye(8), atol=1e-15)


def test_multilinear_functions_are_reproduced_exactly(box: SchedulingBox) -> None:
    rng = np.random.default_rng(1)
    z = rng.uniform(box.lower, box.upper, size=(500, 3))

    def f(q: np.ndarray) -> np.ndarray:
        return 3.0 + q[..., 0] - 2 * q[..., 1] * q[..., 2] + q[..., 0] * q[..., 1] * q[..., 2]

    approx = box.blend(box.memberships(z), f(box.vertices()))
    np.testing.assert_allclose(approx, f(z), rtol=0, atol=1e-12)


def test_clip_counts_points_outside(box: SchedulingBox) -> None:
    z = np.array([[0.0, 3.0, 0.7], [2.0, 3.0, 0.7], [0.0, 9.0, 0.1]])
    zc, n = box.clip(z)
    assert n == 2
    assert box.contains(zc).all()
    np.testing.assert_allclose(box.memberships(z[1]), box.memberships(zc[1]))


def test_rejects_bad_bounds() -> None:
    with pytest.raises(ValueError, match="lower < upper"):
        SchedulingBox(("a",), (1.0,), (1.0,))
