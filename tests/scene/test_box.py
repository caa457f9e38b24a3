"""Oriented boxes: corner recovery in any order, containment, separating-axis intersection."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.scene.box import OrientedBox
from spacedg.errors import InvalidDataError
from spacedg.render.gaussians import quat_to_matrix


def _random_rotation(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=(1, 4))
    return quat_to_matrix(q / np.linalg.norm(q))[0]


@pytest.mark.parametrize("extents", [[1, 1, 1], [0.1, 0.2, 3.0], [0.5, 0.5, 0.0], [2.0, 0.01, 0.01]])
def test_from_corners_recovers_boxes_from_shuffled_corners(rng, extents):
    for _ in range(10):
        box = OrientedBox(rng.normal(size=3), extents, _random_rotation(rng))
        got = OrientedBox.from_corners(box.corners()[rng.permutation(8)])
        np.testing.assert_allclose(sorted(got.extents), sorted(extents), atol=1e-9)
        np.testing.assert_allclose(got.center, box.center, atol=1e-12)
        dist = np.linalg.norm(got.corners()[:, None] - box.corners()[None], axis=2).min(axis=1)
        assert dist.max() < 1e-9


def test_from_corners_rejects_non_boxes(rng):
    with pytest.raises(InvalidDataError, match="do not form a box"):
        OrientedBox.from_corners(rng.normal(size=(8, 3)))
    with pytest.raises(InvalidDataError, match="8 finite 3D points"):
        OrientedBox.from_corners(np.zeros((7, 3)))


def test_contains_and_extent_along(rng):
    rot = _random_rotation(rng)
    box = OrientedBox([1.0, 2.0, 3.0], [2.0, 1.0, 0.5], rot)
    inside = box.center + (rng.uniform(-0.49, 0.49, (100, 3)) * box.extents) @ rot.T
    outside = box.center + (rng.uniform(0.51, 1.0, (100, 3)) * np.sign(rng.normal(size=(100, 3))) * box.extents) @ rot.T
    assert box.contains(inside).all() and not box.contains(outside).any()
    lo, hi = box.extent_along(np.array([0.0, 0.0, 1.0]))
    corners_z = box.corners()[:, 2]
    assert lo == pytest.approx(corners_z.min()) and hi == pytest.approx(corners_z.max())


def test_intersection_touching_overlap_and_rotation():
    a = OrientedBox([0, 0, 0], [1, 1, 1])
    assert not a.intersects(OrientedBox([0, 0, 1.0], [1, 1, 1]))  # a cup on a table: touching
    assert a.intersects(OrientedBox([0, 0, 0.99], [1, 1, 1]))
    assert not a.intersects(OrientedBox([0, 0, 0.99], [1, 1, 1]), tol=0.02)
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    diamond = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    # a 45°-rotated unit box whose corner reaches x = 1.2 - 0.707 = 0.49 < 0.5: overlap
    assert a.intersects(OrientedBox([1.2, 0, 0], [1, 1, 1], diamond))
    assert not a.intersects(OrientedBox([1.25, 0, 0], [1, 1, 1], diamond))


def test_invalid_boxes_are_rejected():
    with pytest.raises(InvalidDataError, match="extents must be 3 finite"):
        OrientedBox([0, 0, 0], [1, -1, 1])
    with pytest.raises(InvalidDataError, match="not orthonormal"):
        OrientedBox([0, 0, 0], [1, 1, 1], np.ones((3, 3)))
    flipped = np.diag([1.0, 1.0, -1.0, 1.0])
    box = OrientedBox.from_transform(flipped, [1, 2, 3])  # a reflection is the same box with one axis flipped
    assert np.linalg.det(box.rotation) == pytest.approx(1.0)
