"""Camera–object relative direction (``question_type = "camera_object_relative_direction"``; camera-object, MCQ).

Three sub types (SPEC-QA, type 4; wording from the paper's appendix "Question Templates"):

``single_view`` (1 view)
    "What is the relative position of <B> with respect to <A> in this view?" (the paper's four
    templates, :data:`SINGLE_VIEW_TEMPLATES`, drawn by ``rng``). Both objects are clearly
    visible in the view and named by :func:`~spacedg.plugins.questions.language.object_phrase`.
    The displacement ``v = R^T (c_B - c_A)`` (box centres, metres) is taken in that camera's
    OpenCV frame (x right, y down, z forward) and labelled by
    :func:`~spacedg.plugins.questions.geometry.dominant_parts` (largest |component| first; a
    second part only when ``|c2| >= 0.5774 |c1|``; at most 2 parts) with
    :data:`~spacedg.plugins.questions.geometry.BODY_DIRECTION_WORDS` (Right/Left, Down/Up,
    Front/Back), e.g. ``"Right-Up"``. **Decision**: "Front" = farther from the camera along
    its optical axis, "Back" = nearer; since "B is in front of A" is ambiguous in English, the
    question ends with :data:`SINGLE_VIEW_NOTE` saying so. Skipped when ``|v| <`` 
    :data:`MIN_DISPLACEMENT_M` = 0.1 m (decision: below that the centres practically coincide
    and the direction is noise).
``bbox_center_direction`` (2 views, :data:`~spacedg.plugins.questions.view_sampling.LOW_COVIS_DIRECTION_PAIRS`:
    covisibility in (0.05, 0.25], baseline >= 0.2 m, rotation >= 15°)
    The object is clearly visible in image A (whether B shows it is not constrained: the low
    covisibility makes it often out of view). Its centre in camera B's frame,
    ``R_b^T (c - t_b)``, is labelled as above ("Front" = ahead of the camera). Skipped when the
    centre is closer than 0.1 m to camera B or camera B is inside the box. The question is
    ``find_in_image(phrase, 0)`` followed by one of the paper's two wordings
    (:data:`TWO_VIEW_TEMPLATES`, drawn by ``rng``), which name the object by its label.
``relpos_A_facing_B`` (2 views, :data:`~spacedg.plugins.questions.view_sampling.OBJECT_DIRECTION_PAIRS`:
    covisibility > 0.25, baseline >= 0.2 m, rotation >= 15°)
    (the public evaluator's name, capitals included).
    Three distinct instances A (where you stand), B (what you face), C (the query) obey the
    three-object rule (:func:`~spacedg.plugins.questions.view_sampling.split_across_views`: each clearly
    visible in image A or B, neither image shows all three). Each object is found in image A if
    it is clearly visible there without a description clash, else in image B on the same
    condition, else the triplet is skipped. With ``up = Scene.up``: ``forward = horizontal(c_B -
    c_A)`` (flattened on the ground plane); skipped when ``|forward| <`` 0.25 m or when the
    A→B vector is vertical-dominant (vertical >= 1.2 × horizontal; decision: the paper's
    "forward nearly collinear with up" rule, with the same factor as for C). ``angle =
    ground_angle(forward, c_C - c_A, up)`` (degrees clockwise from forward seen from above,
    90 = right, right = forward × up); skipped when C − A is vertical-dominant or its
    horizontal length < 0.25 m (both legs by :func:`~spacedg.plugins.questions.geometry.ground_leg`);
    triplets with any two intersecting boxes
    (:func:`~spacedg.plugins.questions.geometry.boxes_intersect`: tolerance
    :data:`~spacedg.plugins.questions.geometry.INTERSECT_TOL_M` = 1 mm, the same as
    ``object_proxy_cardinal_direction``; decision, so that boxes that merely touch, e.g. a lamp
    on a table, count as apart whatever the float noise) are skipped. The truth is
    ``RELPOS_SECTORS.classify(angle)`` (eight 45° sectors centred on front, front-right, …);
    distractors come from ``RELPOS_SECTORS.distractors`` (the neighbour across a boundary
    within 3° is never offered). The question is one ``find_in_image`` marker per object (A, B,
    C in that order, each pointing at its image) and then "You are positioned at the <A> and
    face the <B>. In which direction is the <C> relative to you?". **Decision**: the objects
    are named by their labels when the three labels differ, by their phrases otherwise; a
    triplet whose names still coincide is skipped.

Every referenced object is clearly visible in the view the question points to and has no
description clash there (:func:`~spacedg.plugins.questions.view_sampling.description_clash`; together
:func:`~spacedg.plugins.questions.records.referable`). Only camera
frames and ``Scene.up`` enter the answers, so questions, options and answers are unchanged when
the whole scene moves rigidly (any up direction).

Options: :func:`~spacedg.plugins.questions.geometry.build_mcq` (truth never among the
distractors; seeded shuffle). ``single_view`` labels take :func:`flipped_labels` first (1 for a
one-part label, 3 for a two-part one); a one-part label is padded with **both** words of one
other axis (chosen by ``rng``), as ``camera_translation``'s ``main_dir``: the four options are
then both signs of two axes, and they never tell which axis is the truth's (padding with
words of two different axes left the truth's axis the only one shown with both signs, a
blind 42 %).

``bbox_center_direction`` does not ask an object whose label would name "Back" or "Up" (rare:
behind camera B, or above a camera at eye height; a blind model learns to avoid them), nor one
whose parts are Up/Down × Front/Back. Its **options are answerable** (decision, debiasing: an
option that is never the truth is one a blind model eliminates): the twelve labels it can
answer fall into three fixed decks of four (:data:`BBOX_DECKS`: the one-part labels Front,
Down, Left, Right; the two-part labels led by Right/Left; those led by Front/Down), and a
question offers exactly the deck of its truth, so every option it shows is the truth of some
question, and the deck tells nothing of which one (the question index takes whole rounds of
its four roles). Two-part labels that differ only in order ("Right-Front", "Front-Right") are
never offered together.

Debiasing (the ``selection`` entry): the camera-frame sub types' **cell** is the sub type, the
template (``single_view``'s four wordings) and the option set (what the text tells: which
axes), ``relpos_A_facing_B``'s is the sub type with the eight
sector labels as roles; the question index takes whole rounds (one record per role) per cell,
every role of the cell in each round, so every option a question shows is the truth of another
question of the same scene (``single_view`` did rounds over the roles a scene offers before
index version 5, which left rare options such as "Back-Up" shown but never right).
Subjects: the view and the unordered object pair (``single_view``: "B relative to A" and "A
relative to B" are one question), camera B's view and the object (``bbox_center_direction``),
the ordered triplet (``relpos_A_facing_B``).

Geometry block (JSON): ``up``; ``cameras`` (view → 4×4 ``cam_to_world``); ``objects`` (id,
label, description, box centre/extents/rotation); ``refs`` (``[{"id", "label", "description",
"view"}]`` in question order); ``visibility``; ``visibility_thresholds``; ``template``;
``thresholds``; for the camera-frame sub types ``frame_view``, ``vector_world``,
``vector_camera``, ``norm_m``, ``parts`` (``[[axis, sign], …]``), ``label``, ``ratio``,
``max_parts``; for ``relpos_A_facing_B`` ``roles``, ``forward``, ``right``, the horizontal and
vertical lengths of A→B and A→C, ``angle_deg``, ``sector_index``, ``sector_label``,
``sector_starts_deg``, ``boundary_distance_deg``, ``neighbour_index``, ``banned_labels``; for
two views ``pair`` and ``pair_rules``; ``selection``.

Order (decision, as in ``camera_object_distance_estimation``): one child generator per sub type,
sub types interleaved round-robin; views (single view) or the pairs of ``sample_pairs``
visited round-robin, each group's candidates in a seeded order; lazy throughout. The
record-building helpers come from :mod:`~spacedg.plugins.questions.records`.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from spacedg.plugins.candidates import PASSED_OVER, Candidate, admission, offer
from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Instance, Scene
from spacedg.plugins.questions.view_sampling import (
    LOW_COVIS_DIRECTION_PAIRS,
    OBJECT_DIRECTION_PAIRS,
    PairRules,
    ViewPair,
    VisibilityIndex,
    label_key,
)
from spacedg.scene.visibility_classes import DEFAULT_THRESHOLDS, VisibilityThresholds
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.questions.geometry import (
    BODY_DIRECTION_WORDS,
    BOUNDARY_GUARD_DEG,
    INTERSECT_TOL_M,
    MAX_PARTS,
    MIN_HORIZONTAL_M,
    RELPOS_SECTORS,
    SectorHit,
    TAN30,
    VERTICAL_FACTOR,
    boxes_intersect,
    build_mcq,
    dominant_parts,
    flipped_labels,
    angle_on_ground,
    ground_axes,
    parts_label,
    point_in_camera,
    single_word_pool,
    vector_length,
)
from spacedg.plugins.questions.language import find_in_image, label_text
from spacedg.plugins.questions.records import (
    camera_inside,
    index_memo,
    label_features,
    make_record,
    object_leg,
    objects_block,
    phrase,
    phrase_key,
    referable,
    referable_ids,
    round_robin_sub_types,
    seeded_order,
    selection_entry,
    view_centre,
)
from spacedg.plugins.questions.pairs import view_and_pair_family
from spacedg.plugins.specs import AnswerType, TaskGroup
from spacedg.seeding import draw_index

__all__ = [
    "BBOX_CENTER_DIRECTION",
    "BBOX_DECKS",
    "bbox_options",
    "FAMILY",
    "MIN_DISPLACEMENT_M",
    "NAME",
    "RELPOS",
    "RELPOS_TEMPLATE",
    "SINGLE_VIEW",
    "SINGLE_VIEW_NOTE",
    "SINGLE_VIEW_TEMPLATES",
    "SUB_QUESTION_TYPES",
    "TWO_VIEW_TEMPLATES",
    "body_direction",
    "generate",
    "make_family",
]

NAME = "camera_object_relative_direction"
SINGLE_VIEW = "single_view"
BBOX_CENTER_DIRECTION = "bbox_center_direction"
RELPOS = "relpos_A_facing_B"
SUB_QUESTION_TYPES: tuple[str, ...] = (SINGLE_VIEW, BBOX_CENTER_DIRECTION, RELPOS)

#: Camera-frame vectors shorter than this (metres) have no meaningful direction: skipped.
MIN_DISPLACEMENT_M = 0.1

#: ``{b}``: the object asked about, ``{a}``: the reference object (paper order).
SINGLE_VIEW_TEMPLATES: tuple[str, ...] = (
    "What is the relative position of the {b} with respect to the {a} in this view?",
    "Where is the {b} located relative to the {a}?",
    "Describe the spatial relationship between the {b} and the {a}.",
    "In which direction is the {b} compared to the {a}?",
)
#: Appended to single-view questions: what Front/Back mean in the camera frame.
SINGLE_VIEW_NOTE = " Directions are as seen from the camera; Front means farther from the camera, Back nearer to it."
#: ``{label}``: the label as written (paper wording, after the image-A marker).
TWO_VIEW_TEMPLATES: tuple[str, ...] = (
    "Which direction is the \"{label}\" relative to you when taking image B?",
    "When you were taking the photo in Image B, where is the {label} area relative to you?",
)
#: ``bbox_center_direction``'s option decks: every label it can answer, in exactly one deck of
#: four (one-part labels; two-part labels led by Right/Left; two-part labels led by Front/Down).
BBOX_DECKS: tuple[tuple[str, ...], ...] = (
    ("Front", "Down", "Left", "Right"),
    ("Right-Front", "Left-Front", "Right-Down", "Left-Down"),
    ("Front-Right", "Front-Left", "Down-Right", "Down-Left"),
)
RELPOS_TEMPLATE = "You are positioned at the {a} and face the {b}. In which direction is the {c} relative to you?"
#: truth → (its deck, the deck's other labels in deck order) (:func:`bbox_options`).
_BBOX_DECK_OF: dict[str, tuple[tuple[str, ...], list[str]]] = {
    t: (d, [o for o in d if o != t]) for d in reversed(BBOX_DECKS) for t in d  # reversed: the first deck holding a label wins
}


# ------------------------------------------------------- camera-frame labels
def body_direction(vector_camera: np.ndarray, rng: np.random.Generator) -> tuple[list[tuple[int, int]], str, tuple[str, ...], str]:
    """``(parts, truth, options, letter)`` of a camera-frame vector (see the module docstring)."""
    parts = dominant_parts(vector_camera)
    truth = parts_label(parts, BODY_DIRECTION_WORDS)
    distractors = flipped_labels(parts, BODY_DIRECTION_WORDS)
    if len(parts) == 1:
        others = [axis for axis in range(3) if axis != parts[0][0]]
        pad_axis = others[draw_index(rng, len(others))]
        distractors += single_word_pool(BODY_DIRECTION_WORDS, exclude_axes=[a for a in range(3) if a != pad_axis])
    options, letter = build_mcq(truth, distractors, rng)
    return parts, truth, options, letter


def bbox_options(truth: str, rng: np.random.Generator) -> tuple[tuple[str, ...], str, tuple[str, ...]]:
    """``(options, letter, deck)`` of a ``bbox_center_direction`` truth: its :data:`BBOX_DECKS`
    deck, shuffled by :func:`~spacedg.plugins.questions.geometry.build_mcq`; ``ValueError`` for a label in no deck."""
    if truth not in _BBOX_DECK_OF:
        raise ValueError(f"bbox_options: {truth!r} is in none of the decks {BBOX_DECKS}")
    deck, others = _BBOX_DECK_OF[truth]
    options, letter = build_mcq(truth, others, rng)
    return options, letter, deck


def _option_selection(subject: str, sub: str, template: int | None, truth: str, options: tuple[str, ...]) -> dict[str, Any]:
    """Selection entry whose cell is the sub type, template (if given) and option set (the roles are its four texts)."""
    cell, texts = _option_cell(sub, template, options)
    return selection_entry(subject, cell, truth, texts)


@functools.lru_cache(maxsize=4096)
def _option_cell(sub: str, template: int | None, options: tuple[str, ...]) -> tuple[str, tuple[str, ...]]:
    """The cell and roles of :func:`_option_selection` (a few dozen option sets recur in every candidate)."""
    texts = tuple(sorted(o[3:] for o in options))
    head = sub if template is None else f"{sub}|template:{template}"
    return f"{head}|options:" + "|".join(texts), texts


def _body_geometry(view: str, world: np.ndarray, cam: np.ndarray, parts: list[tuple[int, int]], truth: str) -> dict[str, Any]:
    return {
        "frame_view": view,
        "vector_world": world.tolist(),
        "vector_camera": cam.tolist(),
        "norm_m": float(np.linalg.norm(cam)),
        "parts": [[axis, sign] for axis, sign in parts],
        "label": truth,
        "ratio": TAN30,
        "max_parts": MAX_PARTS,
    }


def _record(
    scene: Scene, index: VisibilityIndex, sub: str, views: tuple[str, ...], objects: Sequence[Instance],
    refs: Sequence[tuple[Instance, str]], question: str, options: tuple[str, ...], letter: str, template: int,
    extra: dict[str, Any],
) -> QARecord:
    geometry = {**objects_block(scene, index, views, objects, refs), "template": template, **extra}
    return make_record(
        scene, NAME, sub, TaskGroup.CAMERA_OBJECT, AnswerType.MCQ, views, {"objects": [inst.id for inst in objects], "template": template},
        question=question, answer=letter, geometry=geometry, options=options,
    )


# --------------------------------------------------------------- single view
def _single_view_stream(scene: Scene, index: VisibilityIndex, view: str, rng: np.random.Generator) -> Iterator[QARecord | Candidate]:
    world_to_cam = np.asarray(scene.views[view].cam_to_world, dtype=np.float64)[:3, :3].T  # R^T, read once per view
    admit = admission()
    for ia, ib in seeded_order(list(itertools.permutations(referable_ids(index, view), 2)), rng):
        a, b = index.instance(ia), index.instance(ib)
        if phrase_key(a) == phrase_key(b):
            continue
        world = b.box.center - a.box.center
        vec = world_to_cam @ world
        if vector_length(vec) < MIN_DISPLACEMENT_M:
            continue
        subject = f"view:{view}|objects:{min(ia, ib)}|{max(ia, ib)}"
        if not admit(SINGLE_VIEW, (view,), subject, (ia, ib)):
            yield PASSED_OVER  # the caller passes it over: no draws
            continue
        template = draw_index(rng, len(SINGLE_VIEW_TEMPLATES))
        parts, truth, options, letter = body_direction(vec, rng)
        yield offer(
            SINGLE_VIEW, (view,), subject, (ia, ib), functools.partial(_option_selection, subject, SINGLE_VIEW, template, truth, options),
            functools.partial(_single_view_record, scene, index, view, (a, b), subject, (world, vec), template, (parts, truth, options, letter)),
        )


def _single_view_record(
    scene: Scene, index: VisibilityIndex, view: str, objs: tuple[Instance, Instance], subject: str,
    vectors: tuple[np.ndarray, np.ndarray], template: int, drawn: tuple[list[tuple[int, int]], str, tuple[str, ...], str],
) -> QARecord:
    """The record of a single-view question about ``objs`` (A, B): ``vectors`` = A → B in world and
    camera axes, ``drawn`` = what :func:`~spacedg.plugins.questions.geometry.body_direction` drew."""
    (a, b), (world, vec), (parts, truth, options, letter) = objs, vectors, drawn
    question = SINGLE_VIEW_TEMPLATES[template].format(a=phrase(a), b=phrase(b)) + SINGLE_VIEW_NOTE
    extra = {
        **_body_geometry(view, world, vec, parts, truth), "thresholds": {"min_displacement_m": MIN_DISPLACEMENT_M},
        "selection": _option_selection(subject, SINGLE_VIEW, template, truth, options),
    }
    return _record(scene, index, SINGLE_VIEW, (view,), (a, b), ((a, view), (b, view)), question, options, letter, template, extra)


# ------------------------------------------------------------ bbox direction
def _bbox_stream(scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, rng: np.random.Generator) -> Iterator[QARecord | Candidate]:
    centre_b = view_centre(index, pair.b)
    admit = admission()
    for iid in seeded_order(index.visible[pair.a], rng):
        inst = index.instance(iid)
        if not referable(index, pair.a, iid) or camera_inside(index, pair.b, inst):
            continue
        answer = _bbox_answer(scene, index, pair.b, inst)
        if answer is None:
            continue
        vec, parts, truth = answer
        subject = f"view:{pair.b}|object:{iid}"
        if not admit(BBOX_CENTER_DIRECTION, (pair.a, pair.b), subject, (iid,)):
            yield PASSED_OVER  # the caller passes it over: no draws
            continue
        template = draw_index(rng, len(TWO_VIEW_TEMPLATES))
        drawn = bbox_options(truth, rng)
        yield offer(
            BBOX_CENTER_DIRECTION, (pair.a, pair.b), subject, (iid,), functools.partial(_bbox_selection, pair, inst, truth, drawn[2]),
            functools.partial(_bbox_record, scene, index, pair, rules, inst, (centre_b, vec), template, (parts, truth), drawn),
        )


def _bbox_answer(scene: Scene, index: VisibilityIndex, view_b: str, inst: Instance) -> tuple[np.ndarray, list[tuple[int, int]], str] | None:
    """``(vector, parts, label)`` of ``inst``'s box centre in camera ``view_b``'s axes, or ``None`` when
    it is not asked (closer than :data:`MIN_DISPLACEMENT_M`, or :func:`_rare_bbox_direction`): memoised
    per (camera B, object) on the index, as they recur with every view A."""
    memo = index_memo(index, "bbox_answers")
    key = (view_b, inst.id)
    if key not in memo:
        vec = point_in_camera(scene.views[view_b], inst.box.center)
        parts = None if vector_length(vec) < MIN_DISPLACEMENT_M else dominant_parts(vec)
        label = parts_label(parts, BODY_DIRECTION_WORDS) if parts is not None else ""
        memo[key] = None if parts is None or _rare_bbox_parts(parts, label) else (vec, parts, label)
    return memo[key]


def _bbox_selection(pair: ViewPair, inst: Instance, truth: str, deck: tuple[str, ...]) -> dict[str, Any]:
    """The selection entry of a box-centre question: cell = the option deck, role = the truth, feature =
    the object's label (a chair is usually below a camera at eye height: the selection gives each label
    every direction of a deck alike, so a per-label prior learns nothing)."""
    cell, roles = _bbox_cell(deck)
    return selection_entry(f"view:{pair.b}|object:{inst.id}", cell, truth, roles, features=_object_features(inst.label))


@functools.lru_cache(maxsize=64)
def _bbox_cell(deck: tuple[str, ...]) -> tuple[str, tuple[str, ...]]:
    """The cell and roles of a box-centre deck (:func:`_bbox_selection`)."""
    roles = tuple(sorted(deck))
    return f"{BBOX_CENTER_DIRECTION}|options:" + "|".join(roles), roles


@functools.lru_cache(maxsize=4096)
def _object_features(label: str) -> tuple[str, ...]:
    """``label_features(plain=False, object=label)``, once per label."""
    return tuple(label_features(plain=False, object=label))


def _bbox_record(
    scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, inst: Instance, where: tuple[np.ndarray, np.ndarray],
    template: int, answer: tuple[list[tuple[int, int]], str], drawn: tuple[tuple[str, ...], str, Sequence[str]],
) -> QARecord:
    """The record of a box-centre question about ``inst``: ``where`` = camera B's centre and the
    object's centre in B's axes, ``answer`` = its dominant parts and label, ``drawn`` = :func:`bbox_options`'."""
    (centre_b, vec), (parts, truth), (options, letter, deck) = where, answer, drawn
    question = find_in_image(phrase(inst), 0) + "\n" + TWO_VIEW_TEMPLATES[template].format(label=label_text(inst.label))
    extra = {
        **_body_geometry(pair.b, inst.box.center - centre_b, vec, parts, truth),
        "thresholds": {"min_displacement_m": MIN_DISPLACEMENT_M},
        "pair": pair.to_dict(), "pair_rules": rules.to_dict(),
        "selection": _bbox_selection(pair, inst, truth, deck),
    }
    return _record(scene, index, BBOX_CENTER_DIRECTION, (pair.a, pair.b), (inst,), ((inst, pair.a),), question, options, letter, template, extra)


def _rare_bbox_label(label: str) -> bool:
    """A direction label naming "Back" or "Up" (see :func:`_rare_bbox_direction`)."""
    return bool({"Back", "Up"} & set(label.split("-")))


def _rare_bbox_parts(parts: list[tuple[int, int]], label: str) -> bool:
    """:func:`_rare_bbox_direction` from a vector's :func:`dominant_parts` and their label."""
    if _rare_bbox_label(label):
        return True
    if len(parts) == 2:  # the four sign combinations of two axes: at least two must be askable
        return {axis for axis, _ in parts} == {1, 2}  # Up/Down × Front/Back: only "Front-Down"/"Down-Front" would be left (no deck)
    return False


def _rare_bbox_direction(vec_camera: np.ndarray) -> bool:
    """Whether ``bbox_center_direction`` skips this object (decision, debiasing): its label would
    name "Back" (behind camera B) or "Up" (above a camera held at eye height). Both are rare
    (a few per scene), so a blind model learns never to pick them; asked only where a scene
    happens to offer them, they would make the rest predictable. Also skipped: Up/Down ×
    Front/Back labels (only "Front-Down"/"Down-Front" would be left: no deck of four)."""
    parts = dominant_parts(vec_camera)
    return _rare_bbox_parts(parts, parts_label(parts, BODY_DIRECTION_WORDS))


# ------------------------------------------------------------------- relpos
def _relpos_candidates(index: VisibilityIndex, pair: ViewPair) -> tuple[dict[int, str], list[tuple[int, int, int]]]:
    """Each usable object's reference view, and the ordered triplets of usable objects that pass
    the three-object rule (:func:`~spacedg.plugins.questions.view_sampling.split_across_views`: a usable
    object is referable, so clearly visible, in A or B; neither view may show all three)."""
    views = (pair.a, pair.b)
    union = sorted(set(index.visible[pair.a]) | set(index.visible[pair.b]))
    ref_view: dict[int, str] = {}
    for iid in union:
        found = next((v for v in views if referable(index, v, iid)), None)  # image A first, else image B
        if found is not None:
            ref_view[iid] = found
    seen_a, seen_b = index.seen_set(pair.a), index.seen_set(pair.b)
    ids = sorted(ref_view)
    shown = [(i in seen_a) | (i in seen_b) << 1 for i in ids]  # bit 0: seen in A, bit 1: seen in B
    triplets: list[tuple[int, int, int]] = []
    extend = triplets.extend
    for (x, sx), (y, sy), (z, sz) in itertools.combinations(zip(ids, shown), 3):
        if not sx & sy & sz:  # else one view shows all three: the task would collapse to a single view
            extend(itertools.permutations((x, y, z)))
    return ref_view, triplets


def _relpos_names(objs: Sequence[Instance]) -> list[str] | None:
    """Labels when they differ, else phrases; ``None`` when even the phrases coincide."""
    if len({label_key(o.label) for o in objs}) == len(objs):
        return [label_text(o.label) for o in objs]
    if len({phrase_key(o) for o in objs}) < len(objs):
        return None
    return [phrase(o) for o in objs]


def _relpos_shape(
    index: VisibilityIndex, ids: Sequence[int], up: np.ndarray,
) -> tuple[list[Instance], list[str], tuple[dict[str, Any], dict[str, Any]], float, SectorHit] | None:
    """What a relative-position question about the triplet ``ids`` (A, B, C) is, whatever its
    views: the objects, their names, the legs A → B and A → C, the angle of C from A facing B
    and its sector; ``None`` when it is not asked (names that coincide, boxes that overlap, a
    leg too short or too steep). Computed once per triplet (it recurs in many view pairs)."""
    objs = [index.instance(i) for i in ids]
    names = _relpos_names(objs)
    if names is None:
        return None
    if any(boxes_intersect(p.box, q.box) for p, q in itertools.combinations(objs, 2)):
        return None
    leg_ab, leg_ac = object_leg(index, ids[1], ids[0], up), object_leg(index, ids[2], ids[0], up)
    if leg_ab is None or leg_ac is None:
        return None
    axes = index_memo(index, "relpos_axes")  # (A, B) → the ground axes of A facing B
    key = (ids[0], ids[1])
    if key not in axes:
        axes[key] = ground_axes(np.asarray(leg_ab["horizontal"]), up)
    # = ground_angle(horizontal A → B, c_C − c_A, up): leg_ac["horizontal"] is that projection, exactly
    angle = angle_on_ground(axes[key], np.asarray(leg_ac["horizontal"]))
    return objs, names, (leg_ab, leg_ac), angle, RELPOS_SECTORS.classify(angle)


#: Triplet geometries memoised per scene (:func:`_relpos_shape`, ~1.5 KB each) before the memo starts again.
_SHAPES_MAX = 65_536


def _relpos_stream(scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, rng: np.random.Generator) -> Iterator[QARecord | Candidate]:
    up = np.asarray(scene.up, dtype=np.float64)
    views = (pair.a, pair.b)
    ref_view, triplets = _relpos_candidates(index, pair)
    shapes = index_memo(index, "relpos_shapes")  # triplet → (objects, names, legs, angle, sector) or None: no view enters it
    admit = admission()
    for ids in seeded_order(triplets, rng):  # each obeys the three-object rule (split_across_views): see _relpos_candidates
        key = tuple(ids)
        if key not in shapes:
            if len(shapes) >= _SHAPES_MAX:
                shapes.clear()  # bounded memory for an exhaustive scan; only time is lost
            shapes[key] = _relpos_shape(index, ids, up)
        shape = shapes[key]
        if shape is None:
            continue
        subject = _relpos_subject(ids)
        if not admit(RELPOS, views, subject, key):
            yield PASSED_OVER  # the caller passes it over: no draws
            continue
        objs, names, (leg_ab, leg_ac), angle, hit = shape
        ref_views = [ref_view[i] for i in ids]
        truth = RELPOS_SECTORS.labels[hit.index]
        drawn = build_mcq(truth, RELPOS_SECTORS.distractors(hit, rng), rng)
        yield offer(
            RELPOS, views, subject, key, functools.partial(_relpos_selection, ids, hit),
            functools.partial(_relpos_record, scene, index, pair, rules, ids, objs, ref_views, names, (leg_ab, leg_ac), angle, hit, drawn),
        )


def _relpos_subject(ids: Sequence[int]) -> str:
    """The selection subject of a relative-position question: the ordered triplet."""
    return f"objects:{ids[0]}|{ids[1]}|{ids[2]}"


def _relpos_selection(ids: Sequence[int], hit: SectorHit) -> dict[str, Any]:
    """The selection entry of a relative-position question whose query falls in sector ``hit``."""
    truth = RELPOS_SECTORS.labels[hit.index]
    guarded = hit.boundary_distance_deg < BOUNDARY_GUARD_DEG
    return selection_entry(_relpos_subject(ids), RELPOS, truth, RELPOS_SECTORS.labels, distractors=_relpos_distractors(hit.index, hit.neighbour, guarded))


@functools.lru_cache(maxsize=256)
def _relpos_distractors(index: int, neighbour: int, guarded: bool) -> tuple[str, ...]:
    """The sector labels that may be distractors: all but the truth (``index``) and, ``guarded``, its neighbour."""
    labels = RELPOS_SECTORS.labels
    banned = [labels[neighbour]] if guarded else []
    return tuple(t for t in labels if t != labels[index] and t not in banned)


def _relpos_record(
    scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, ids: Sequence[int], objs: list[Instance],
    ref_views: list[str], names: list[str], legs: tuple[dict[str, Any], dict[str, Any]], angle: float, hit: SectorHit,
    drawn: tuple[tuple[str, ...], str],
) -> QARecord:
    """The record of a relative-position triplet: anchor, facing and query ``objs`` found in ``ref_views``, the
    ``legs`` anchor → facing and anchor → query, the ``angle`` and sector ``hit`` of the query, ``drawn`` = (options, letter)."""
    up = np.asarray(scene.up, dtype=np.float64)
    views = (pair.a, pair.b)
    (leg_ab, leg_ac), (options, letter) = legs, drawn
    forward, ab_h = np.asarray(leg_ab["horizontal"]), leg_ab["horizontal_m"]
    truth = RELPOS_SECTORS.labels[hit.index]
    markers = " ".join(find_in_image(phrase(o), views.index(v)) for o, v in zip(objs, ref_views))
    question = markers + "\n" + RELPOS_TEMPLATE.format(a=names[0], b=names[1], c=names[2])
    fwd_unit = forward / ab_h
    banned = [RELPOS_SECTORS.labels[hit.neighbour]] if hit.boundary_distance_deg < BOUNDARY_GUARD_DEG else []
    extra = {
        "roles": {"anchor": ids[0], "facing": ids[1], "query": ids[2]},
        "forward": fwd_unit.tolist(),
        "right": np.cross(fwd_unit, up).tolist(),
        "ab_horizontal_m": ab_h,
        "ab_vertical_m": leg_ab["vertical_m"],
        "ac_horizontal_m": leg_ac["horizontal_m"],
        "ac_vertical_m": leg_ac["vertical_m"],
        "angle_deg": angle,
        "sector_index": hit.index,
        "sector_label": truth,
        "sector_starts_deg": list(RELPOS_SECTORS.starts),
        "boundary_distance_deg": hit.boundary_distance_deg,
        "neighbour_index": hit.neighbour,
        "banned_labels": banned,
        "thresholds": {
            "min_horizontal_m": MIN_HORIZONTAL_M, "vertical_factor": VERTICAL_FACTOR, "boundary_guard_deg": BOUNDARY_GUARD_DEG,
            "intersect_tol_m": INTERSECT_TOL_M,
        },
        "pair": pair.to_dict(), "pair_rules": rules.to_dict(),
        "selection": _relpos_selection(ids, hit),
    }
    return _record(scene, index, RELPOS, views, objs, list(zip(objs, ref_views)), question, options, letter, 0, extra)


def generate(
    scene: Scene,
    rng: np.random.Generator,
    thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS,
    bbox_rules: PairRules = LOW_COVIS_DIRECTION_PAIRS,
    relpos_rules: PairRules = OBJECT_DIRECTION_PAIRS,
) -> Iterator[QARecord]:
    """Every valid camera–object direction question of ``scene``, lazily, in a seeded order (see the module docstring)."""
    yield from round_robin_sub_types(
        scene, VisibilityIndex(scene, thresholds), rng, _single_view_stream, (bbox_rules, _bbox_stream), (relpos_rules, _relpos_stream),
    )


#: ``make_family(thresholds, bbox_rules, relpos_rules)``: this family with other visibility thresholds / pair rules
#: (:func:`~spacedg.plugins.questions.pairs.view_and_pair_family`); :data:`FAMILY`, the registered one, uses the defaults.
make_family = view_and_pair_family(
    generate, name=NAME, task_group=TaskGroup.CAMERA_OBJECT, answer_types={AnswerType.MCQ}, sub_question_types=SUB_QUESTION_TYPES,
    description="Direction of an object relative to another in one view, to camera B, or to a person at A facing B.",
)
FAMILY = make_family()
spacedg_register_question_families = registering(FAMILY)
