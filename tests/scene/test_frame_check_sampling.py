"""The frame check's even sampling and box test equal their plain forms (:mod:`spacedg.scene.frame_check`)."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.scene.box import OrientedBox
from spacedg.scene.frame_check import _even, _holds_any


@pytest.mark.parametrize("n", [0, 1, 2, 3, 7, 47, 48, 49, 95, 20_000, 20_001, 199_999, 200_001, 215_963])
@pytest.mark.parametrize("k", [0, 1, 2, 4, 48, 20_000, 200_000])
def test_even_is_the_sorted_unique_rounded_linspace(n: int, k: int) -> None:
    plain = np.unique(np.linspace(0, n - 1, num=min(n, k)).round().astype(np.int64)) if n else np.zeros(0, np.int64)
    got = _even(n, k)
    assert got.dtype == np.int64 and np.array_equal(got, plain)


def test_holds_any_equals_the_test_of_every_point() -> None:
    box = OrientedBox(np.zeros(3), np.ones(3), np.eye(3))
    far = np.full((64, 3), 5.0)
    for inside_at in (None, 0, 5, 16, 63):  # 16: in the strided subset; 5 and 63: only in the full set
        points = far.copy()
        if inside_at is not None:
            points[inside_at] = 0.1
        assert _holds_any(box, points, 0.0) == bool(box.contains(points).any()) == (inside_at is not None)
    assert _holds_any(box, np.array([[0.55, 0.0, 0.0]]), 0.06) and not _holds_any(box, np.array([[0.57, 0.0, 0.0]]), 0.06)
