"""Answerability: the contrast measure, the objects a question names, the table."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.data.answerability import (
    ROSE_K,
    VIEWING_FLARE,
    WEBER_THRESHOLD,
    answerability_table,
    condition_of,
    groups_answerability,
    item_answerability,
    named_objects,
    noise_sigma,
    object_contrast,
    share_by_condition,
)
from spacedg.errors import ParameterError
from spacedg.render.colour_cpu import decode_srgb, encode_srgb_u8


def _scene_image(y_object: float, y_surround: float, noise: float = 0.0, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A uint8 64x48 image: a grey surround of linear luminance ``y_surround``, a 16x12 object of
    ``y_object`` (grey, so luminance = each channel), plus Gaussian noise of ``noise`` (linear); and the id map."""
    linear = np.full((48, 64, 3), y_surround, np.float32)
    linear[18:30, 24:40] = y_object
    if noise:
        linear += np.random.default_rng(seed).normal(0.0, noise, linear.shape[:2])[:, :, None].astype(np.float32)
    ids = np.full((48, 64), -1, np.int32)
    ids[18:30, 24:40] = 3
    return encode_srgb_u8(np.clip(linear, 0.0, 1.0)), ids


@pytest.mark.parametrize("ratio, seen", [(1.06, True), (1.005, False), (0.94, True), (0.995, False)])
def test_weber_threshold_on_a_grey_surround(ratio, seen):
    """A step of c·Y on a mid-grey surround is discernible exactly when c·Y/(Y + flare) >= 2 %."""
    image, ids = _scene_image(0.4 * ratio, 0.4)
    result = groups_answerability([("v", (3,))], image[None], [ids], ("v",))
    (obj,) = result.objects
    y_o, y_s = (float(decode_srgb(np.float32(image[r, c, 0] / 255.0))) for r, c in ((20, 30), (0, 0)))  # the 8-bit levels
    assert obj.weber == pytest.approx(abs(y_o - y_s) / (y_s + VIEWING_FLARE), rel=1e-4)
    assert abs(obj.weber - abs(ratio - 1) * 0.4 / (0.4 + VIEWING_FLARE)) < 0.013  # what was asked, within one code (1.2 %)
    assert obj.discernible is seen and result.answerable is seen and obj.pixels == 16 * 12


def test_one_code_step_in_the_dark_is_not_an_infinite_contrast():
    """Near black the viewing flare bounds the contrast: codes 1 vs 0 are 2.4 %, not infinite."""
    image = np.zeros((48, 64, 3), np.uint8)
    ids = np.full((48, 64), -1, np.int32)
    image[18:30, 24:40], ids[18:30, 24:40] = 1, 3
    luma = np.where(ids == 3, (1 / 255) / 12.92, 0.0)
    weber, snr, n = object_contrast(luma, ids == 3, sigma=0.0)
    assert groups_answerability([("v", (3,))], image[None], [ids], ("v",)).objects[0].weber == pytest.approx(weber)
    assert weber == pytest.approx((1 / 255 / 12.92) / VIEWING_FLARE) and n == 192


def test_noise_hides_a_small_step():
    """The same 10 % step is discernible without noise and not under noise 40x its size (Rose)."""
    clean, ids = _scene_image(0.44, 0.4)
    noisy, _ = _scene_image(0.44, 0.4, noise=0.6, seed=1)
    quiet = groups_answerability([("v", (3,))], clean[None], [ids], ("v",)).objects[0]
    loud = groups_answerability([("v", (3,))], noisy[None], [ids], ("v",)).objects[0]
    assert quiet.discernible and quiet.weber >= WEBER_THRESHOLD
    assert not loud.discernible and loud.snr < ROSE_K


def test_an_isoluminant_colour_step_is_seen_in_its_channel():
    """A red object on a grey surround of the same luminance: no luminance step, a large red one."""
    grey = 0.3
    red = np.array([grey / 0.2126 * 0.5, grey * 0.5 / 0.7152, 0.0], np.float32)  # luminance = grey
    linear = np.full((48, 64, 3), grey, np.float32)
    linear[18:30, 24:40] = red
    ids = np.full((48, 64), -1, np.int32)
    ids[18:30, 24:40] = 3
    (obj,) = groups_answerability([("v", (3,))], encode_srgb_u8(linear)[None], [ids], ("v",)).objects
    assert obj.discernible and obj.signal in ("red", "blue") and obj.to_dict()["signal"] == obj.signal


def test_noise_estimate_ignores_ramps_and_finds_white_noise():
    ramp = np.tile(np.linspace(0, 1, 64), (48, 1))
    assert noise_sigma(ramp) == pytest.approx(0.0, abs=1e-9)
    rng = np.random.default_rng(0)
    assert noise_sigma(rng.normal(0, 0.05, (200, 200))) == pytest.approx(0.05, rel=0.1)
    assert noise_sigma(np.zeros((2, 5))) == 0.0


def test_an_absent_object_is_not_discernible_and_groups_need_one_member():
    image, ids = _scene_image(0.8, 0.2)
    result = groups_answerability([("v", (3, 9))], image[None], [ids], ("v",))  # 9 is not in the image
    assert result.answerable and [o.discernible for o in result.objects] == [True, False]
    assert not groups_answerability([("v", (9,))], image[None], [ids], ("v",)).answerable
    assert groups_answerability([], image[None], [ids], ("v",)).answerable  # nothing named: nothing to see
    with pytest.raises(ParameterError, match="id map"):
        groups_answerability([("v", (3,))], image[None], [], ("v",))
    with pytest.raises(ParameterError, match="view 'w'"):
        groups_answerability([("w", (3,))], image[None], [ids], ("v",))


def test_named_objects_of_every_family(room_records):
    """Each record's named objects lie in its views; counting names its counted objects, existence
    its label's visible members (one group), camera motion nothing."""
    seen = set()
    for _, records in room_records:
        for record in records:
            groups = named_objects(record)
            assert {view for view, _ in groups} <= set(record.views)
            g = record.geometry
            if record.question_type == "object_counting":
                assert len(groups) == record.answer
            elif record.question_type == "object_existence_estimation":
                assert len(groups) == (1 if record.answer == "yes" else 0)
            elif record.question_type.startswith("camera_") and not g.get("refs"):
                assert groups == []
            else:
                assert [ids for _, ids in groups] == [(ref["id"],) for ref in g["refs"]]
            seen.add(record.question_type)
    assert len(seen) >= 10


def test_condition_of_an_item():
    haze = [{"name": "haze", "params": {}, "seed": 1, "preset": "3"}]
    night = [{"name": "motion_blur", "preset": "2"}, {"name": "low_light", "preset": "bench"}, {"name": "low_res", "preset": "2"}]
    assert condition_of("haze", haze) == ("haze", "3") and condition_of("ori", []) == ("ori", "-")
    assert condition_of("night_capture", night) == ("night_capture", "bench")
    assert condition_of("haze", [{"name": "haze", "preset": None}]) == ("haze", "-")


def test_share_table():
    rows = [{"degradation_type": "haze", "severity": "bench", "answerable": a, "groups": g} for a, g in ((True, 1), (False, 2), (True, 0))]
    rows.append({"degradation_type": "ori", "severity": "-", "answerable": True, "groups": 1})
    shares = share_by_condition(rows)
    assert shares["haze"]["bench"] == {"items": 3, "with_objects": 2, "answerable": 1, "share": 0.5}
    table = answerability_table(shares)
    assert "| ori | 100 % (1/1) |  |" in table and "| haze |  | 50 % (1/2) |" in table


def test_item_answerability_reads_the_record(room_records):
    scene, records = room_records[0]
    record = next(r for r in records if r.question_type == "camera_object_distance_estimation")
    (view,) = record.views
    ((_, (oid,)),) = named_objects(record)
    ids = np.full((48, 64), -1, np.int32)
    ids[10:30, 10:30] = oid
    image = np.full((1, 48, 64, 3), 90, np.uint8)
    image[0, 10:30, 10:30] = 200
    assert item_answerability(record, image, [ids]).answerable
    image[0, 10:30, 10:30] = 90
    assert not item_answerability(record, image, [ids]).answerable
