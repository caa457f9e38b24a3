"""``fitted_size`` / ``Camera.fitted``: a requested image size is a bounding box; a view keeps its
aspect ratio (within one pixel) and its intrinsics stay consistent with its pixels."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.errors import InvalidDataError
from spacedg.render import Camera, FisheyeLens, fitted_size


def _camera(width: int, height: int, fisheye: FisheyeLens | None = None) -> Camera:
    f = 0.8 * width
    return Camera(f, f, width / 2 + 3.0, height / 2 - 2.0, width, height, np.eye(4), fisheye=fisheye)


@pytest.mark.parametrize(
    ("view", "box", "expected"),
    [
        ((1920, 1080), (320, 240), (320, 180)),  # 16:9 in a 4:3 box: the width binds
        ((640, 480), (320, 240), (320, 240)),  # 4:3 in 4:3: exactly the size asked
        ((160, 120), (320, 240), (320, 240)),  # enlarged too (a re-render, not an interpolation)
        ((1080, 1920), (320, 240), (135, 240)),  # portrait: the height binds
        ((1296, 968), (320, 240), (320, 240)),  # 239.01 px: within a pixel of the box, kept at the box
        ((1000, 1000), (320, 240), (240, 240)),
        ((5000, 10), (100, 100), (100, 1)),  # never under one pixel
    ],
)
def test_fitted_size(view, box, expected):
    assert fitted_size(*view, *box) == expected
    w, h = expected
    assert w <= box[0] and h <= box[1] and (w == box[0] or h == box[1])
    # the aspect ratio is the view's within one pixel of the shorter side
    assert abs(w * view[1] / view[0] - h) <= 1.0


def test_fitted_size_refuses_non_positive():
    with pytest.raises(InvalidDataError, match="positive"):
        fitted_size(0, 10, 10, 10)


@pytest.mark.parametrize("fisheye", [None, FisheyeLens(0.05, 0.01, 0.0, 0.0)])
@pytest.mark.parametrize(("view", "box"), [((1920, 1080), (320, 240)), ((640, 480), (320, 240)), ((1080, 1920), (320, 240))])
def test_fitted_camera_projects_as_the_full_view_scaled(view, box, fisheye):
    full = _camera(*view, fisheye)
    small = full.fitted(*box)
    assert (small.width, small.height) == fitted_size(*view, *box)
    # one scale on both axes (up to the rounding of a side): the picture is not squeezed
    sx, sy = small.width / full.width, small.height / full.height
    assert abs(sx - sy) * max(full.width, full.height) <= 1.0 + 1e-9
    rng = np.random.default_rng(0)
    points = np.column_stack([rng.uniform(-1, 1, 50), rng.uniform(-1, 1, 50), rng.uniform(1, 4, 50)])
    uv_full, _, ok_full = full.project(points)
    uv_small, _, ok_small = small.project(points)
    assert np.array_equal(ok_full, ok_small)
    # a 3D point lands on the same place of the picture: the full-size pixel scaled by the image sizes
    np.testing.assert_allclose(uv_small, uv_full * [sx, sy], atol=1e-9)


def test_fitted_keeps_a_camera_already_at_that_size():
    cam = _camera(640, 480)
    assert cam.fitted(640, 480) is cam
    a, b = cam.fitted(320, 240), cam.resized(320, 240)  # an aspect-preserving size renders as before
    assert (a.fx, a.fy, a.cx, a.cy, a.width, a.height) == (b.fx, b.fy, b.cx, b.cy, b.width, b.height)
