"""Degraded views turned into one flat colour are reported (spacedg.data.erased_views), never changed."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from spacedg.data import erased_views
from spacedg.data.erased_views import is_flat, warn_if_erased
from spacedg.data.pipeline import degrade_image
from spacedg.errors import ErasedViewWarning, SpaceDGWarning

_ERASE_HAZE = {"name": "haze", "params": {"density": 100.0, "airlight": 1.0, "depth_ref": 1.0}}


def _textured(seed: int = 4101) -> np.ndarray:
    return (np.random.default_rng(seed).random((48, 64, 3)) * 255).astype(np.uint8)


@pytest.mark.parametrize("shape", [(48, 64, 3), (48, 64), (1, 1, 3), (5, 3, 3)])
def test_is_flat_sees_one_differing_value_anywhere(shape) -> None:
    flat = np.full(shape, 77, np.uint8)
    assert is_flat(flat)
    for index in np.ndindex(*shape):  # inside and outside the quick sample's strides alike
        other = flat.copy()
        other[index] = 78
        assert not is_flat(other) or shape[:2] == (1, 1)  # one pixel is one colour, whatever it holds


def test_is_flat_on_float_nan_and_empty_images() -> None:
    assert is_flat(np.full((6, 5, 3), 0.25, np.float32))
    with_nan = np.full((6, 5, 3), 0.25, np.float32)
    with_nan[3, 4, 1] = np.nan
    assert not is_flat(with_nan) and not is_flat(np.full((6, 5, 3), np.nan, np.float32))
    assert not is_flat(np.zeros((0, 4, 3), np.uint8))
    colour = np.zeros((6, 5, 3), np.uint8)
    colour[...] = (10, 200, 30)  # one colour that is not grey is flat too
    assert is_flat(colour)


def test_an_erasing_chain_warns_once_naming_its_parameters_and_changes_nothing() -> None:
    image, depth = _textured(), np.full((48, 64), 2.0, np.float32)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        out, provenance = degrade_image(image, [_ERASE_HAZE], depth=depth)
    erased = [w for w in caught if issubclass(w.category, ErasedViewWarning)]
    assert len(erased) == 1 and issubclass(erased[0].category, SpaceDGWarning)
    message = str(erased[0].message)
    assert "haze {density: 100, airlight: 1, depth_ref: 1}" in message and "(255, 255, 255)" in message
    assert "weaken them" in message and "seed" not in message
    assert (out == 255).all()  # delivered as asked: the warning changes no byte
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        again, _ = degrade_image(image, [_ERASE_HAZE], depth=depth)
    assert np.array_equal(out, again) and provenance[0]["params"]["density"] == 100.0


@pytest.mark.parametrize("chain", [["haze"], ["low_light"], ["over_exposure"], ["jpeg_compression", "low_res"]])
def test_the_bench_presets_erase_nothing(chain) -> None:
    with warnings.catch_warnings():
        warnings.simplefilter("error", ErasedViewWarning)
        degrade_image(_textured(4102), chain, depth=np.full((48, 64), 2.5, np.float32), seed=4103)


def test_a_flat_input_is_not_the_chains_doing() -> None:
    flat = np.full((48, 64, 3), 128, np.uint8)
    with warnings.catch_warnings():
        warnings.simplefilter("error", ErasedViewWarning)
        out, _ = degrade_image(flat, [_ERASE_HAZE], depth=np.full((48, 64), 2.0, np.float32))
    assert is_flat(out)


def test_warn_if_erased_counts_views_reports_once_per_scene_and_skips_unknown_sources() -> None:
    class Step:
        name, params = "low_light", {"exposure": 1e-9}

    erased_views._REPORTED.clear()
    flat, textured = np.zeros((4, 4, 3), np.uint8), _textured()[:4, :4]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert warn_if_erased([flat, textured, flat], [textured, textured, None], [Step()], "scene s") == 1
        assert warn_if_erased([flat, flat], [textured, textured], [Step()], "scene s") == 0  # reported already: not looked at
        assert warn_if_erased([flat], [textured], [Step()], "scene t") == 1  # another scene: reported
        assert warn_if_erased([flat], [textured], [], "scene u") == 0  # a clean item: nothing to blame
    first, second = (str(w.message) for w in caught)
    assert "1 of 3 views of scene s" in first and "(0, 0, 0)" in first and "once per scene" in first
    assert "every view of scene t" in second


def test_a_source_is_made_only_for_a_flat_result_and_a_flat_one_blames_nothing() -> None:
    """The pipeline hands the clean render's 8-bit encoding as a function: a render whose light varies
    below one 8-bit step (a dark wall) encodes flat, and its flat degraded image is not the chain's doing."""
    class Step:
        name, params = "jpeg_compression", {"quality": 1}

    erased_views._REPORTED.clear()
    calls = []

    def encoded(image: np.ndarray):
        return lambda: calls.append(1) or image

    flat, textured = np.zeros((4, 4, 3), np.uint8), _textured()[:4, :4]
    with warnings.catch_warnings():
        warnings.simplefilter("error", ErasedViewWarning)
        assert warn_if_erased([textured], [encoded(textured)], [Step()], "scene d") == 0 and calls == []  # not made
        assert warn_if_erased([flat], [encoded(np.full((4, 4, 3), 3, np.uint8))], [Step()], "scene d") == 0 and calls == [1]
        assert warn_if_erased([flat], [lambda: None], [Step()], "scene d") == 0  # no colour rendered: unknown


def test_under_an_error_filter_every_erased_item_raises() -> None:
    """The report is marked only after it was made: a user who turns the warning into an error gets it for
    every erased item of a scene, not only the first."""
    class Step:
        name, params = "over_exposure", {"exposure": 1e6}

    erased_views._REPORTED.clear()
    white, textured = np.full((4, 4, 3), 255, np.uint8), _textured()[:4, :4]
    with warnings.catch_warnings():
        warnings.simplefilter("error", ErasedViewWarning)
        for _ in range(2):
            with pytest.raises(ErasedViewWarning, match="over_exposure"):
                warn_if_erased([white], [textured], [Step()], "scene e")


def test_a_fisheye_view_counts_the_pixels_inside_its_image_circle() -> None:
    """Outside a fisheye's image circle every image is black: a white disc on black is an erased view, and
    a render that is one colour inside the circle is flat already."""
    class Step:
        name, params = "haze", {"density": 100.0}

    erased_views._REPORTED.clear()
    rows, cols = np.mgrid[:32, :32]
    circle = (rows - 15.5) ** 2 + (cols - 15.5) ** 2 < 14.0**2
    inside = np.repeat(circle[:, :, None], 3, axis=2)
    disc = np.where(inside, np.uint8(255), np.uint8(0)).astype(np.uint8)
    render = np.where(inside, _textured(4104)[:32, :32], np.uint8(0)).astype(np.uint8)
    blank_wall = np.where(inside, np.uint8(90), np.uint8(0)).astype(np.uint8)
    assert is_flat(disc, circle) and not is_flat(disc) and not is_flat(render, circle)
    assert not is_flat(disc, np.zeros_like(circle))  # no pixel counts: not flat
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert warn_if_erased([disc], [blank_wall], [Step()], "scene f", valid=[circle]) == 0  # the render was flat inside
        assert warn_if_erased([disc], [render], [Step()], "scene f", valid=[circle]) == 1
    (only,) = caught
    assert "(255, 255, 255)" in str(only.message)
