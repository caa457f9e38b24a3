"""Built-in ``camera_translation`` and ``camera_rotation`` families (golden, CPU, fast).

Scenes come from ``tests/qa_scenes.py``: camera A sits at ``EYE`` looking along +x (its right
is world −y, its down world −z). Which view of a pair is "view A" is a seeded coin of
``sample_pairs``, so expectations are written for the orientation ``a → b`` and mirrored
(translation: ``d → −d``) or recomputed for ``b → a``.
"""

from __future__ import annotations

import math
import re
from collections import Counter

import numpy as np
import pytest
from tests.qa_scenes import build, camera, obj, random_rigid

from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Scene
from spacedg.plugins.questions.view_sampling import PairRules
from spacedg.plugins import AnswerType, TaskGroup, get_question_family, reset_registry
from spacedg.plugins.questions import camera_rotation, camera_translation
from spacedg.plugins.questions.camera_rotation import RotationCase, classify_rotation
from spacedg.plugins.questions.camera_translation import snap_factor, threshold_for

EYE = np.array([0.0, 0.0, 1.5])
WORDS = (("right", "left"), ("down", "up"), ("forward", "backward"))


def _cam_a():
    return camera(EYE, 0.0)


def _moved(d_cam: tuple[float, float, float]) -> Scene:
    """Two views with the same orientation; B is ``d_cam`` (A's camera frame, metres) from A."""
    a = _cam_a()
    rot = np.asarray(a.cam_to_world)[:3, :3]
    b = camera(EYE + rot @ np.asarray(d_cam, dtype=np.float64), 0.0)
    return build([obj(1, "chair", (3.0, 0.0, 0.5))], {"a": a, "b": b})


def _turned(yaw: float = 0.0, pitch: float = 0.0, roll: float = 0.0) -> Scene:
    """Two views at the same place; B has heading ``yaw`` (CCW from above, so −30 = turned right), pitch, roll."""
    return build([obj(1, "chair", (3.0, 0.0, 0.5))], {"a": _cam_a(), "b": camera(EYE, yaw, pitch, roll)})


def _records(family, scene: Scene, seed: int) -> list[QARecord]:
    return list(family.generate(scene, np.random.default_rng(seed)))


def _by_sub(records: list[QARecord]) -> dict[str, QARecord]:
    out = {r.sub_question_type: r for r in records}
    assert len(out) == len(records)
    return out


def _texts(record: QARecord) -> dict[str, str]:
    return {line[0]: line[3:] for line in record.options}


def _truth(record: QARecord) -> str:
    return _texts(record)[record.answer]


def _flip(label: str) -> str:
    opposite = {w: pair[1 - k] for pair in WORDS for k, w in enumerate(pair)}
    return "-".join(opposite[w] for w in label.split("-"))


def _random_scene(seed: int = 3, n: int = 7) -> Scene:
    rng = np.random.default_rng(seed)
    views = {}
    for k in range(n):
        eye = EYE + rng.uniform(-1.2, 1.2, size=3) * np.array([1.0, 1.0, 0.3])
        views[f"v{k}"] = camera(eye, rng.uniform(-45, 45), rng.uniform(-25, 25), rng.uniform(-12, 12))
    return build([obj(1, "chair", (3.0, 0.0, 0.5)), obj(2, "table", (2.5, 1.0, 0.4))], views)


# ------------------------------------------------------------------ translation
@pytest.mark.parametrize("seed", range(6))
def test_one_metre_right(seed: int) -> None:
    records = _records(camera_translation.FAMILY, _moved((1.0, 0.0, 0.0)), seed)
    subs = _by_sub(records)
    assert set(subs) == set(camera_translation.SUB_TYPES)
    forward = records[0].views == ("a", "b")
    main = subs["main_dir"]
    assert main.answer_type is AnswerType.MCQ and main.task_group is TaskGroup.CAMERA_CENTRIC
    assert _truth(main) == ("right" if forward else "left")
    assert main.question == "What is the primary camera motion direction from view A to view B in view A's coordinate?"
    assert subs["distance_exact"].answer == pytest.approx(1.000, abs=1e-12)
    thr = subs["distance_threshold"]
    shown = float(re.search(r"exceeds (\d+\.\d\d) meters", thr.question).group(1))
    assert shown == thr.geometry["threshold_m"]
    assert thr.answer == ("yes" if 1.0 > shown else "no")
    assert not 0.85 < thr.geometry["factor"] < 1.15
    assert "matri" not in thr.question
    for r in records:
        assert r.geometry["refs"] == [] and r.geometry["distance_m"] == pytest.approx(1.0)
        assert len(r.geometry["cam_to_world_a"]) == 4 and r.geometry["up"] == [0.0, 0.0, 1.0]


def test_snap_and_threshold_for_chosen_factors() -> None:
    assert snap_factor(0.7, 0.0) == 0.7 and snap_factor(1.3, 0.0) == 1.3
    assert snap_factor(0.85, 0.0) == 0.85 and snap_factor(1.15, 0.0) == 1.15
    assert snap_factor(0.9, 0.9) == 0.85 and snap_factor(1.1, 0.1) == 1.15
    assert snap_factor(1.0, 0.2) == 0.85 and snap_factor(1.0, 0.7) == 1.15  # tie: seeded coin
    assert threshold_for(1.0, 0.85) == 0.85 and 1.0 > threshold_for(1.0, 0.85)  # "yes"
    assert threshold_for(1.0, 1.15) == 1.15 and not 1.0 > threshold_for(1.0, 1.15)  # "no"
    assert threshold_for(1.0, 0.6123) == 0.61  # rounded to what the question prints
    assert threshold_for(0.05, 0.6) == 0.05  # floor


def test_threshold_answers_are_balanced_and_use_the_printed_value() -> None:
    scene = _moved((0.3, 0.1, 0.5))
    answers = Counter()
    for seed in range(200):
        rec = _by_sub(_records(camera_translation.FAMILY, scene, seed))["distance_threshold"]
        g = rec.geometry
        assert f"exceeds {g['threshold_m']:.2f} meters" in rec.question
        assert rec.answer == ("yes" if g["distance_m"] > g["threshold_m"] else "no")
        assert 0.6 <= g["factor_drawn"] <= 1.4
        if 0.85 < g["factor_drawn"] < 1.15:  # snapped to the nearer end
            assert g["factor"] == (0.85 if g["factor_drawn"] < 1.0 else 1.15)
        else:
            assert g["factor"] == g["factor_drawn"]
        answers[rec.answer] += 1
    assert 70 <= answers["yes"] <= 130


@pytest.mark.parametrize(
    ("d", "label"),
    [
        ((1.0, 0.0, 1.0), "right-forward"),  # exact tie: x before z (documented)
        ((0.7, 0.0, 1.0), "forward-right"),  # largest first
        ((1.0, 0.05, 0.1), "right"),  # tiny off-axis parts dropped
        ((1.0, 0.56, 0.0), "right"),  # 0.56 < 0.5774
        ((-0.6, -1.0, 0.0), "up-left"),
        ((1.0, 0.8, 0.9), "right-forward"),  # three components: at most two parts
        ((0.0, 0.0, -0.5), "backward"),
    ],
)
def test_main_direction_label(d: tuple[float, float, float], label: str) -> None:
    for seed in range(4):
        records = _records(camera_translation.FAMILY, _moved(d), seed)
        main = _by_sub(records)["main_dir"]
        expected = label if main.views == ("a", "b") else _flip(label)
        assert _truth(main) == expected
        assert len(main.geometry["parts"]) <= 2
        assert _by_sub(records)["distance_exact"].answer == pytest.approx(round(math.dist((0, 0, 0), d), 3))


def _check_options(main: QARecord) -> None:
    truth = _truth(main)
    texts = list(_texts(main).values())
    assert len(set(texts)) == 4 and texts.count(truth) == 1
    if "-" in truth:  # two parts: the 4 sign combinations of the same two axes
        axes = {frozenset(next(i for i, p in enumerate(WORDS) if w in p) for w in t.split("-")) for t in texts}
        assert len(axes) == 1 and all(t.count("-") == 1 for t in texts)
    else:  # one part: single words, both signs of two axes; none contains the truth
        assert all("-" not in t for t in texts)
        assert _flip(truth) in texts
        pairs = Counter(next(i for i, p in enumerate(WORDS) if t in p) for t in texts)
        assert sorted(pairs.values()) == [2, 2]


def test_distractors_never_partially_correct() -> None:
    seen = Counter()
    for seed in range(5):
        for scene in (_random_scene(seed), _moved((1.0, 0.0, 0.0)), _moved((0.2, -0.9, 0.7))):
            for rec in _records(camera_translation.FAMILY, scene, seed):
                if rec.sub_question_type == "main_dir":
                    _check_options(rec)
                    seen["-" in _truth(rec)] += 1
    assert seen[True] and seen[False]


def test_short_baseline_is_skipped() -> None:
    assert _records(camera_translation.FAMILY, _moved((0.3, 0.0, 0.1)), 0) == []
    assert len(_records(camera_translation.FAMILY, _moved((0.36, 0.0, 0.0)), 0)) == 3


def test_first_pass_covers_every_pair_with_mixed_sub_types() -> None:
    records = _records(camera_translation.FAMILY, _random_scene(), 11)
    n = len(records) // 3
    assert n >= 5 and len(records) == 3 * n
    first = records[:n]
    assert len({r.views for r in first}) == n
    counts = Counter(r.sub_question_type for r in first)
    assert max(counts.values()) - min(counts.values()) <= 1
    assert Counter((r.views, r.sub_question_type) for r in records).most_common(1)[0][1] == 1


def test_geometry_reproduces_translation_answers() -> None:
    """Independent code: recompute d from the stored poses, the label by the 0.5774 rule."""
    for rec in _records(camera_translation.FAMILY, _random_scene(), 2):
        g = rec.geometry
        pa, pb = np.array(g["cam_to_world_a"]), np.array(g["cam_to_world_b"])
        d = pa[:3, :3].T @ (pb[:3, 3] - pa[:3, 3])
        assert np.allclose(d, g["d"], atol=1e-8)
        if rec.sub_question_type == "main_dir":
            mags = np.abs(g["d"])
            order = sorted(range(3), key=lambda i: (-mags[i], i))
            keep = [i for i in order if mags[i] >= 0.5774 * mags[order[0]]][:2]
            label = "-".join(WORDS[i][0 if g["d"][i] > 0 else 1] for i in keep)
            assert _truth(rec) == label == g["label"]
        elif rec.sub_question_type == "distance_exact":
            assert rec.answer == round(float(np.linalg.norm(g["d"])), 3)
        else:
            assert rec.answer == ("yes" if np.linalg.norm(g["d"]) > g["threshold_m"] else "no")
        assert QARecord.from_json(rec.to_json()) == rec


# --------------------------------------------------------------------- rotation
def test_classify_rotation_rules() -> None:
    assert classify_rotation(30, 0, 0) == RotationCase("yaw", "pitch", 30.0, 0.0, 0.0, "single")
    assert classify_rotation(30, 12, 0).mode == "single"  # r = 0.4 inclusive
    assert classify_rotation(30, 18, 1).mode == "dual"  # r = 0.6 inclusive
    assert isinstance(classify_rotation(30, 15, 0), str)  # grey zone
    assert classify_rotation(10, 4.9, 0).mode == "single"  # a2 < 5° although r = 0.49
    assert isinstance(classify_rotation(4.9, 1, 0), str)  # a1 < 5°
    assert isinstance(classify_rotation(10, 61, 0), str)  # gimbal lock
    assert isinstance(classify_rotation(160, 0, 0), str)  # turn direction ambiguous
    case = classify_rotation(1, 6, -20)
    assert (case.ax1, case.ax2, case.mode) == ("roll", "pitch", "single")
    assert classify_rotation(-20, 0, 20).ax1 == "yaw"  # tie: yaw, pitch, roll order


@pytest.mark.parametrize("seed", range(6))
def test_yaw_30_right_is_single_turn_right(seed: int) -> None:
    (rec,) = _records(camera_rotation.FAMILY, _turned(yaw=-30.0), seed)
    forward = rec.views == ("a", "b")
    assert _truth(rec) == ("turn right" if forward else "turn left")
    assert rec.sub_question_type == "yaw+pitch_single"
    assert set(_texts(rec).values()) == {"turn right", "turn left", "tilt up", "tilt down"}
    assert "among yaw (turn left/right) and pitch (tilt up/down)" in rec.question
    assert rec.geometry["euler_deg"]["yaw"] == pytest.approx(30.0 if forward else -30.0)


@pytest.mark.parametrize("seed", range(6))
def test_yaw_30_pitch_25_is_dual(seed: int) -> None:
    (rec,) = _records(camera_rotation.FAMILY, _turned(yaw=-30.0, pitch=25.0), seed)
    assert rec.sub_question_type == "yaw+pitch_dual"
    # b -> a is the inverse R_x(-25) R_y(-30): yaw -32.5°, pitch -21.5°, roll 13.1°.
    expected = "turn right and tilt up" if rec.views == ("a", "b") else "turn left and tilt down"
    assert _truth(rec) == expected
    assert {t.split(" and ")[0] for t in _texts(rec).values()} == {"turn right", "turn left"}
    assert "TWO components: yaw (turn left/right) and pitch (tilt up/down)" in rec.question


def test_roll_is_clockwise() -> None:
    for seed in range(4):
        (rec,) = _records(camera_rotation.FAMILY, _turned(roll=20.0), seed)
        assert rec.sub_question_type == "yaw+roll_single"  # singles are named by their text axes
        assert _truth(rec) == ("clockwise roll" if rec.views == ("a", "b") else "counterclockwise roll")
        assert "among yaw (turn left/right) and roll (clockwise/counterclockwise)" in rec.question


def test_grey_zone_and_small_rotations_are_skipped() -> None:
    loose = camera_rotation.make_family(PairRules(min_rotation_deg=0.0))
    for seed in range(4):
        assert _records(camera_rotation.FAMILY, _turned(yaw=-30.0, pitch=15.0), seed) == []  # r = 0.5 (0.42 reversed)
        assert _records(loose, _turned(yaw=-4.0, pitch=2.0), seed) == []  # a1 < 5°
        assert _records(camera_rotation.FAMILY, _turned(yaw=-10.0), seed) == []  # pair rule: < 15°
        assert _records(camera_rotation.FAMILY, _turned(yaw=-20.0, pitch=70.0), seed) == []  # gimbal


def test_rotation_geometry_reproduces_answer() -> None:
    records = []
    for seed in range(3):
        records += _records(camera_rotation.FAMILY, _random_scene(seed), seed)
    assert {r.geometry["mode"] for r in records} == {"single", "dual"}
    for rec in records:
        g = rec.geometry
        assert rec.sub_question_type in camera_rotation.SUB_TYPES
        pa, pb = np.array(g["cam_to_world_a"]), np.array(g["cam_to_world_b"])
        r = pa[:3, :3].T @ pb[:3, :3]
        assert np.allclose(r, g["r_rel"], atol=1e-9)
        yaw, pitch, roll = _gravity_reading(pa, pb, np.array(g["up"]))
        assert g["euler_deg"]["yaw"] == pytest.approx(yaw, abs=1e-5) and g["euler_deg"]["pitch"] == pytest.approx(pitch, abs=1e-5)
        assert g["euler_deg"]["roll"] == pytest.approx(roll, abs=1e-5)
        ax1 = g["axes"][0]
        words = {"yaw": ("turn right", "turn left"), "pitch": ("tilt up", "tilt down"), "roll": ("clockwise roll", "counterclockwise roll")}
        word1 = words[ax1][0 if g["euler_deg"][ax1] > 0 else 1]
        assert word1 in _truth(rec)
        if g["mode"] == "dual":
            ax2 = g["axes"][1]
            assert words[ax2][0 if g["euler_deg"][ax2] > 0 else 1] in _truth(rec)
            assert g["ratio"] >= 0.6
        assert QARecord.from_json(rec.to_json()) == rec


def _gravity_reading(pose_a: np.ndarray, pose_b: np.ndarray, up: np.ndarray) -> tuple[float, float, float]:
    """Independent gravity-aware (yaw, pitch, roll): heading, elevation and bank differences."""
    def attitude(pose):
        right, forward = pose[:3, 0], pose[:3, 2]
        elevation = math.degrees(math.asin(forward @ up))
        flat = forward - (forward @ up) * up
        heading_vec = flat / np.linalg.norm(flat)
        level_right = np.cross(forward, up) / np.linalg.norm(np.cross(forward, up))
        bank = math.degrees(math.atan2(right @ np.cross(forward, level_right), right @ level_right))
        return heading_vec, elevation, bank

    (fa, ea, ba), (fb, eb, bb) = attitude(pose_a), attitude(pose_b)
    yaw = math.degrees(math.atan2(fb @ np.cross(fa, up), fb @ fa))  # + = towards A's right
    wrap = lambda a: (a + 180.0) % 360.0 - 180.0  # noqa: E731
    return yaw, eb - ea, wrap(bb - ba)


def test_panning_a_tilted_camera_is_a_pure_yaw() -> None:
    """Hand-worked: a camera looking 30° down pans 40° right about the vertical. A person sees a
    pan; the camera-frame Euler angles of R_a^T R_b add about 10° of roll (the old reading)."""
    from spacedg.plugins.questions.geometry import euler_yaw_pitch_roll, gravity_rotation, relative_rotation

    a, b = camera(EYE, 0.0, -30.0), camera(EYE, -40.0, -30.0)
    up = np.array([0.0, 0.0, 1.0])
    assert gravity_rotation(a, b, up) == pytest.approx((40.0, 0.0, 0.0), abs=1e-9)
    old_yaw, old_pitch, old_roll = euler_yaw_pitch_roll(relative_rotation(a, b))
    assert abs(old_roll) > 9.0 and abs(old_pitch) > 5.0  # imperceptible components of the old reading
    for seed in range(4):
        (rec,) = _records(camera_rotation.FAMILY, build([obj(1, "chair", (3.0, 0.0, 0.5))], {"a": a, "b": b}), seed)
        assert rec.geometry["mode"] == "single" and rec.geometry["axes"][0] == "yaw"
        assert _truth(rec) == ("turn right" if rec.views == ("a", "b") else "turn left")
        assert rec.geometry["euler_deg"]["roll"] == pytest.approx(0.0, abs=1e-6)


def test_gravity_reading_hand_worked_cases() -> None:
    from spacedg.plugins.questions.geometry import euler_yaw_pitch_roll, gravity_rotation, relative_rotation

    up = np.array([0.0, 0.0, 1.0])
    # a level camera: both readings agree exactly
    a, b = camera(EYE, 10.0), camera(EYE, -20.0, 15.0, 8.0)
    assert gravity_rotation(a, b, up) == pytest.approx(euler_yaw_pitch_roll(relative_rotation(a, b)), abs=1e-9)
    assert gravity_rotation(a, b, up) == pytest.approx((30.0, 15.0, 8.0), abs=1e-9)
    # looking down 35°, then 10° up: a tilt of 25°, nothing else
    assert gravity_rotation(camera(EYE, 0.0, -35.0), camera(EYE, 0.0, -10.0), up) == pytest.approx((0.0, 25.0, 0.0), abs=1e-9)
    # a tilted camera rolling 12° clockwise about its own optical axis keeps heading and elevation
    assert gravity_rotation(camera(EYE, 50.0, -25.0), camera(EYE, 50.0, -25.0, 12.0), up) == pytest.approx((0.0, 0.0, 12.0), abs=1e-9)
    # a turn across ±180° of heading wraps to the short way round
    assert gravity_rotation(camera(EYE, 170.0), camera(EYE, -170.0), up)[0] == pytest.approx(-20.0, abs=1e-9)


# ----------------------------------------------------------------- invariance
@pytest.mark.parametrize("seed", range(5))
def test_rigid_motion_of_the_scene_changes_nothing(seed: int) -> None:
    scene = _random_scene(7)
    moved = scene.transformed(*random_rigid(seed))
    for family in (camera_translation.FAMILY, camera_rotation.FAMILY):
        before = _records(family, scene, 4)
        after = _records(family, moved, 4)
        assert before and len(before) == len(after)
        for r0, r1 in zip(before, after):
            assert (r0.id, r0.views, r0.sub_question_type, r0.question, r0.options) == (r1.id, r1.views, r1.sub_question_type, r1.question, r1.options)
            if r0.answer_type is AnswerType.NA:
                assert r1.answer == pytest.approx(r0.answer, abs=1e-6)
            else:
                assert r0.answer == r1.answer


def test_same_seed_same_records() -> None:
    scene = _random_scene()
    for family in (camera_translation.FAMILY, camera_rotation.FAMILY):
        a = [r.to_dict() for r in _records(family, scene, 9)]
        assert a == [r.to_dict() for r in _records(family, scene, 9)]
        assert a != [r.to_dict() for r in _records(family, scene, 10)]
        assert len({r["id"] for r in a}) == len(a)


def test_correct_letter_is_spread_over_a_to_d() -> None:
    letters = Counter()
    for seed in range(40):
        for family in (camera_translation.FAMILY, camera_rotation.FAMILY):
            letters.update(r.answer for r in _records(family, _random_scene(seed % 4), seed) if r.answer_type is AnswerType.MCQ)
    total = sum(letters.values())
    assert set(letters) == set("ABCD") and all(abs(n / total - 0.25) < 0.06 for n in letters.values())


def test_missing_covisibility_is_a_clear_error() -> None:
    scene = _moved((1.0, 0.0, 0.0)).with_covisibility(None)
    with pytest.raises(Exception, match="covisibility"):
        list(camera_translation.FAMILY.generate(scene, np.random.default_rng(0)))


@pytest.mark.parametrize("name", ["camera_translation", "camera_rotation"])
def test_registered_family_matches_module(monkeypatch: pytest.MonkeyPatch, name: str) -> None:
    monkeypatch.delenv("SPACEDG_DISABLE_PLUGIN_AUTOLOAD", raising=False)
    monkeypatch.delenv("SPACEDG_PLUGINS", raising=False)
    module = {"camera_translation": camera_translation, "camera_rotation": camera_rotation}[name]
    reset_registry()
    try:
        family = get_question_family(name)
        assert family.origin is not None and family.origin.builtin
        assert family.needs == frozenset({"covisibility"}) and family.num_views == (2,)
        assert family.task_group is TaskGroup.CAMERA_CENTRIC
        scene = _random_scene()
        via_registry = [r.to_dict() for r in family.generate(scene, np.random.default_rng(5))]
        assert via_registry and via_registry == [r.to_dict() for r in _records(module.FAMILY, scene, 5)]
    finally:
        reset_registry()


def test_rotation_declares_the_nine_sub_types_that_occur() -> None:
    """Three singles named by their text axes (not by the answer's axis) and six duals, dominant axis first."""
    subs = camera_rotation.FAMILY.sub_question_types
    assert len(subs) == 9 and len(set(subs)) == 9
    assert {s for s in subs if s.endswith("_single")} == {"yaw+pitch_single", "yaw+roll_single", "pitch+roll_single"}
    assert "yaw+pitch_dual" in subs and "pitch+yaw_dual" in subs


@pytest.mark.parametrize("turn", [dict(yaw=-30.0), dict(pitch=25.0), dict(yaw=-8.0, pitch=30.0)])
def test_a_single_sub_type_does_not_tell_the_answer_axis(turn: dict[str, float]) -> None:
    """A tilt and a pan between the same axes are one sub type: the name shows what the text shows."""
    for seed in range(3):
        (rec,) = _records(camera_rotation.FAMILY, _turned(**turn), seed)
        assert rec.sub_question_type == "yaw+pitch_single"
        assert rec.geometry["axes"][0] == ("pitch" if "pitch" in turn and abs(turn["pitch"]) > abs(turn.get("yaw", 0.0)) else "yaw")
