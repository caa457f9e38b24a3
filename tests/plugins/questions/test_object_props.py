"""Golden tests: ``object_size_comparison``, ``object_bounding_size_estimation``, ``object_existence_estimation``.

Every scene is hand-built with :mod:`tests.qa_scenes` (visibility and covisibility written in),
so each answer is known by construction. World z is up unless a test moves the scene.
"""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest
from tests.qa_scenes import CLEAR, PARTLY, build, camera, obj, random_rigid

from spacedg.scene.box import OrientedBox
from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Instance, InstanceVisibility, Scene
from spacedg.plugins import AnswerType, TaskGroup, get_question_family, reset_registry
from spacedg.plugins.questions import object_bounding_size_estimation as bsize
from spacedg.plugins.questions import object_existence_estimation as exist
from spacedg.plugins.questions import language
from spacedg.plugins.questions import object_size_comparison as cmp
from spacedg.plugins.questions.language import object_phrase

VIEWS = {"a": camera((0.0, 0.0, 1.2), 0.0), "b": camera((0.0, 1.0, 1.2), 10.0)}


def _records(family: object, scene: Scene, seed: int = 0) -> list[QARecord]:
    return list(family.generate(scene, np.random.default_rng(seed)))  # type: ignore[attr-defined]


def _truth(record: QARecord) -> str:
    """Text of the correct option."""
    return next(o[3:] for o in record.options if o[0] == record.answer)


def _cmp_by(scene: Scene, seed: int = 0) -> dict[tuple[str, int, int], QARecord]:
    """Size-comparison records keyed by (sub type, object-1 id, object-2 id)."""
    out = {}
    for r in _records(cmp.FAMILY, scene, seed):
        ids = tuple(ref["id"] for ref in r.geometry["refs"])
        out[(r.sub_question_type, *ids)] = r
    return out


def _two_objects(one: Instance, two: Instance) -> Scene:
    """``one`` clearly visible only in view a, ``two`` only in view b."""
    vis = {"a": {one.id: CLEAR}, "b": {two.id: CLEAR}}
    return build([one, two], VIEWS, vis)


def _answer_of(scene: Scene, sub: str, seed: int = 0) -> str:
    records = [r for r in _records(cmp.FAMILY, scene, seed) if r.sub_question_type == sub]
    assert len(records) == 1
    return _truth(records[0])


# ===================================================================== size comparison
def test_sofa_is_longer_than_chair() -> None:
    sofa = obj(1, "sofa", (2.0, 0.0, 0.4), (2.0, 0.9, 0.8), "grey fabric sofa")
    chair = obj(2, "chair", (2.0, 1.5, 0.5), (0.5, 0.5, 1.0), "wooden chair")
    scene = _two_objects(sofa, chair)
    records = _records(cmp.FAMILY, scene)
    assert {r.sub_question_type for r in records} == {"longest_side_compare", "top_height_compare"}
    rec = next(r for r in records if r.sub_question_type == "longest_side_compare")
    assert _truth(rec) == "grey fabric sofa"
    g = rec.geometry
    first, second = g["refs"]
    # object 1 is the one seen in image A (whichever view the pair orientation made A)
    assert first["view"] == rec.views[0] and second["view"] == rec.views[1]
    values = {ref["id"]: v for ref, v in zip(g["refs"], g["values"])}
    assert values == {1: 2.0, 2: 1.0}
    assert g["delta"] == pytest.approx(g["values"][0] - g["values"][1])
    # what a view can resolve: same below max(5 cm, 10 %), different from max(10 cm, 20 %)
    assert g["tie_threshold_m"] == pytest.approx(0.2) and g["different_threshold_m"] == pytest.approx(0.4)
    assert g["quantity"] == "longest_side"
    assert g["selection"]["roles"] == ["first", "second", "same"] and g["selection"]["role"] == "second"  # "sofa" > "chair"
    assert g["selection"]["cell"] == "longest_side_compare|prior:second|strong"  # typical sofa 1.95 m vs chair 0.9 m
    assert rec.question.splitlines()[1].startswith("Which is longer (consider the longest side of the object)? ")
    assert rec.task_group is TaskGroup.OBJECT_CENTRIC and rec.answer_type is AnswerType.MCQ
    # chair top 1.0 m > sofa top 0.8 m
    assert _answer_of(scene, "top_height_compare") == "wooden chair"


def test_question_text_and_options() -> None:
    sofa = obj(1, "sofa", (2.0, 0.0, 0.4), (2.0, 0.9, 0.8), "grey fabric sofa")
    chair = obj(2, "chair", (2.0, 1.5, 0.45), (0.5, 0.5, 0.9), "wooden chair")
    for rec in _records(cmp.FAMILY, _two_objects(sofa, chair)):
        p1, p2 = (object_phrase(ref["label"], ref["description"]) for ref in rec.geometry["refs"])
        assert rec.question == cmp.render_question(rec.sub_question_type, p1, p2)
        assert rec.question.startswith(f"In image A, find the {p1}. In image B, find the {p2}.\n")
        assert sorted(o[3:] for o in rec.options) == sorted([p1, p2, "about the same"])  # the three possible answers
    assert cmp.render_question("top_height_compare", "lamp", "table").endswith(
        "Which object's top is higher (consider the top of the objects)? lamp or table?"
    )


def test_box_rotated_about_up_keeps_its_longest_side() -> None:
    rotated = obj(1, "bench", (2.0, 0.0, 0.4), (2.0, 0.5, 0.8), "long wooden bench", yaw_deg=90.0)
    other = obj(2, "table", (2.0, 1.5, 0.4), (1.5, 0.9, 0.8), "white table")
    scene = _two_objects(rotated, other)
    assert _answer_of(scene, "longest_side_compare") == "long wooden bench"
    rec = next(r for r in _records(cmp.FAMILY, scene) if r.sub_question_type == "longest_side_compare")
    values = {ref["id"]: v for ref, v in zip(rec.geometry["refs"], rec.geometry["values"])}
    assert values[1] == pytest.approx(2.0)
    # a box pitched 45° about a horizontal axis: still its longest side, not its vertical span
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(math.pi / 4), -math.sin(math.pi / 4)], [0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)]])
    assert cmp.longest_side(Instance(3, "pole", "", OrientedBox(np.zeros(3), np.array([0.1, 1.5, 0.1]), tilt))) == 1.5


def test_what_a_view_can_resolve() -> None:
    """Same below max(5 cm, 10 %), different from max(10 cm, 20 %), the grey zone between skipped
    (the paper's 1 cm tie cannot be seen); tops: same below 5 cm, different from 15 cm."""
    # corner diagonals differ a lot (1.04 m vs 1.33 m); longest sides differ by 9 cm < 10 % of 1.09 m
    thin = obj(1, "shelf", (2.0, 0.0, 0.5), (1.0, 0.2, 0.2), "narrow metal shelf")
    bulky = obj(2, "cabinet", (2.0, 1.5, 0.5), (1.09, 0.8, 0.6), "oak cabinet")
    assert abs(np.linalg.norm(thin.box.extents) - np.linalg.norm(bulky.box.extents)) > 0.25
    scene = _two_objects(thin, bulky)
    assert _answer_of(scene, "longest_side_compare") == "about the same"
    rec = next(r for r in _records(cmp.FAMILY, scene) if r.sub_question_type == "longest_side_compare")
    assert rec.geometry["truth"] == "same" and rec.geometry["selection"]["role"] == "same"
    # 15 cm apart on 1.15 m: visible but not sure → skipped
    unsure = obj(2, "cabinet", (2.0, 1.5, 0.5), (1.15, 0.8, 0.6), "oak cabinet")
    assert not [r for r in _records(cmp.FAMILY, _two_objects(thin, unsure)) if r.sub_question_type == "longest_side_compare"]
    # 30 cm apart on 1.3 m (>= 26 cm): clearly different
    longer = obj(2, "cabinet", (2.0, 1.5, 0.5), (1.3, 0.8, 0.6), "oak cabinet")
    assert _answer_of(_two_objects(thin, longer), "longest_side_compare") == "oak cabinet"
    assert cmp.thresholds_for("longest_side", [0.3, 0.2]) == (0.05, 0.1)
    assert cmp.thresholds_for("top_elevation", [5.0, 2.0]) == (0.05, 0.15)


def test_top_height_tall_thin_lamp_vs_wide_low_table() -> None:
    lamp = obj(1, "lamp", (2.0, 0.0, 0.8), (0.3, 0.3, 1.6), "black floor lamp")
    table = obj(2, "table", (2.0, 1.5, 0.25), (2.0, 1.0, 0.5), "low glass table")
    scene = _two_objects(lamp, table)
    assert _answer_of(scene, "top_height_compare") == "black floor lamp"
    assert _answer_of(scene, "longest_side_compare") == "low glass table"  # 2.0 m > 1.6 m
    rec = next(r for r in _records(cmp.FAMILY, scene) if r.sub_question_type == "top_height_compare")
    g = rec.geometry
    tops = {ref["id"]: v for ref, v in zip(g["refs"], g["values"])}
    assert tops == {1: pytest.approx(1.6), 2: pytest.approx(0.5)}
    assert g["quantity"] == "top_elevation" and g["up"] == [0.0, 0.0, 1.0]
    for entry in g["objects"]:
        assert entry["top_corner"][2] == pytest.approx(entry["value"])
    # top of a tilted box comes from its highest corner
    tilt = np.array([[1.0, 0.0, 0.0], [0.0, math.cos(math.pi / 4), -math.sin(math.pi / 4)], [0.0, math.sin(math.pi / 4), math.cos(math.pi / 4)]])
    pole = Instance(3, "pole", "", OrientedBox(np.array([0.0, 0.0, 1.0]), np.array([0.2, 1.0, 0.2]), tilt))
    expected = 1.0 + 0.5 * math.sin(math.pi / 4) + 0.1 * math.cos(math.pi / 4)
    assert cmp.top_elevation(pole, np.array([0.0, 0.0, 1.0])) == pytest.approx(expected)


def test_equal_tops_are_about_the_same() -> None:
    a = obj(1, "box", (2.0, 0.0, 0.5), (0.4, 0.4, 1.0), "cardboard box")
    b = obj(2, "crate", (2.0, 1.5, 0.7), (0.4, 0.4, 0.605), "plastic crate")  # top 1.0025 m
    assert _answer_of(_two_objects(a, b), "top_height_compare") == "about the same"


def _rich_scene() -> Scene:
    """Five objects, three views, partial visibility: many comparison candidates."""
    insts = [
        obj(1, "sofa", (3.0, 0.0, 0.4), (2.0, 0.9, 0.8), "grey fabric sofa"),
        obj(2, "chair", (3.0, 1.5, 0.45), (0.5, 0.5, 0.9), "wooden chair"),
        obj(3, "lamp", (4.0, -1.0, 0.8), (0.3, 0.3, 1.6), "black floor lamp", yaw_deg=20.0),
        obj(4, "table", (3.5, 0.5, 0.375), (1.2, 0.7, 0.75), "white table", yaw_deg=35.0),
        obj(5, "chair", (2.5, -0.5, 0.45), (0.505, 0.5, 0.9), "red plastic chair"),
    ]
    views = {"a": camera((0.0, 0.0, 1.2), 0.0), "b": camera((0.0, 1.0, 1.2), 10.0), "c": camera((0.5, -1.0, 1.4), -15.0)}
    vis = {
        "a": {1: CLEAR, 2: CLEAR, 3: CLEAR, 4: PARTLY, 5: CLEAR},
        "b": {1: CLEAR, 2: CLEAR, 4: CLEAR, 5: PARTLY},
        "c": {3: CLEAR, 4: CLEAR, 5: CLEAR},
    }
    return build(insts, views, vis, covisibility=0.5, vocabulary=["sofa", "chair", "lamp", "table", "bed", "Television"])


def test_only_possible_answers_are_offered_and_letters_spread() -> None:
    """Three options (object 1, object 2, about the same): no never-correct option; letters A–C spread."""
    scene = _rich_scene()
    letters = []
    for seed in range(8):
        for r in _records(cmp.FAMILY, scene, seed):
            texts = [o[3:] for o in r.options]
            assert len(texts) == 3 and cmp.SAME in texts and cmp.NEVER_CORRECT not in texts
            assert r.geometry["truth_text"] == _truth(r)
            letters.append(r.answer)
    assert set(letters) == {"A", "B", "C"}
    counts = [letters.count(x) for x in "ABC"]
    assert min(counts) > 0.2 * len(letters)


def test_comparison_object_rules() -> None:
    scene = _rich_scene()
    records = _records(cmp.FAMILY, scene)
    assert records
    for r in records:
        (r1, r2) = r.geometry["refs"]
        assert r1["id"] != r2["id"]
        assert (r1["view"], r2["view"]) == r.views
        # object 1 clearly visible in A, object 2 in B
        for ref in (r1, r2):
            assert scene.instance(ref["id"]).visibility[ref["view"]] == CLEAR
    # object 4 is only partial in a, object 5 only partial in b: never referenced there
    refs = {(ref["id"], ref["view"]) for r in records for ref in r.geometry["refs"]}
    assert (4, "a") not in refs and (5, "b") not in refs
    assert (4, "b") in refs and (5, "a") in refs
    # every (pair, object 1, object 2, sub) appears at most once
    keys = [(r.views, tuple(ref["id"] for ref in r.geometry["refs"]), r.sub_question_type) for r in records]
    assert len(keys) == len(set(keys))
    assert len({r.id for r in records}) == len(records)


def test_twins_with_same_description_are_skipped() -> None:
    twin1 = obj(1, "chair", (2.0, 0.0, 0.45), (0.5, 0.5, 0.9), "black office chair")
    twin2 = obj(2, "chair", (2.0, 0.8, 0.45), (0.5, 0.5, 0.9), "black office chair")
    table = obj(3, "table", (2.0, 1.5, 0.4), (1.2, 0.8, 0.8), "white table")
    # a shows both twins (twin2 only partly: still a clash); b shows table and twin1
    vis = {"a": {1: CLEAR, 2: PARTLY, 3: CLEAR}, "b": {1: CLEAR, 3: CLEAR}}
    scene = build([twin1, twin2, table], VIEWS, vis)
    records = _records(cmp.FAMILY, scene)
    refs = {(ref["id"], ref["view"]) for r in records for ref in r.geometry["refs"]}
    assert (1, "a") not in refs and (2, "a") not in refs  # ambiguous in a
    assert (1, "b") in refs  # alone in b: fine
    bs = _records(bsize.FAMILY, scene)
    assert {(r.geometry["object"]["id"], r.views[0]) for r in bs} == {(3, "a"), (3, "b"), (1, "b")}
    # different descriptions make them referable again
    twin2b = obj(2, "chair", (2.0, 0.8, 0.45), (0.5, 0.5, 0.9), "red office chair")
    scene2 = build([twin1, twin2b, table], VIEWS, vis)
    bs2 = {(r.geometry["object"]["id"], r.views[0]) for r in _records(bsize.FAMILY, scene2)}
    assert (1, "a") in bs2


def test_same_label_same_description_objects_are_never_compared() -> None:
    # two identical-looking chairs, each alone in its view: no way to tell them apart in words
    c1 = obj(1, "chair", (2.0, 0.0, 0.45), (0.5, 0.5, 0.9), "black office chair")
    c2 = obj(2, "chair", (2.0, 1.5, 0.45), (0.6, 0.5, 0.9), "black office chair")
    assert _records(cmp.FAMILY, _two_objects(c1, c2)) == []
    # same label, different descriptions: fine
    c3 = obj(2, "chair", (2.0, 1.5, 0.45), (0.6, 0.5, 0.9), "red office chair")
    assert len(_records(cmp.FAMILY, _two_objects(c1, c3))) == 2
    # different labels, no descriptions: fine
    d1 = obj(1, "chair", (2.0, 0.0, 0.45), (0.5, 0.5, 0.9), "")
    d2 = obj(2, "stool", (2.0, 1.5, 0.45), (0.6, 0.5, 0.9), "")
    assert len(_records(cmp.FAMILY, _two_objects(d1, d2))) == 2


def test_pairs_need_covisibility_and_baseline() -> None:
    sofa = obj(1, "sofa", (2.0, 0.0, 0.4), (2.0, 0.9, 0.8), "grey fabric sofa")
    chair = obj(2, "chair", (2.0, 1.5, 0.45), (0.5, 0.5, 0.9), "wooden chair")
    vis = {"a": {1: CLEAR}, "b": {2: CLEAR}}
    assert _records(cmp.FAMILY, build([sofa, chair], VIEWS, vis, covisibility=0.2)) == []
    close = {"a": camera((0.0, 0.0, 1.2), 0.0), "b": camera((0.0, 0.1, 1.2), 10.0)}  # 0.1 m < 0.2 m
    assert _records(cmp.FAMILY, build([sofa, chair], close, vis)) == []


def test_round_robin_over_pairs() -> None:
    records = _records(cmp.FAMILY, _rich_scene(), 3)
    pairs = [frozenset(r.views) for r in records]
    n_pairs = len(set(pairs))
    assert n_pairs == 3
    assert len(set(pairs[:n_pairs])) == n_pairs  # the first round visits every pair


# ===================================================================== bounding size
def test_bounding_size_exact_and_sorted() -> None:
    box = obj(1, "box", (2.0, 0.0, 0.2), (0.3, 0.1, 0.2), "small cardboard box", yaw_deg=30.0)
    odd = obj(2, "vase", (2.0, 0.5, 0.2), (0.456, 0.789, 0.123), "blue ceramic vase")
    flat = obj(3, "poster", (2.0, -0.5, 1.0), (0.6, 0.004, 0.9), "movie poster")
    scene = build([box, odd, flat], {"a": VIEWS["a"]})
    records = {r.geometry["object"]["id"]: r for r in _records(bsize.FAMILY, scene)}
    assert set(records) == {1, 2}  # the 4 mm poster rounds to 0.00 m: skipped
    assert records[1].answer == (0.1, 0.2, 0.3)
    assert records[2].answer == (0.12, 0.46, 0.79)
    r = records[1]
    assert r.answer_type is AnswerType.SIZE_LIST and r.sub_question_type == "extent_list" and r.options == ()
    assert r.to_dict()["answer"] == [0.1, 0.2, 0.3]
    g = r.geometry
    assert g["sorted_extents"] == pytest.approx([0.1, 0.2, 0.3]) and g["rounding_decimals"] == 2
    assert g["refs"] == [{"id": 1, "label": "box", "description": "small cardboard box", "view": "a"}]
    assert g["object"]["extents"] == pytest.approx([0.3, 0.1, 0.2])
    assert g["visibility"]["class"] == "visible"
    assert r.question == bsize.render_question(g["template"], box)
    assert "small cardboard box" in r.question


def test_bounding_size_templates_and_visibility() -> None:
    scene = _rich_scene()
    seen = set()
    for seed in range(12):
        for r in _records(bsize.FAMILY, scene, seed):
            seen.add(r.geometry["template"])
            assert r.question == bsize.TEMPLATES[r.geometry["template"]].format(
                target_obj=object_phrase(r.geometry["object"]["label"], r.geometry["object"]["description"])
            )
    assert seen == {0, 1, 2, 3}
    keys = {(r.geometry["object"]["id"], r.views[0]) for r in _records(bsize.FAMILY, scene)}
    assert keys == {(1, "a"), (2, "a"), (3, "a"), (5, "a"), (1, "b"), (2, "b"), (4, "b"), (3, "c"), (4, "c"), (5, "c")}
    assert bsize.TEMPLATES[0].format(target_obj="red cup").startswith("What are the 3D physical dimensions of the red cup?")


# ===================================================================== existence
_DEFAULT_VOCAB = ["chair", "table", "lamp", "bed", "umbrella"]


def _existence_scene(vocabulary: list[str] | None = _DEFAULT_VOCAB) -> Scene:
    """v0: chair 1 clear + chair 2 partial → yes; table partial → grey; lamp hidden → no.
    v1: chair 1 partial only → grey; table, lamp clear → yes. v2: nothing visible → all no."""
    insts = [
        obj(1, "chair", (2.0, 0.0, 0.45), (0.5, 0.5, 0.9), "black chair"),
        obj(2, "chair", (2.0, 0.8, 0.45), (0.5, 0.5, 0.9), "red chair"),
        obj(3, "table", (3.0, 0.0, 0.4), (1.2, 0.8, 0.8), "white table"),
        obj(4, "lamp", (3.0, 1.0, 0.8), (0.3, 0.3, 1.6), "floor lamp"),
    ]
    views = {"v0": camera((0, 0, 1.2), 0), "v1": camera((0, 1, 1.2), 10), "v2": camera((0, -1, 1.2), 180)}
    vis = {
        "v0": {1: CLEAR, 2: PARTLY, 3: PARTLY, 4: InstanceVisibility(0, 0.0)},
        "v1": {1: PARTLY, 3: CLEAR, 4: CLEAR},
        "v2": {},
    }
    return build(insts, views, vis, vocabulary=vocabulary)


def test_existence_yes_no_and_grey_zone() -> None:
    scene = _existence_scene()
    index = exist.VisibilityIndex(scene)
    pos, neg = exist.candidates(scene, index)
    assert {(c.view, c.key) for c in pos} == {("v0", "chair"), ("v1", "table"), ("v1", "lamp")}
    assert {(c.view, c.key) for c in neg} == {
        ("v0", "lamp"), ("v0", "bed"), ("v0", "umbrella"), ("v1", "bed"), ("v1", "umbrella"),
        ("v2", "chair"), ("v2", "table"), ("v2", "lamp"), ("v2", "bed"), ("v2", "umbrella"),
    }
    for seed in range(10):
        records = _records(exist.FAMILY, scene, seed)
        assert len(records) == 6
        keys = {(r.views[0], r.geometry["label_key"]): r.answer for r in records}
        assert ("v0", "table") not in keys and ("v1", "chair") not in keys  # grey zone
        for (view, key), answer in keys.items():
            assert answer == ("yes" if (view, key) in {(c.view, c.key) for c in pos} else "no")
        for r in records:
            assert r.answer_type is AnswerType.YN and r.sub_question_type == "existence" and r.options == ()
            assert r.geometry["refs"] == []
            classes = [i["class"] for i in r.geometry["instances"]]
            if r.answer == "yes":
                assert "visible" in classes
            else:
                assert all(c == "hidden" for c in classes)


def test_existence_geometry_and_wording() -> None:
    scene = _existence_scene()
    recs = {(r.views[0], r.geometry["label_key"]): r for s in range(20) for r in _records(exist.FAMILY, scene, s)}
    yes = recs[("v0", "chair")]
    assert yes.answer == "yes" and yes.geometry["label_source"] == "scene"
    assert yes.geometry["instances"] == [
        {"id": 1, "visible_pixels": 5000, "visible_fraction": 0.9, "class": "visible"},
        {"id": 2, "visible_pixels": 60, "visible_fraction": 0.2, "class": "partial"},
    ]
    assert yes.geometry["thresholds"] == {"min_pixels": 400.0, "min_fraction": 0.5}
    assert "black" not in yes.question and "red" not in yes.question  # label only, no description
    assert yes.question == exist.render_question(yes.geometry["template"], "chair")
    lamp = recs[("v0", "lamp")]
    assert lamp.answer == "no" and lamp.geometry["instances"][0]["class"] == "hidden"
    templates = {r.geometry["template"] for s in range(20) for r in _records(exist.FAMILY, scene, s)}
    assert templates == {0, 1, 2, 3}
    for s in range(5):  # a "yes" and its "no" read word for word the same
        records = _records(exist.FAMILY, scene, s)
        for a, b in zip(records[::2], records[1::2]):
            assert a.geometry["label_key"] == b.geometry["label_key"] and a.question == b.question and {a.answer, b.answer} == {"yes", "no"}
    assert exist.render_question(0, "chair") == "Is there a chair visible in this image?"
    assert exist.render_question(1, "umbrella") == "Can you find an umbrella in the current view?"
    assert exist.render_question(2, "coffee_table") == "Does the image contain a coffee table?"
    assert exist.render_question(3, "apple") == "Check if an apple is present in this picture."
    assert [language.indefinite_article(w) for w in ("unicorn toy", "hour glass", "TV", "HDMI cable", "oven")] == ["a", "an", "a", "an", "an"]
    assert language.with_articles("A orange lamp with a olive shade, a uniform and a red cup") == "An orange lamp with an olive shade, a uniform and a red cup"


def test_existence_negatives_from_vocabulary() -> None:
    """Vocabulary words are negative candidates, but a label that is never "yes" in the scene is
    never asked: the label alone would give its answer away."""
    scene = _existence_scene(["Chair", "bed", "Coffee_Table", "coffee table"])
    index = exist.VisibilityIndex(scene)
    _, neg = exist.candidates(scene, index)
    sources = {c.key: c.source for c in neg}
    assert sources["bed"] == "vocabulary" and sources["coffee table"] == "vocabulary" and sources["lamp"] == "scene"
    seen: dict[str, set[str]] = {}
    for seed in range(30):
        for r in _records(exist.FAMILY, scene, seed):
            seen.setdefault(r.geometry["label_key"], set()).add(r.answer)
            assert r.geometry["label_source"] == "scene"
    assert set(seen) == {"chair", "table", "lamp"} and all(v == {"yes", "no"} for v in seen.values())
    # without a vocabulary only scene labels exist
    plain = _existence_scene(None)
    assert plain.vocabulary == ("chair", "lamp", "table")
    got = {(r.views[0], r.geometry["label_key"]): r for s in range(10) for r in _records(exist.FAMILY, plain, s)}
    assert {k for k, r in got.items() if r.answer == "no"} <= {("v0", "lamp"), ("v2", "chair"), ("v2", "table"), ("v2", "lamp")}
    assert [r.answer for r in _records(exist.FAMILY, plain, 0)].count("no") == 3


def _prefix_balanced(answers: list[str]) -> bool:
    diff = 0
    for a in answers:
        diff += 1 if a == "yes" else -1
        if abs(diff) > 1:
            return False
    return diff == 0


def test_existence_balance_exact() -> None:
    scene = _existence_scene()
    starts = set()
    for seed in range(20):
        answers = [r.answer for r in _records(exist.FAMILY, scene, seed)]
        assert answers.count("yes") == answers.count("no") == 3
        assert _prefix_balanced(answers)
        starts.add(answers[0])
    assert starts == {"yes", "no"}
    # more positives than negatives: still balanced, capped by the negatives
    insts = [obj(i, f"thing{i}", (2.0, 0.3 * i, 0.4)) for i in range(1, 6)]
    views = {"v0": camera((0, 0, 1.2), 0), "v1": camera((0, 1, 1.2), 10)}
    vis = {"v0": {i: CLEAR for i in range(1, 6)}, "v1": {i: CLEAR for i in range(1, 5)}}
    answers = [r.answer for r in _records(exist.FAMILY, build(insts, views, vis), 1)]
    assert answers.count("yes") == answers.count("no") == 1  # only (v1, thing5) is a negative
    assert _prefix_balanced(answers)


# ===================================================================== invariance & determinism
def _signature(records: list[QARecord]) -> list[tuple]:
    return [(r.id, r.views, r.question, r.options, r.answer, r.sub_question_type) for r in records]


FAMILIES = [cmp.FAMILY, bsize.FAMILY, exist.FAMILY]


@pytest.mark.parametrize("family", FAMILIES, ids=lambda f: f.name)
@pytest.mark.parametrize("seed", [0, 1, 2, 3, 7])
def test_invariant_under_rigid_motion(family: object, seed: int) -> None:
    scene = _rich_scene()
    base = _signature(_records(family, scene, 11))
    assert base
    rot, t = random_rigid(seed)
    moved = scene.transformed(rot, t)
    assert not np.allclose(moved.up, [0.0, 0.0, 1.0])  # up is no longer z
    assert _signature(_records(family, moved, 11)) == base
    # and from a scene whose up is not z to another
    rot2, t2 = random_rigid(seed + 100)
    twice = moved.transformed(rot2, t2)
    assert _signature(_records(family, twice, 11)) == base


def test_top_height_follows_scene_up() -> None:
    lamp = obj(1, "lamp", (2.0, 0.0, 0.8), (0.3, 0.3, 1.6), "black floor lamp")
    table = obj(2, "table", (2.0, 1.5, 0.25), (2.0, 1.0, 0.5), "low glass table")
    scene = _two_objects(lamp, table)
    for seed in range(5):
        rot, t = random_rigid(seed)
        moved = scene.transformed(rot, t)
        rec = next(r for r in _records(cmp.FAMILY, moved) if r.sub_question_type == "top_height_compare")
        assert _truth(rec) == "black floor lamp"
        assert rec.geometry["up"] == pytest.approx((rot @ np.array([0.0, 0.0, 1.0])).tolist())
        assert abs(rec.geometry["delta"]) == pytest.approx(1.1)


@pytest.mark.parametrize("family", FAMILIES, ids=lambda f: f.name)
def test_deterministic_and_lazy(family: object) -> None:
    scene = _rich_scene()
    a, b = _records(family, scene, 42), _records(family, scene, 42)
    assert [r.to_dict() for r in a] == [r.to_dict() for r in b]
    assert json.dumps([r.to_dict() for r in a]) == json.dumps([r.to_dict() for r in b])
    prefix = list(itertools.islice(family.generate(scene, np.random.default_rng(42)), 3))  # type: ignore[attr-defined]
    assert [r.to_dict() for r in prefix] == [r.to_dict() for r in a[:3]]
    orders = {tuple(r.id for r in _records(family, scene, s)) for s in range(6)}
    assert len(orders) > 1
    for r in a:
        assert QARecord.from_json(r.to_json()) == r


def test_geometry_recomputes_answers() -> None:
    """Independent recomputation from the stored geometry block only."""
    scene = _rich_scene()
    for r in _records(cmp.FAMILY, scene, 5):
        g = r.geometry
        up = np.array(g["up"])
        vals = []
        for o in g["objects"]:
            ext, rot, c = np.array(o["extents"]), np.array(o["rotation"]), np.array(o["center"])
            if g["quantity"] == "longest_side":
                vals.append(ext.max())
            else:
                corners = [c + rot @ (np.array(s) * ext / 2) for s in itertools.product((-1, 1), repeat=3)]
                vals.append(max(float(p @ up) for p in corners))
        d = vals[0] - vals[1]
        names = [object_phrase(o["label"], o["description"]) for o in g["objects"]]
        expected = "about the same" if abs(d) < g["tie_threshold_m"] else (names[0] if d > 0 else names[1])
        assert _truth(r) == expected
    for r in _records(bsize.FAMILY, scene, 5):
        assert list(r.answer) == sorted(round(e, 2) for e in r.geometry["object"]["extents"])


# ===================================================================== registration
@pytest.mark.parametrize(
    ("module", "needs", "views", "subs"),
    [
        (cmp, {"visibility", "covisibility"}, (2,), ("longest_side_compare", "top_height_compare")),
        (bsize, {"visibility"}, (1,), ("extent_list",)),
        (exist, {"visibility"}, (1,), ("existence",)),
    ],
    ids=["size_comparison", "bounding_size", "existence"],
)
def test_registered(monkeypatch: pytest.MonkeyPatch, module: object, needs: set, views: tuple, subs: tuple) -> None:
    monkeypatch.delenv("SPACEDG_DISABLE_PLUGIN_AUTOLOAD", raising=False)
    monkeypatch.delenv("SPACEDG_PLUGINS", raising=False)
    reset_registry()
    try:
        family = get_question_family(module.NAME)  # type: ignore[attr-defined]
        assert family.origin is not None and family.origin.builtin
        assert family.task_group is TaskGroup.OBJECT_CENTRIC
        assert family.needs == frozenset(needs) and family.num_views == views and family.sub_question_types == subs
        scene = _rich_scene()
        assert [r.to_dict() for r in family.generate(scene, np.random.default_rng(5))] == [
            r.to_dict() for r in _records(module.FAMILY, scene, 5)  # type: ignore[attr-defined]
        ]
    finally:
        reset_registry()


def test_label_only_questions_skip_confusable_labels():
    """Counting "lamp" or answering "no lamp" while a "floor lamp" is in view is ambiguous: skipped."""
    from tests.qa_scenes import CLEAR, build, camera, obj
    from spacedg.plugins.questions.view_sampling import confusable, head_noun
    from spacedg.plugins.questions import object_counting

    assert head_noun("Floor_Lamp") == "lamp" and head_noun("pair of shoes") == "pair"
    assert confusable("lamp", "floor lamp") and not confusable("lamp", "Lamp") and not confusable("chair", "table")
    assert confusable("chair", "armchair") and confusable("monitor", "tv") and confusable("table", "desk")  # the lexicon
    views = {"both": camera((0, 0, 1.5)), "floor_only": camera((0, -1, 1.5)), "lamp_only": camera((0, 1, 1.5))}
    insts = [obj(1, "lamp", (2, 0, 0.8)), obj(2, "floor lamp", (2, 1, 0.8)), obj(3, "chair", (3, 0, 0.4))]
    vis = {"both": {1: CLEAR, 2: CLEAR, 3: CLEAR}, "floor_only": {2: CLEAR, 3: CLEAR}, "lamp_only": {1: CLEAR, 3: CLEAR}}
    scene = build(insts, views, vis, vocabulary=["lamp", "floor lamp", "chair", "sofa"])
    every = object_counting.make_family(counts=None)
    counts = {(r.views[0], r.geometry["label"]) for r in every.generate(scene, np.random.default_rng(0))}
    assert ("both", "lamp") not in counts and ("both", "floor lamp") not in counts
    assert {("lamp_only", "lamp"), ("floor_only", "floor lamp"), ("both", "chair")} <= counts
    answers = {(r.views[0], r.geometry["label_key"]): r.answer for seed in range(6)
               for r in exist.FAMILY.generate(scene, np.random.default_rng(seed))}
    assert ("floor_only", "lamp") not in answers and ("lamp_only", "floor lamp") not in answers  # "no" would be ambiguous
    assert answers.get(("both", "lamp")) in (None, "yes") and ("floor_only", "sofa") not in answers  # "sofa" is never "yes"
