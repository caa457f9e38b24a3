"""No non-finite light leaves the pipeline silently; degrade_image's depth rules; the size policy of PipelineOptions."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from spacedg.data.pipeline import PipelineOptions, degrade, degrade_image
from spacedg.errors import InvalidDataError, ParameterError, PluginError

SMALL = PipelineOptions(image_size=(48, 36))


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_a_linear_plugin_returning_non_finite_light_is_named(small_room, monkeypatch, bad: float) -> None:
    from spacedg.data import chain as chain_module
    from spacedg.plugins.degradations import haze

    def poisoned(rgb, aux, params, rng):  # type: ignore[no-untyped-def]
        out = rgb.copy()
        out[3, 5, 1] = bad
        return out

    broken = replace(haze.SPEC, apply=poisoned)
    monkeypatch.setattr(chain_module, "get_degradation", lambda name: broken)
    view = next(iter(small_room.views))
    with pytest.raises(PluginError, match=r"linear degradation 'haze' .*non-finite light: 1 of .*first at \(row, column, channel\) \(3, 5, 1\)"):
        degrade(small_room, [view], "haze", options=SMALL)
    photo = np.zeros((8, 9, 3), np.uint8)
    with pytest.raises(PluginError, match="linear degradation 'haze'"):
        degrade_image(photo, "haze", depth=np.ones((8, 9)))


def test_a_non_finite_render_is_an_error_not_black_pixels(small_room, monkeypatch) -> None:
    from spacedg.render.request import RenderRequest

    original = RenderRequest.render

    def broken(self, *args, **kwargs):  # type: ignore[no-untyped-def]
        frame = original(self, *args, **kwargs)
        frame.rgb[0, 0, 0] = np.nan
        return frame

    monkeypatch.setattr(RenderRequest, "render", broken)
    view = next(iter(small_room.views))
    with pytest.raises(InvalidDataError, match=f"view '{view}': the render holds non-finite light"):
        degrade(small_room, [view], None, options=SMALL)


def test_degrade_image_depth_rules() -> None:
    photo = np.random.default_rng(0).integers(0, 256, (10, 12, 3), dtype=np.uint8)
    far = np.full((10, 12), 5.0, np.float32)
    # 0, NaN and +inf are "no surface": the airlight of the normalisation depth (depth_ref), exactly like a render's empty pixels
    holes = far.copy()
    holes[2, 3], holes[4, 5], holes[6, 7] = 0.0, np.nan, np.inf
    with_holes, provenance = degrade_image(photo, {"name": "haze", "params": {"density": 2.0, "airlight": 0.8}}, depth=holes)
    at_ref = far.copy()
    at_ref[~np.isfinite(holes) | (holes == 0)] = provenance[0]["params"]["depth_ref"]
    expected, _ = degrade_image(photo, {"name": "haze", "params": {"density": 2.0, "airlight": 0.8}}, depth=at_ref, scene_depth=5.0)
    np.testing.assert_array_equal(with_holes, expected)
    for value in (-3.0, -math.inf):
        bad = far.copy()
        bad[1, 2] = value
        with pytest.raises(InvalidDataError, match=r"depth holds 1 negative value\(s\) \(first at \(row, column\) \(1, 2\)"):
            degrade_image(photo, "haze", depth=bad)
    with pytest.raises(InvalidDataError, match="depth has shape"):
        degrade_image(photo, "haze", depth=np.ones((3, 3)))
    with pytest.raises(InvalidDataError, match="alpha holds 1 value"):
        alpha = np.ones((10, 12))
        alpha[0, 0] = np.nan
        degrade_image(photo, "haze", depth=far, alpha=alpha)
    with pytest.raises(ParameterError, match="alpha without depth"):
        degrade_image(photo, "haze", alpha=np.ones((10, 12)))


def test_haze_refuses_negative_depth() -> None:
    from spacedg.plugins.degradations.haze import haze

    rgb = np.ones((4, 4, 3), np.float32)
    depth = np.full((4, 4), 2.0, np.float32)
    depth[1, 1] = -0.5
    with pytest.raises(InvalidDataError, match="haze: depth holds 1 negative"):
        haze(rgb, depth, np.ones((4, 4), np.float32), 1.0, 0.8)


@pytest.mark.parametrize("size", [(100_000, 100_000), (16385, 8), (8192, 8192)])
def test_pipeline_image_size_follows_the_size_policy(size) -> None:
    with pytest.raises(ParameterError, match="over the limit: spacedg renders at most 16384 pixels a side"):
        PipelineOptions(image_size=size)
    assert PipelineOptions(image_size=(7680, 4320)).image_size == (7680, 4320)  # 8K UHD fits


@pytest.mark.parametrize("seed", range(6))
def test_the_finite_check_finds_every_non_finite_value(seed: int) -> None:
    """The pipeline's check (its min and max) passes finite images, large values near float32's limit and the
    empty image, and finds one NaN, +inf or -inf anywhere, with the count and the first position."""
    from spacedg.data.pipeline import _first_non_finite

    rng = np.random.default_rng(3000 + seed)
    image = rng.uniform(-1.0, 1.0, (int(rng.integers(1, 40)), int(rng.integers(1, 40)), 3)).astype(np.float32)
    image.flat[int(rng.integers(0, image.size))] = np.float32(3e38) * (1 if seed % 2 else -1)
    assert _first_non_finite(image) is None and _first_non_finite(np.zeros((0, 4, 3), np.float32)) is None
    at = tuple(int(rng.integers(0, n)) for n in image.shape)
    for bad in (math.nan, math.inf, -math.inf):
        poisoned = image.copy()
        poisoned[at] = bad
        assert _first_non_finite(poisoned) == (
            f"1 of {image.size} values are NaN or ±inf (first at (row, column, channel) {at}: {poisoned[at]})"
        )
