"""The fast paths of question generation give exactly what the plain code gives: deferred
geometry conversion, the list fast path of ``json_ready``, ``cross3`` and the memoised entries."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest

from spacedg.errors import InvalidDataError
from spacedg.plugins.qa_record import _json_ready_walk, deferred_geometry, json_ready
from spacedg.scene.box import OrientedBox, cross3
from tests.qa_records import qa_record as _record

GEOMETRY = {"up": (0.0, 0.0, 1.0), "m": [[1.0, 2], (3, 4.5)], "n": np.float64(2.5), "k": [np.int64(3), True, None, "a"]}


def test_deferred_geometry_is_converted_once_materialised() -> None:
    plain = _record(geometry=GEOMETRY)
    with deferred_geometry():
        raw = _record(geometry=GEOMETRY)
    assert raw.geometry is GEOMETRY  # kept as given inside the block
    done = raw.materialised()
    assert done == plain and done.to_json() == plain.to_json()
    assert plain.materialised() is plain and done.materialised() is done


def test_deferred_geometry_raises_on_materialising() -> None:
    with deferred_geometry():
        raw = _record(geometry={"bad": [1.0, math.nan]})
    with pytest.raises(InvalidDataError, match=r"geometry\.bad\[1\]"):
        raw.materialised()


@pytest.mark.parametrize("value", [
    [1.0, 2.0], (1, 2.5), (1e308, 1e308), [10**400, 1.0], [True, 1.0], [None, "a", 1], [], (),
    {"a": [1.0, [2.0, np.float64(3)]]}, [[1.0, 2.0], [3.0, 4.0]], {"a": {"b": (1, 2)}},
])
def test_json_ready_list_fast_path_equals_the_walk(value: object) -> None:
    fast, walk = json_ready(value), _json_ready_walk(value, "geometry")
    assert repr(fast) == repr(walk)


@pytest.mark.parametrize("value", [[math.nan, 1.0], [1.0, math.inf], [[1.0], [2.0, -math.inf]], {1: 2.0}])
def test_json_ready_list_fast_path_rejects_like_the_walk(value: object) -> None:
    with pytest.raises(InvalidDataError) as fast:
        json_ready(value)
    with pytest.raises(InvalidDataError) as walk:
        _json_ready_walk(value, "geometry")
    assert str(fast.value) == str(walk.value)


def test_cross3_is_np_cross_bit_for_bit() -> None:
    rng = np.random.default_rng(5)
    a = rng.normal(size=(500, 3)) * 10.0 ** rng.integers(-6, 6, size=(500, 1))
    b = rng.normal(size=(500, 3)) * 10.0 ** rng.integers(-6, 6, size=(500, 1))
    for x, y in zip(a, b):
        assert cross3(x, y).tobytes() == np.cross(x, y).tobytes()
    pose = np.eye(4)
    assert cross3(pose[:3, 2], np.array([0.0, 0.0, 1.0])).tobytes() == np.cross(pose[:3, 2], [0.0, 0.0, 1.0]).tobytes()
    assert np.array_equal(cross3(np.array([1, 0, 0]), np.array([0, 1, 0])), [0, 0, 1])  # ints: np.cross itself


def test_box_intersection_memo_is_per_box_object() -> None:
    from spacedg.plugins.questions.geometry import boxes_intersect

    a = OrientedBox(np.zeros(3), np.ones(3), np.eye(3))
    near = OrientedBox(np.array([0.5, 0.0, 0.0]), np.ones(3), np.eye(3))
    far = OrientedBox(np.array([5.0, 0.0, 0.0]), np.ones(3), np.eye(3))
    assert boxes_intersect(a, near) and boxes_intersect(a, near)
    assert not boxes_intersect(a, far) and not boxes_intersect(a, far)


def test_compass_questions_equal_compass_question() -> None:
    from spacedg.plugins.questions.compass_cache import CompassQuestions
    from spacedg.plugins.questions.records import compass_question

    gen = np.random.default_rng(11)
    up = np.array([0.1, -0.2, 0.97])
    refs, queries = gen.normal(size=(4, 3)), gen.normal(size=(5, 3))
    plain_rng, cached_rng = np.random.default_rng(2), np.random.default_rng(2)
    cache = CompassQuestions(up)
    for _ in range(3):  # every reference/query again: memoised frames and projections
        for i, ref in enumerate(refs):
            for j, query in enumerate(queries):
                plain = compass_question(ref, query, up, plain_rng)
                cached = cache.ask(i, ref.tolist(), j, query.tolist(), cached_rng)
                assert repr(cached) == repr(plain)
    assert plain_rng.random() == cached_rng.random()  # the same draws


def test_a_compass_angle_on_a_sector_boundary_is_not_asked() -> None:
    """30° clockwise of the reference lies on a sector boundary whichever cardinal is assumed
    (30, 120, 210, 300): ±30° and the 0.5774 ratio disagree there, so neither path asks it, and
    both draw only the assumed cardinal."""
    from spacedg.plugins.questions.compass_cache import CompassQuestions
    from spacedg.plugins.questions.records import compass_question

    up = np.array([0.0, 0.0, 1.0])
    ref = np.array([1.0, 0.0, 0.0])
    on_edge = np.array([math.cos(math.radians(30.0)), -math.sin(math.radians(30.0)), 0.0])
    beside = np.array([math.cos(math.radians(30.05)), -math.sin(math.radians(30.05)), 0.0])
    for seed in range(4):
        plain_rng, cached_rng = np.random.default_rng(seed), np.random.default_rng(seed)
        assert compass_question(ref, on_edge, up, plain_rng) is None
        assert CompassQuestions(up).ask(0, ref.tolist(), 1, on_edge.tolist(), cached_rng) is None
        assert plain_rng.random() == cached_rng.random() == _after_one_integer(seed)
        asked = compass_question(ref, beside, up, np.random.default_rng(seed))
        assert asked is not None and asked[3]["banned_labels"]  # 0.05° off: asked, the neighbour banned


def _after_one_integer(seed: int) -> float:
    rng = np.random.default_rng(seed)
    rng.integers(4)
    return rng.random()


def test_memoised_legs_angles_and_box_centre_answers_equal_the_plain_geometry() -> None:
    """The relative-position triplets (shared ``object_leg``s, memoised ground axes per anchor and
    facing object) and the box-centre answers (memoised per camera B and object) give exactly the
    numbers of the plain calls, for every triplet and camera of a random scene with a tilted up."""
    import itertools
    from collections import Counter

    from spacedg.plugins.questions import camera_object_relative_direction as rel
    from spacedg.plugins.questions.geometry import (
        BODY_DIRECTION_WORDS, RELPOS_SECTORS, dominant_parts, ground_angle, ground_leg, parts_label, point_in_camera,
    )
    from spacedg.plugins.questions.view_sampling import VisibilityIndex
    from tests.qa_scenes import build, camera, obj

    gen = np.random.default_rng(4)
    labels = ["chair", "table", "lamp", "sofa", "plant", "desk"]
    instances = [obj(i + 1, labels[i], gen.uniform(-3.0, 3.0, 3), gen.uniform(0.2, 0.6, 3), yaw_deg=float(gen.uniform(0, 90)))
                 for i in range(6)]
    views = {f"v{k}": camera(gen.uniform(-4.0, 4.0, 3), float(gen.uniform(0, 360)), float(gen.uniform(-20, 20))) for k in range(4)}
    scene = build(instances, views)
    scene.up = tuple((np.array([0.05, -0.1, 1.0]) / np.linalg.norm([0.05, -0.1, 1.0])).tolist())  # type: ignore[misc]
    index = VisibilityIndex(scene)
    up = np.asarray(scene.up, dtype=np.float64)
    asked = Counter()
    for _ in range(2):  # the second pass reads the memos
        for ids in itertools.permutations([inst.id for inst in instances], 3):
            shape = rel._relpos_shape(index, ids, up)
            a, b, c = (index.instance(i).box.center for i in ids)
            leg_ab, leg_ac = ground_leg(b - a, up), ground_leg(c - a, up)
            if shape is None:
                continue
            asked["triplets"] += 1
            assert shape[2] == (leg_ab, leg_ac)
            angle = ground_angle(np.asarray(leg_ab["horizontal"]), c - a, up)
            assert shape[3] == angle and shape[4] == RELPOS_SECTORS.classify(angle)
        for view, inst in itertools.product(views, instances):
            vec = point_in_camera(scene.views[view], inst.box.center)
            got = rel._bbox_answer(scene, index, view, inst)
            if np.linalg.norm(vec) < rel.MIN_DISPLACEMENT_M or rel._rare_bbox_direction(vec):
                assert got is None
            else:
                parts = dominant_parts(vec)
                asked["box centres"] += 1
                assert got is not None and got[0].tolist() == vec.tolist() and got[1:] == (parts, parts_label(parts, BODY_DIRECTION_WORDS))
    assert asked["triplets"] >= 20 and asked["box centres"] >= 10, asked  # the comparisons above did run


def test_with_changes_keeps_a_plain_geometry_and_checks_the_fields() -> None:
    plain = _record(geometry=GEOMETRY)
    changed = plain.with_changes(question="Another question?")
    assert changed.geometry is plain.geometry and changed.question == "Another question?"
    assert changed.to_dict() == {**plain.to_dict(), "question": "Another question?"}
    with pytest.raises(InvalidDataError, match="question"):
        plain.with_changes(question="  ")  # the fields are checked as by the constructor
    with deferred_geometry():
        raw = _record(geometry={"bad": [1.0, math.nan]})
    with pytest.raises(InvalidDataError, match=r"geometry\.bad\[1\]"):
        raw.with_changes(question="Q?")  # a geometry not yet converted is converted (and refused) as before
    assert plain.with_changes(geometry={"n": np.float64(1.5)}).geometry == {"n": 1.5}


def test_bbox_options_deal_each_truth_its_first_deck_as_before() -> None:
    from spacedg.plugins.questions.camera_object_relative_direction import BBOX_DECKS, bbox_options
    from spacedg.plugins.questions.geometry import build_mcq

    for seed, truth in enumerate(t for deck in BBOX_DECKS for t in deck):
        deck = next(d for d in BBOX_DECKS if truth in d)  # the plain rule
        expected = (*build_mcq(truth, [t for t in deck if t != truth], np.random.default_rng(seed)), deck)
        assert bbox_options(truth, np.random.default_rng(seed)) == expected
    with pytest.raises(ValueError, match="none of the decks"):
        bbox_options("Back", np.random.default_rng(0))


def test_draw_index_is_the_one_argument_draw() -> None:
    from spacedg.seeding import draw_index

    plain, fast = np.random.default_rng(46), np.random.default_rng(46)
    for k in range(3000):
        n = 1 + k % 29
        assert draw_index(fast, n) == int(plain.integers(n))
        if k % 3 == 0:  # interleaved with other draws (numpy's buffered 32-bit half stays in step)
            assert fast.random() == plain.random()
    assert fast.bit_generator.state == plain.bit_generator.state


class _PlainDecks:
    """The letter decks as written before the last-deck fast path: an LRU of (id(rng), options) → (rng, letters)."""

    def __init__(self, size: int) -> None:
        from collections import OrderedDict

        self.decks: OrderedDict[tuple[int, int], tuple[np.random.Generator, list[int]]] = OrderedDict()
        self.size = size

    def next(self, rng: np.random.Generator, n_options: int) -> int:
        key = (id(rng), n_options)
        entry = self.decks.get(key)
        if entry is None or entry[0] is not rng:
            entry = self.decks[key] = (rng, [])
            while len(self.decks) > self.size:
                self.decks.popitem(last=False)
        self.decks.move_to_end(key)
        if not entry[1]:
            entry[1].extend(int(i) for i in rng.permutation(n_options))
        return entry[1].pop()


def test_letter_decks_equal_the_plain_lru(monkeypatch: pytest.MonkeyPatch) -> None:
    from collections import OrderedDict

    from spacedg.plugins.questions import geometry

    monkeypatch.setattr(geometry, "_DECKS", OrderedDict())
    monkeypatch.setattr(geometry, "_MAX_DECKS", 8)
    plain = _PlainDecks(8)
    order = np.random.default_rng(4646)
    fast_rngs = [np.random.default_rng(seed) for seed in range(12)]  # more generators than decks: evictions
    plain_rngs = [np.random.default_rng(seed) for seed in range(12)]
    got, want = [], []
    for _ in range(3000):
        k, options, run = int(order.integers(12)), int(order.choice([3, 4])), int(order.integers(1, 6))
        for _ in range(run):  # runs of one generator and option count, as a family draws them
            got.append(geometry._next_letter(fast_rngs[k], options))
            want.append(plain.next(plain_rngs[k], options))
        if order.random() < 0.02:  # a generator replaced: a new object, perhaps at the old one's id
            fast_rngs[k], plain_rngs[k] = np.random.default_rng(100 + k), np.random.default_rng(100 + k)
    assert got == want
    assert [r.bit_generator.state for r in fast_rngs] == [r.bit_generator.state for r in plain_rngs]


def test_selection_entry_lists_are_fresh_strings() -> None:
    from spacedg.plugins.questions.records import selection_entry

    roles, features = ("no", "yes"), ("a:chair",)
    first = selection_entry("s", "c", "yes", roles, features=features)
    second = selection_entry("s", "c", "yes", roles, features=features)  # the tuples seen before: copied as they are
    assert first == second == {"subject": "s", "cell": "c", "role": "yes", "roles": ["no", "yes"], "features": ["a:chair"]}
    first["roles"].append("maybe")
    assert second["roles"] == ["no", "yes"] and roles == ("no", "yes")  # each entry has its own list
    class Label(str):
        def __str__(self) -> str:
            return "label:" + str.__str__(self)

    subclassed = selection_entry("s", "c", Label("x"), (Label("x"), "y"))  # a str subclass: str() as before
    assert subclassed["roles"] == ["label:x", "y"] and type(subclassed["roles"][0]) is str
    numeric = selection_entry("s", "c", 1, (1, 2))  # not strings: converted
    assert numeric["roles"] == ["1", "2"] and numeric["role"] == "1" and all(type(r) is str for r in numeric["roles"])


def test_visibility_tables_are_shared_only_inside_the_block() -> None:
    from spacedg.plugins.questions.view_sampling import VisibilityIndex, shared_visibility_tables
    from spacedg.scene.visibility_classes import VisibilityThresholds
    from tests.qa_scenes import build, camera, obj

    scene = build([obj(1, "chair", (0, 0, 2)), obj(2, "table", (1, 0, 3))], {"f0": camera((0, 0, 0)), "f1": camera((0.5, 0, 0))})
    other = build([obj(1, "chair", (0, 0, 2))], {"f0": camera((0, 0, 0))}, scene_id="other")
    apart = VisibilityIndex(scene)
    assert VisibilityIndex(scene).classes is not apart.classes  # outside the block: classified anew
    strict = VisibilityThresholds(min_fraction=0.99)
    with shared_visibility_tables():
        first, second = VisibilityIndex(scene), VisibilityIndex(scene)
        assert second.classes is first.classes and second.visible is first.visible  # one classification
        assert second.memos is not first.memos  # each index its own memos
        assert VisibilityIndex(scene, strict).classes is not first.classes  # other thresholds: their own
        assert VisibilityIndex(other).visible == {"f0": (1,)}  # another scene: its own
    assert VisibilityIndex(scene).classes is not first.classes  # the block is over: classified anew
    for index in (first, VisibilityIndex(scene, strict)):
        plain = VisibilityIndex(scene, index.thresholds)
        assert (index.classes, index.visible, index.seen) == (plain.classes, plain.visible, plain.seen)


def _stats_as_before(selection: object) -> dict[str, Counter[str]]:
    """``_Selection.stats`` written out independently (one comprehension, each record's round size from the
    rule itself: 1 outside cells, else its cell's roles or, for a cell left without roles, the record's own)."""
    pool, taken, judged_out, asked, room = (getattr(selection, k) for k in ("pool", "taken", "judged_out", "asked", "room"))
    subs = [r.sub_question_type for r in pool.records]

    def round_size(i: int) -> int:
        cell = pool.cell_keys[i]
        return 1 if cell is None else max(1, len(pool.cell_roles.get(cell) or pool.selections[i].get("roles", [])))

    counts = Counter(zip(subs, [
        "taken" if i in taken else "judge" if i in judged_out
        else "repeat" if subject is not None and subject in asked
        else "quota" if room[sub] < round_size(i) else "unbalanced"
        for i, (sub, subject) in enumerate(zip(subs, pool.subjects))
    ]))
    out: dict[str, Counter[str]] = {sub: Counter({"pooled": n}) for sub, n in Counter(subs).items()}
    for (sub, reason), n in counts.items():
        out[sub][reason] = n
    return out


@pytest.mark.parametrize("quota", [1, 2, 5])
def test_selection_stats_equal_the_plain_rule(quota: int) -> None:
    from spacedg.plugins.qa_record import QARecord
    from spacedg.plugins.questions.records import selection_entry
    from spacedg.plugins.specs import AnswerType, TaskGroup
    from spacedg.qa.selection import _Selection

    def record(k: int, sub: str, **entry: object) -> QARecord:
        return QARecord(
            id=f"r{k}", scene_id="s", question_type="fam", sub_question_type=sub, task_group=TaskGroup.OBJECT_CENTRIC,
            answer_type=AnswerType.YN, views=("a",), question=f"Q{k}?", answer="yes", geometry={"selection": selection_entry(**entry)},
        )

    rng = np.random.default_rng(12)
    records = []
    for k in range(60):
        kind = int(rng.integers(4))
        if kind == 0:  # metric (no cell)
            records.append(record(k, "m", subject=f"o{k % 7}"))
        elif kind == 1:  # a three-role cell, subjects repeating
            records.append(record(k, "c", subject=f"p{k % 9}", cell="three", role=str(rng.choice(["x", "y", "z"])), roles=("x", "y", "z")))
        elif kind == 2:  # rounds over the offered roles, of which this scene offers one: the cell's roles become []
            records.append(record(k, "c", subject=f"q{k}", cell="partial", role="x", roles=("x", "y"), all_roles=False))
        else:  # another sub type's two-role cell
            records.append(record(k, "d", subject=f"r{k % 11}", cell="two", role=str(rng.choice(["yes", "no"])), roles=("yes", "no")))
    selection = _Selection(records, quota, lambda r: r.id != "r5")  # one refusal of a judge
    selection.take_metric()
    selection.take_rounds()
    selection.take_small_quotas()
    assert selection.pool.cell_roles["fam|partial"] == []
    assert selection.stats() == _stats_as_before(selection)
    assert sum(sum(v for k, v in row.items() if k != "pooled") for row in selection.stats().values()) == len(records)
