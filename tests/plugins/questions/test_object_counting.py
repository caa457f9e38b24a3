"""Built-in ``object_counting`` family, visibility classes and plural wording.

The scene is built by hand with visibility filled in, so every answer is known by
construction:

======  =============================================  ==============================
view    instances (visible_pixels, visible_fraction)    expected
======  =============================================  ==============================
v0      chair 1 (1000, .9), 2 (500, .6), 3 (0, 0)       2 chairs (3 hidden)
        box 4 (800, .9), 5 (50, .8) → 5 is partial      skipped (grey zone)
        shelf 6 (2000, 1.0)                             1 shelf
        glass 9 (300, .9): 300 < 400 px → partial       skipped
        person 7, 8: no record                          0 people
v1      chair 1 (900, .2): fraction < .25 → partial     skipped
        box 4 (700, .7), 5 (450, .5)                    2 boxes
        person 7 (5000, 1.0), 8 (1200, .55)             2 people
        glass 9 (1000, 1.0)                             1 glass
v2      320×240 image: min_pixels scales to 100         1 chair (150 px is enough here;
        chair 1 (150, .7), chair 2 no record                    2 hidden, no record)
        no box, shelf, person, glass                    0 of each (v1: 0 shelves)
======  =============================================  ==============================

These construction tests use the unbalanced family (``counts=None``: every valid count); the
registered family asks the bins 0, 1 and 2+ equally often per label (``test_balanced_counts_per_label``).
"""

from __future__ import annotations

import itertools
import json
from collections import Counter

import numpy as np
import pytest

from spacedg.scene.box import OrientedBox
from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Instance, InstanceVisibility, Scene
from spacedg.scene.visibility_classes import DEFAULT_THRESHOLDS, VisibilityClass, VisibilityThresholds, classify
from spacedg.errors import InvalidDataError, ParameterError
from spacedg.plugins import AnswerType, TaskGroup, get_question_family, reset_registry
from spacedg.plugins.questions import object_counting
from spacedg.plugins.questions.language import count_phrase, label_text, plural
from spacedg.plugins.questions.object_counting import FAMILY, TEMPLATES, make_family, render_question
from spacedg.render.camera import Camera, look_at
from spacedg.render.gaussians import Gaussians

V = InstanceVisibility
EXPECTED = {("v0", "chair"): 2, ("v0", "shelf"): 1, ("v1", "box"): 2, ("v1", "person"): 2, ("v1", "glass"): 1, ("v2", "chair"): 1}
ZEROS = {("v0", "person"): 0, ("v1", "shelf"): 0, ("v2", "box"): 0, ("v2", "shelf"): 0, ("v2", "person"): 0, ("v2", "glass"): 0}
#: Every valid candidate, unbalanced.
UNBALANCED = make_family(counts=None)


def _camera(eye: tuple[float, float, float], width: int = 640, height: int = 480) -> Camera:
    pose = look_at(np.array(eye), np.array([0.0, 0.0, 0.5]), np.array([0.0, 0.0, 1.0]))
    f = 0.8 * width
    return Camera(f, f, width / 2, height / 2, width, height, pose)


def _instance(iid: int, label: str, pos: tuple[float, float, float], vis: dict[str, InstanceVisibility]) -> Instance:
    box = OrientedBox(np.array(pos), np.array([0.4, 0.4, 0.8]))
    return Instance(iid, label, f"a {label}", box, images=tuple(vis), visibility=vis)


def build_scene(with_visibility: bool = True) -> Scene:
    means = np.array([[0.0, 0.0, 0.5], [1.0, 0.0, 0.5], [0.0, 1.0, 0.5], [1.0, 1.0, 0.5]])
    gaussians = Gaussians.from_colors(
        means, np.tile([1.0, 0.0, 0.0, 0.0], (4, 1)), np.full((4, 3), 0.05), np.full(4, 0.9),
        np.array([[0.8, 0.2, 0.2], [0.2, 0.8, 0.2], [0.2, 0.2, 0.8], [0.5, 0.5, 0.5]]),
        instance_ids=np.array([1, 4, 6, 9]),
    )
    views = {"v0": _camera((3.0, 0.0, 1.5)), "v1": _camera((0.0, 3.0, 1.5)), "v2": _camera((-3.0, 0.5, 1.5), 320, 240)}
    vis: dict[int, dict[str, InstanceVisibility]] = {
        1: {"v0": V(1000, 0.9), "v1": V(900, 0.2), "v2": V(150, 0.7)},
        2: {"v0": V(500, 0.6)},
        3: {"v0": V(0, 0.0)},
        4: {"v0": V(800, 0.9), "v1": V(700, 0.7)},
        5: {"v0": V(50, 0.8), "v1": V(450, 0.5)},
        6: {"v0": V(2000, 1.0)},
        7: {"v1": V(5000, 1.0)},
        8: {"v1": V(1200, 0.55)},
        9: {"v0": V(300, 0.9), "v1": V(1000, 1.0)},
    }
    labels = {1: "chair", 2: "chair", 3: "chair", 4: "box", 5: "box", 6: "shelf", 7: "person", 8: "person", 9: "glass"}
    instances = [
        _instance(i, labels[i], (0.3 * i, 0.1 * i, 0.4), vis[i] if with_visibility else {}) for i in sorted(labels)
    ]
    return Scene("counting_room", gaussians, views, instances, up=(0.0, 0.0, 1.0))


@pytest.fixture(scope="module")
def scene() -> Scene:
    return build_scene()


def _records(scene: Scene, seed: int = 0) -> list[QARecord]:
    return list(UNBALANCED.generate(scene, np.random.default_rng(seed)))


# ------------------------------------------------------------- answers
def test_counts_known_by_construction(scene: Scene) -> None:
    records = _records(scene)
    got = {(r.views[0], r.geometry["label"]): r.answer for r in records}
    assert got == {**EXPECTED, **ZEROS}
    assert len(records) == len(EXPECTED) + len(ZEROS)  # one record per (view, label)
    for r in records:
        assert r.question_type == "object_counting" and r.sub_question_type == "count"
        assert r.task_group is TaskGroup.OBJECT_CENTRIC and r.answer_type is AnswerType.COUNT
        assert isinstance(r.answer, int) and r.answer >= 0 and r.options == ()
        assert r.scene_id == "counting_room" and r.id.startswith("counting_room/object_counting/count/")
        assert r.answer == len(r.geometry["counted"])


def test_grey_zone_skipped(scene: Scene) -> None:
    keys = {(r.views[0], r.geometry["label"]) for r in _records(scene)}
    assert ("v0", "box") not in keys  # box 5 has too few pixels
    assert ("v1", "chair") not in keys  # chair 1 too occluded (fraction .2 < .25)
    assert ("v0", "glass") not in keys  # 300 px < 400 px at 640×480
    assert ("v0", "person") in keys  # nothing visible at all: a count of 0


def test_hidden_instances_not_counted(scene: Scene) -> None:
    by_key = {(r.views[0], r.geometry["label"]): r for r in _records(scene)}
    g = by_key[("v0", "chair")].geometry
    assert [c["id"] for c in g["counted"]] == [1, 2]
    assert g["counted"][0] == {"id": 1, "visible_pixels": 1000, "visible_fraction": 0.9}
    assert g["not_counted"] == [{"id": 3, "visible_pixels": 0, "visible_fraction": 0.0, "class": "hidden"}]
    g2 = by_key[("v2", "chair")].geometry
    assert [c["id"] for c in g2["counted"]] == [1]
    assert {"id": 2, "visible_pixels": None, "visible_fraction": None, "class": "hidden"} in g2["not_counted"]
    assert g2["image_size"] == [320, 240]
    assert g2["thresholds"] == {"min_pixels": 100.0, "min_fraction": 0.25}
    assert by_key[("v0", "chair")].geometry["thresholds"]["min_pixels"] == 400.0


def test_counts_as_people_count_a_partly_hidden_instance() -> None:
    """A chair a table hides to 30 % (or half out of frame) is counted, as a person counts it: with
    the 0.5 of the other families it would put the view in the grey zone and nothing would be asked."""
    scene = build_scene()
    half_hidden = [
        inst if inst.id != 1 else Instance(1, "chair", inst.description, inst.box, images=inst.images, visibility={**inst.visibility, "v1": V(900, 0.3)})
        for inst in scene.instances
    ]
    scene = Scene(scene.id, scene.gaussians, scene.views, half_hidden, up=scene.up)
    got = {(r.views[0], r.geometry["label"]): r for r in UNBALANCED.generate(scene, np.random.default_rng(0))}
    assert got[("v1", "chair")].answer == 1 and got[("v1", "chair")].geometry["counted"][0]["visible_fraction"] == 0.3
    assert object_counting.COUNT_THRESHOLDS.min_fraction == 0.25 < DEFAULT_THRESHOLDS.min_fraction
    assert classify(V(900, 0.3), DEFAULT_THRESHOLDS, 640 * 480) is VisibilityClass.PARTIAL  # other families stay strict


def test_custom_thresholds() -> None:
    strict = make_family(VisibilityThresholds(min_pixels=600, min_fraction=0.5), counts=None)
    got = {(r.views[0], r.geometry["label"]): r.answer for r in strict.generate(build_scene(), np.random.default_rng(0))}
    # v0: chair 2 (500 px) becomes partial → skipped; v1: box 5 (450 px) → skipped
    assert ("v0", "chair") not in got and ("v1", "box") not in got
    assert got[("v1", "person")] == 2


# ---------------------------------------------------------- determinism
def test_same_seed_same_records(scene: Scene) -> None:
    a, b = _records(scene, 42), _records(scene, 42)
    assert [r.to_dict() for r in a] == [r.to_dict() for r in b]
    assert json.dumps([r.to_dict() for r in a]) == json.dumps([r.to_dict() for r in b])
    orders = {tuple((r.views[0], r.geometry["label"]) for r in _records(scene, seed)) for seed in range(6)}
    assert len(orders) > 1  # the seed shuffles the order ...
    assert {frozenset(o) for o in orders} == {frozenset({**EXPECTED, **ZEROS})}  # ... of the same candidates
    # lazily generated: taking a prefix gives the prefix
    prefix = list(itertools.islice(UNBALANCED.generate(scene, np.random.default_rng(42)), 3))
    assert [r.id for r in prefix] == [r.id for r in a[:3]]


def test_ids_are_unique_and_stable(scene: Scene) -> None:
    records = _records(scene, 1)
    assert len({r.id for r in records}) == len(records)
    again = {(r.views[0], r.geometry["label"]): r.id for r in _records(scene, 1)}
    assert again == {(r.views[0], r.geometry["label"]): r.id for r in records}


def test_json_round_trip(scene: Scene) -> None:
    for record in _records(scene, 3):
        text = json.dumps(record.to_dict())
        clone = QARecord.from_dict(json.loads(text))
        assert clone == record and clone.to_dict() == record.to_dict()
        assert QARecord.from_json(record.to_json()) == record


# --------------------------------------------------------------- wording
def test_questions_use_templates_and_plurals(scene: Scene) -> None:
    seen_templates = set()
    for seed in range(10):
        for r in _records(scene, seed):
            t = r.geometry["template"]
            seen_templates.add(t)
            assert r.question == render_question(t, r.geometry["label"])
    assert seen_templates == set(range(len(TEMPLATES)))
    assert render_question(0, "box") == "How many boxes are visible in this image?"
    assert render_question(0, "person") == "How many people are visible in this image?"
    assert render_question(2, "shelf") == "What is the total count of shelves shown?"
    assert render_question(3, "glass") == "Tell me how many glasses exist in the current view."
    assert render_question(1, "coffee_table") == "Count the number of coffee table objects in this image."


def test_no_template_says_in_the_scene() -> None:
    # deviation from the paper: the answer counts one image, so no template may ask about the scene
    assert not any("scene" in t for t in TEMPLATES)


@pytest.mark.parametrize(
    ("word", "expected"),
    [
        ("box", "boxes"), ("shelf", "shelves"), ("glass", "glasses"), ("person", "people"), ("chair", "chairs"),
        ("bench", "benches"), ("dish", "dishes"), ("battery", "batteries"), ("toy", "toys"), ("knife", "knives"),
        ("bookshelf", "bookshelves"), ("child", "children"), ("mouse", "mice"), ("potato", "potatoes"),
        ("photo", "photos"), ("roof", "roofs"), ("bus", "buses"), ("lens", "lenses"), ("sheep", "sheep"),
        ("scissors", "scissors"), ("stairs", "stairs"), ("books", "books"), ("TV", "TVs"), ("Sofa", "Sofas"),
        ("coffee table", "coffee tables"), ("office_chair", "office chairs"), ("pair of shoes", "pairs of shoes"),
        ("salesperson", "salespeople"), ("stomach", "stomachs"), ("cactus", "cacti"), ("taxi", "taxis"),
    ],
)
def test_plural(word: str, expected: str) -> None:
    assert plural(word) == expected


def test_label_text_and_count_phrase() -> None:
    assert label_text("  coffee__table ") == "coffee table"
    assert count_phrase(1, "box") == "1 box" and count_phrase(3, "box") == "3 boxes" and count_phrase(0, "person") == "0 people"


# ------------------------------------------------------------ visibility
def test_classify() -> None:
    assert classify(None) is VisibilityClass.HIDDEN
    assert classify(V(0, 0.0)) is VisibilityClass.HIDDEN
    assert classify(V(400, 0.5)) is VisibilityClass.VISIBLE  # thresholds are inclusive
    assert classify(V(399, 1.0)) is VisibilityClass.PARTIAL
    assert classify(V(10_000, 0.49)) is VisibilityClass.PARTIAL
    assert classify(V(1, 1.0)) is VisibilityClass.PARTIAL
    # scaled with the image area: 1280×960 needs 4× the pixels
    assert classify(V(1000, 0.9), image_area=1280 * 960) is VisibilityClass.PARTIAL
    assert classify(V(1600, 0.9), image_area=1280 * 960) is VisibilityClass.VISIBLE
    assert DEFAULT_THRESHOLDS.pixels_for(None) == 400.0


@pytest.mark.parametrize(
    ("kwargs", "pattern"),
    [({"min_pixels": 0}, "min_pixels must be a number > 0"), ({"min_fraction": 0.0}, r"min_fraction must be in \(0, 1\]"),
     ({"min_fraction": 1.5}, "min_fraction"), ({"reference_area": 0}, "reference_area")],
)
def test_bad_thresholds(kwargs: dict, pattern: str) -> None:
    with pytest.raises(InvalidDataError, match=pattern):
        VisibilityThresholds(**kwargs)


# --------------------------------------------------------- family checks
def test_registered_family_matches_module(monkeypatch: pytest.MonkeyPatch, scene: Scene) -> None:
    monkeypatch.delenv("SPACEDG_DISABLE_PLUGIN_AUTOLOAD", raising=False)
    monkeypatch.delenv("SPACEDG_PLUGINS", raising=False)
    reset_registry()
    try:
        family = get_question_family("object_counting")
        assert family.origin is not None and family.origin.builtin
        assert family.needs == frozenset({"visibility"}) and family.num_views == (1,)
        via_registry = [r.to_dict() for r in family.generate(scene, np.random.default_rng(5))]
        assert via_registry == [r.to_dict() for r in FAMILY.generate(scene, np.random.default_rng(5))]
    finally:
        reset_registry()


def test_missing_visibility_is_a_clear_error() -> None:
    with pytest.raises(InvalidDataError, match="needs per-view instance visibility.*spacedg.scene.visibility"):
        FAMILY.generate(build_scene(with_visibility=False), np.random.default_rng(0))


def test_rng_must_be_a_generator(scene: Scene) -> None:
    with pytest.raises(ParameterError, match="numpy.random.Generator.*default_rng"):
        FAMILY.generate(scene, 0)  # type: ignore[arg-type]


def test_empty_scene_yields_nothing() -> None:
    empty = Scene("empty", Gaussians.empty(), {"v0": _camera((3.0, 0.0, 1.5))}, [])
    assert list(FAMILY.generate(empty, np.random.default_rng(0))) == []


def test_balanced_counts_per_label() -> None:
    """The registered family asks the bins 0, 1 and 2+ of a label equally often, one wording per round;
    a label that cannot reach every count is not asked; related labels (armchair) and objects
    showing a label (a bookshelf's books) make a view ambiguous."""
    from tests.qa_scenes import CLEAR, build, camera, obj

    chairs = [obj(1, "chair", (2, 0, 0.4), description="red chair"), obj(2, "chair", (2, 1, 0.4), description="blue chair")]
    extra = [obj(3, "table", (3, 0, 0.4)), obj(4, "armchair", (3, 2, 0.4)), obj(5, "bookshelf", (4, 0, 1.0)), obj(6, "book", (3, 0, 0.8))]
    views = {f"v{k}": camera((0, 0, 1.5), 10.0 * k) for k in range(7)}
    vis = {
        "v0": {1: CLEAR, 2: CLEAR, 3: CLEAR}, "v1": {1: CLEAR, 3: CLEAR}, "v2": {3: CLEAR}, "v3": {1: CLEAR, 2: CLEAR},
        "v4": {1: CLEAR, 4: CLEAR},  # an armchair beside the chair: ambiguous for "chair"
        "v5": {5: CLEAR}, "v6": {6: CLEAR},  # books on the shelf are not annotated: "book" is ambiguous in v5
    }
    scene = build(chairs + extra, views, vis)
    every_record = list(FAMILY.generate(scene, np.random.default_rng(3)))
    records = [r for r in every_record if not r.geometry["selection"]["cell"].endswith("|unbalanced")]
    assert all(r.answer in (0, 1, 2) for r in every_record) and len(every_record) > len(records)  # then the fill-ins
    got = Counter((r.geometry["label"], r.answer) for r in records)
    assert got == {("chair", 0): 1, ("chair", 1): 1, ("chair", 2): 1}  # one round; v3's second 2 has no 0/1 partner left
    assert len({r.question for r in records}) == 1  # one wording for the round
    for r in records:
        assert r.geometry["selection"]["cell"] == f"label:chair|template:{r.geometry['template']}"
        assert r.geometry["selection"]["roles"] == ["0", "1", "2+"]
        assert r.views[0] != "v4"
    every = {(r.views[0], r.geometry["label"]) for r in UNBALANCED.generate(scene, np.random.default_rng(0))}
    assert ("v4", "chair") not in every and ("v5", "book") not in every and ("v6", "book") in every


def test_module_hook_registers_family() -> None:
    got = []
    object_counting.spacedg_register_question_families(got.append)
    assert got == [FAMILY]


def test_counts_beyond_two_are_asked_and_binned() -> None:
    """A view showing four chairs is asked (bin "2+"), the 2+ bin takes the highest count first,
    and a view showing more than MAX_COUNT instances is not asked."""
    from tests.qa_scenes import CLEAR, build, camera, obj

    chairs = [obj(i, "chair", (2, 0.5 * i, 0.4), description=f"chair {i}") for i in range(1, 13)]
    views = {f"v{k}": camera((0, 0, 1.5), 10.0 * k) for k in range(6)}
    vis = {"v0": {}, "v1": {1: CLEAR}, "v2": {1: CLEAR, 2: CLEAR}, "v3": {i: CLEAR for i in range(1, 5)},
           "v4": {i: CLEAR for i in range(1, 13)}, "v5": {}}
    records = list(FAMILY.generate(build(chairs, views, vis), np.random.default_rng(0)))
    balanced = [r for r in records if not r.geometry["selection"]["cell"].endswith("|unbalanced")]
    assert Counter(object_counting.count_bin(r.answer) for r in balanced) == {"0": 1, "1": 1, "2+": 1}
    assert {r.answer for r in balanced if r.answer >= 2} == {4}  # the highest count of the bin first
    assert all(r.geometry["selection"]["role"] == object_counting.count_bin(r.answer) for r in records)
    assert 12 not in {r.answer for r in records} and 2 in {r.answer for r in records}  # 12 > MAX_COUNT


def test_count_bin() -> None:
    assert [object_counting.count_bin(n) for n in (0, 1, 2, 6, 10)] == ["0", "1", "2+", "2+", "2+"]


def test_a_room_with_a_wall_row_asks_to_count_six() -> None:
    """A generated room with a row of six along a wall (``row_probability=1``; seed 9 has one):
    views showing all six are asked, and the balanced family's ``2+`` bin asks the highest count first."""
    from spacedg.qa.build import prepare_scene
    from spacedg.scene.synthetic import CaptureConfig, RoomConfig, generate_room

    room = generate_room(9, RoomConfig(gaussians=20_000, capture=CaptureConfig(320, 240, 24, 32), row_probability=1.0))
    scene = prepare_scene(room, None, progress=False)
    every = list(UNBALANCED.generate(scene, np.random.default_rng(0)))
    assert max(r.answer for r in every) >= 6
    for r in every:  # every counted instance recognisable under the counting thresholds; nothing in the grey zone
        th = r.geometry["thresholds"]
        assert th["min_fraction"] == 0.25
        assert all(c["visible_pixels"] >= th["min_pixels"] and c["visible_fraction"] >= 0.25 for c in r.geometry["counted"])
        assert all(n["visible_pixels"] in (0, None) for n in r.geometry["not_counted"])
    balanced = [r for r in FAMILY.generate(scene, np.random.default_rng(0)) if not r.geometry["selection"]["cell"].endswith("|unbalanced")]
    assert max(r.answer for r in balanced) >= 6
