"""TUMFTM tracks (SPEC §10): all shared tracks load and plan; malformed files are rejected."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tsmpc.config import PlannerSettings
from tsmpc.errors import DataFormatError
from tsmpc.planning.tracks import (
    TUMFTM_HEADER,
    Track,
    is_tumftm,
    lateral_offset,
    load_tumftm,
    off_track,
    plan_track,
)

NAMES = ["Hockenheim", "Monza", "Silverstone", "Spa", "Zandvoort"]


@pytest.mark.parametrize("name", NAMES)
def test_shared_tracks_plan(tracks_dir: Path, name: str) -> None:
    path = tracks_dir / f"{name}.csv"
    assert is_tumftm(path)
    track = load_tumftm(path)
    assert track.name == name and 3000 < track.length < 8000
    st = PlannerSettings()
    ref = plan_track(track, st)
    assert ref.closed
    lap = float(np.sum(ref.v) * ref.dt)
    assert lap == pytest.approx(track.length, rel=0.01)
    assert ref.v.max() <= st.v_max + 1e-6
    assert np.max(np.abs(ref.v**2 * ref.kappa)) <= st.a_lat_max * 1.01
    off = lateral_offset(track, ref.x, ref.y)
    assert np.max(np.abs(off)) < 1.0
    assert not np.any(off_track(track, ref.x, ref.y))


def test_offset_sign_and_off_track() -> None:
    # A square loop driven anticlockwise: the inside is to the left.
    x = np.array([0.0, 100.0, 100.0, 0.0])
    y = np.array([0.0, 0.0, 100.0, 100.0])
    tr = Track("square", x, y, np.full(4, 5.0), np.full(4, 4.0))
    off = lateral_offset(tr, [50.0, 50.0, 50.0], [3.0, -3.0, 10.0])
    np.testing.assert_allclose(off, [3.0, -3.0, 10.0])
    np.testing.assert_array_equal(off_track(tr, [50.0, 50.0, 50.0], [3.0, -3.0, -6.0]), [False, False, True])


@pytest.mark.parametrize(("body", "message"), [
    ("x,y\n1,2\n", "first line"),
    (TUMFTM_HEADER + "\n1,2,3\n", "expected 4 values"),
    (TUMFTM_HEADER + "\n1,2,3,abc\n", "non-numeric"),
    (TUMFTM_HEADER + "\n0,0,1,1\n1,0,1,1\n1,1,1,1\n0,nan,1,1\n", "NaN"),
    (TUMFTM_HEADER + "\n0,0,1,1\n1,0,1,1\n", "at least 4"),
    (TUMFTM_HEADER + "\n0,0,1,1\n1,0,-1,1\n1,1,1,1\n0,1,1,1\n", "positive"),
])
def test_malformed_rejected(tmp_path: Path, body: str, message: str) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(body, encoding="utf-8")
    with pytest.raises(DataFormatError, match=message):
        load_tumftm(path)
