"""Object-proxy cardinal direction (``question_type = "object_proxy_cardinal_direction"``; object-centric, 2 views, MCQ).

Sub type ``proxy_frame`` (SPEC-QA, type 7; paper appendix "Object-Object Cardinal Direction").
Three distinct objects A (defines the frame), B (the proxy origin) and C (the query): "The
direction of <A> relative to <B> is <assumed_dir>. What is the direction of <C> relative to <B>?"

Frame (exact definition; world metres, ``up = Scene.up``, box centres ``c_A, c_B, c_C``):

- origin = B's box centre; reference leg ``c_A − c_B``, query leg ``c_C − c_B``;
- the assumed direction ``d`` is drawn by ``rng`` from
  :data:`~spacedg.plugins.questions.geometry.CARDINALS`; **north** is the unit ground vector
  such that ``horizontal(c_A − c_B)`` lies ``angle(d)`` (0, 90, 180, 270°) clockwise from it
  seen from above; **east = north × up**
  (:func:`~spacedg.plugins.questions.geometry.compass_frame`). Example,
  z up: B at the origin, A at +x declared "west" → north = −y, east = −x, and C at +y is "south";
- ``angle = ground_angle(north, c_C − c_B, up)`` ∈ [0, 360) clockwise from north; the truth is
  ``COMPASS_SECTORS.classify(angle)`` (cardinals ±30° around their axis, diagonals the 30°
  between: the 0.5774 rule). Options: the truth and three of the other seven labels from
  ``COMPASS_SECTORS.distractors`` (seeded; within 3° of a sector boundary the label across it is
  never offered), letters by :func:`~spacedg.plugins.questions.geometry.build_mcq`; not asked
  within :data:`~spacedg.plugins.questions.geometry.COMPASS_RULE_BAND_DEG` (0.01°) of a boundary,
  where the ±30° and the 0.5774 readings disagree.

Skipped (the paper's "geometric ambiguity filters"): any two of the three boxes intersect
(:func:`~spacedg.plugins.questions.geometry.boxes_intersect`, tolerance
:data:`~spacedg.plugins.questions.geometry.INTERSECT_TOL_M` = 1 mm: boxes must overlap by more
than 1 mm along every separating axis; touching boxes, e.g. a vase standing on a table, are
kept. Decision: with ``tol = 0`` float noise decides touching boxes, and the answer set changed
under a rigid motion of the scene; ``camera_object_relative_direction`` uses the same
tolerance); ``|horizontal(c_A − c_B)|`` or ``|horizontal(c_C − c_B)|`` below 0.25 m; either leg
vertical-dominant (vertical ≥ 1.2 × horizontal; this is also the paper's "forward nearly
collinear with up" rule; both by :func:`~spacedg.plugins.questions.geometry.ground_leg`).

Objects (decisions in brackets): pairs of views from
:func:`~spacedg.plugins.questions.view_sampling.sample_pairs` with
:data:`~spacedg.plugins.questions.view_sampling.OBJECT_PAIRS` (covisibility > 0.25, baseline ≥ 0.2 m). The
triplet obeys the three-object rule (:func:`~spacedg.plugins.questions.view_sampling.split_across_views`:
each clearly visible in image A or B, neither image shows all three). Each object is named in
[image A if it is clearly visible there without a description clash
(:func:`~spacedg.plugins.questions.records.referable`), else image B on the same condition];
an object usable in neither makes the triplet invalid. Because neither image shows all three,
the markers always point into both images. [The three phrases
(:func:`~spacedg.plugins.questions.language.object_phrase`) must differ case-insensitively; the
question names the objects by these phrases, the same words as the markers.]

Question: one marker per object in role order A, B, C (each pointing at its image), then the
paper's sentence (**deviation**: with "the" before each object, which the paper's template
leaves out and which reads badly with descriptions)::

    In image A, find the red lamp. In image A, find the wooden table. In image B, find the blue sofa.
    The direction of the red lamp relative to the wooden table is west. What is the direction of the blue sofa relative to the wooden table?

Order and bounded enumeration: pairs in ``sample_pairs`` order, visited round-robin (one record
per pair per round; the family is made by :func:`~spacedg.plugins.questions.pairs.pair_family`).
A pair's candidates are the ordered triplets of distinct usable objects, ``n(n−1)(n−2)`` of
them, walked in a seeded random order drawn **lazily**
(:func:`~spacedg.plugins.questions.records.lazy_permutation`: memory and time grow with what
is taken, not with ``n³``); pairs where no triplet can satisfy the
three-object rule (every usable object seen in one of the images) are dropped before any draw.
Cheap tests run first (three-object rule, phrases, leg lengths), box intersections last and
cached per pair. For each accepted triplet ``rng`` draws the assumed direction, then the
distractor order and the letter (:func:`~spacedg.plugins.questions.records.compass_question`).
Same seed, same records in the same order.

Geometry block (JSON): ``up``; ``cameras`` (view → 4×4 ``cam_to_world``); ``objects`` (A, B, C:
id, label, description, box ``center``/``extents``/``rotation``); ``refs`` (``[{"id", "label",
"description", "view"}]`` in question order A, B, C); ``visibility``; ``visibility_thresholds``
(these six from :func:`~spacedg.plugins.questions.records.objects_block`); ``roles``
(``{"A", "B", "C"}`` → ids); ``reference`` (leg B→A) and ``query`` (leg B→C), each
``origin`` (c_B), ``vector``, ``horizontal``, ``horizontal_m``, ``vertical_m``; ``assumed_dir``;
``assumed_angle_deg``; ``north``; ``east``; ``angle_deg``; ``sector_index``; ``sector_label``;
``sector_labels``; ``sector_starts_deg``; ``boundary_distance_deg``; ``neighbour_index``;
``banned_labels``; ``thresholds``; ``intersect_tol_m``; ``template`` (always 0); ``pair``;
``pair_rules``; ``selection`` (cell = the assumed direction, roles = the eight compass labels,
balanced per assumed direction by the question index; subject = the ordered triplet).
"""

from __future__ import annotations

import functools
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from spacedg.plugins.candidates import PASSED_OVER, Candidate, admission, offer
from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Instance, Scene
from spacedg.plugins.questions.view_sampling import (
    PairRules,
    ViewPair,
    VisibilityIndex,
)
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.questions.geometry import (
    COMPASS_SECTORS,
    INTERSECT_TOL_M,
    boxes_intersect,
)
from spacedg.plugins.questions.language import find_in_image
from spacedg.plugins.questions.pairs import pair_family
from spacedg.plugins.questions.compass_cache import compass_questions
from spacedg.plugins.questions.records import (
    index_memo,
    compass_distractors,
    lazy_permutation,
    make_record,
    object_leg,
    objects_block,
    phrase,
    phrase_key,
    referable_ids,
    selection_entry,
)
from spacedg.plugins.specs import AnswerType, TaskGroup

__all__ = ["FAMILY", "NAME", "SUB_QUESTION_TYPE", "TEMPLATE", "decode_triplet", "make_family", "render_question"]

NAME = "object_proxy_cardinal_direction"
SUB_QUESTION_TYPE = "proxy_frame"
#: The paper's wording after the markers, with "the" before each object; ``{a}``, ``{b}``, ``{c}``:
#: phrases; ``{assumed}``: a cardinal.
TEMPLATE = "The direction of the {a} relative to the {b} is {assumed}. What is the direction of the {c} relative to the {b}?"


def decode_triplet(k: int, n: int) -> tuple[int, int, int]:
    """The ``k``-th ordered triplet of distinct indices in ``range(n)`` (``0 <= k < n(n−1)(n−2)``)."""
    x, rest = divmod(k, (n - 1) * (n - 2))
    y, z = divmod(rest, n - 2)
    if y >= x:
        y += 1
    for skip in sorted((x, y)):
        if z >= skip:
            z += 1
    return x, y, z


def render_question(phrases: tuple[str, str, str], images: tuple[int, int, int], assumed_dir: str) -> str:
    """One marker per object (A, B, C; ``images`` are 0 for image A, 1 for image B), then the paper's question."""
    markers = " ".join(find_in_image(p, i) for p, i in zip(phrases, images))
    return markers + "\n" + TEMPLATE.format(a=phrases[0], b=phrases[1], c=phrases[2], assumed=assumed_dir)


def _pair_stream(scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, rng: np.random.Generator) -> Iterator[QARecord | Candidate]:
    up = np.asarray(scene.up, dtype=np.float64)
    views = (pair.a, pair.b)
    ref_view: dict[int, str] = {}
    for view in views:
        for iid in referable_ids(index, view):
            ref_view.setdefault(iid, view)  # image A first, else image B
    ids = sorted(ref_view)
    n = len(ids)
    seen_a, seen_b = index.seen_set(pair.a), index.seen_set(pair.b)
    only_b = [i not in seen_a for i in ids]  # must come from image B: not seen in A
    only_a = [i not in seen_b for i in ids]
    if n < 3 or not any(only_a) or not any(only_b):
        return  # no triplet can be split across the two views
    insts = [index.instance(i) for i in ids]
    keys = [phrase_key(inst) for inst in insts]
    centres = [inst.box.center for inst in insts]
    # memoised per scene (the index), by instance ids: a leg between two objects (object_leg), whether two
    # boxes overlap and the compass frames do not depend on the views
    hits: dict[tuple[int, int], bool] = index_memo(index, "box_overlaps")
    compass = compass_questions(index, up)
    admit = admission()

    def overlap(p: int, q: int) -> bool:
        key = (min(ids[p], ids[q]), max(ids[p], ids[q]))
        if key not in hits:
            hits[key] = boxes_intersect(insts[p].box, insts[q].box)
        return hits[key]

    for k in lazy_permutation(n * (n - 1) * (n - 2), rng):
        x, y, z = decode_triplet(k, n)
        # the three-object rule (split_across_views) for these ids: each is referable in A or B, so
        # clearly visible in one of them; neither view may show all three (one must be only in A, one only in B)
        if not (only_a[x] or only_a[y] or only_a[z]) or not (only_b[x] or only_b[y] or only_b[z]):
            continue
        if keys[x] == keys[y] or keys[x] == keys[z] or keys[y] == keys[z]:
            continue  # two objects with the same phrase
        ref, query = object_leg(index, ids[x], ids[y], up), object_leg(index, ids[z], ids[y], up)
        if ref is None or query is None:
            continue
        if overlap(x, y) or overlap(x, z) or overlap(y, z):
            continue
        triplet_ids = (ids[x], ids[y], ids[z])
        subject = _triplet_subject(*triplet_ids)
        if not admit(SUB_QUESTION_TYPE, views, subject, triplet_ids):
            yield PASSED_OVER  # the caller passes it over: no draws
            continue
        objs = (insts[x], insts[y], insts[z])
        drawn = compass.ask(("objects", ids[x], ids[y]), ref["vector"], ("objects", ids[z], ids[y]), query["vector"], rng)  # = compass_question(ref, query, up, rng)
        if drawn is None:
            continue  # on a sector boundary: the label depends on the reading of the rule
        obj_views = tuple(ref_view[i] for i in triplet_ids)
        yield offer(
            SUB_QUESTION_TYPE, views, subject, triplet_ids, functools.partial(_selection, objs, drawn),
            functools.partial(_record, scene, index, pair, rules, objs, obj_views, centres[y].tolist(), (ref, query), drawn),
        )


def _subject(objs: Sequence[Instance]) -> str:
    """The selection subject: the ordered triplet (A, B, C)."""
    a, b, c = (o.id for o in objs)
    return _triplet_subject(a, b, c)


def _triplet_subject(a: int, b: int, c: int) -> str:
    """:func:`_subject` from the three instance ids."""
    return f"objects:{a}|{b}|{c}"


def _selection(objs: Sequence[Instance], drawn: tuple[str, tuple[str, ...], str, dict[str, Any]]) -> dict[str, Any]:
    """The selection entry (module docstring) of the question about ``objs`` that ``drawn`` describes."""
    assumed, compass = drawn[0], drawn[3]
    return selection_entry(
        _subject(objs), f"assumed:{assumed}", compass["sector_label"], COMPASS_SECTORS.labels, distractors=compass_distractors(compass),
    )


def _record(
    scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, objs: tuple[Instance, ...], obj_views: tuple[str, ...],
    origin: list[float], legs: tuple[dict[str, Any], dict[str, Any]], drawn: tuple[str, tuple[str, ...], str, dict[str, Any]],
) -> QARecord:
    """The record of one triplet ``objs`` (A, B, C) found in ``obj_views``: B's centre ``origin``,
    the ``legs`` B → A and B → C, and what :func:`~spacedg.plugins.questions.records.compass_question` drew."""
    views = (pair.a, pair.b)
    (ref, query), (assumed, options, letter, compass) = legs, drawn
    phrases = tuple(phrase(o) for o in objs)
    geometry = {
        **objects_block(scene, index, views, list(objs), zip(objs, obj_views)),
        "roles": {"A": objs[0].id, "B": objs[1].id, "C": objs[2].id},
        "reference": {"origin": origin, **ref},
        "query": {"origin": list(origin), **query},
        **compass,
        "template": 0,
        "intersect_tol_m": INTERSECT_TOL_M,
        "pair": pair.to_dict(),
        "pair_rules": rules.to_dict(),
        "selection": _selection(objs, drawn),
    }
    return make_record(
        scene, NAME, SUB_QUESTION_TYPE, TaskGroup.OBJECT_CENTRIC, AnswerType.MCQ, views,
        {"roles": [o.id for o in objs], "assumed_dir": assumed},
        question=render_question(phrases, tuple(views.index(v) for v in obj_views), assumed),  # type: ignore[arg-type]
        answer=letter, geometry=geometry, options=options,
    )


#: ``make_family(thresholds, pair_rules)``: this family with other visibility thresholds / pair rules
#: (:func:`~spacedg.plugins.questions.pairs.pair_family`); :data:`FAMILY`, the registered one, uses the defaults.
make_family = pair_family(
    _pair_stream, name=NAME, task_group=TaskGroup.OBJECT_CENTRIC, answer_types={AnswerType.MCQ}, sub_question_types=(SUB_QUESTION_TYPE,),
    plain_rounds=True, description="Given the compass direction of object A from object B, the compass direction of object C from B.",
)
FAMILY = make_family()
spacedg_register_question_families = registering(FAMILY)
