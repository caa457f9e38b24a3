"""Object size comparison (``question_type = "object_size_comparison"``; object-centric, 2 views, MCQ).

Two objects are compared across two images: object 1 is **clearly visible** in image A
(:attr:`VisibilityIndex.visible`), object 2 clearly visible in image B. The pair of views comes
from :func:`~spacedg.plugins.questions.view_sampling.sample_pairs` with
:data:`~spacedg.plugins.questions.view_sampling.OBJECT_PAIRS` (covisibility > 0.25, baseline ≥ 0.2 m).

Sub question types and the measured quantity (metres):

``longest_side_compare``
    ``value = max(box.extents)``: the longest full side of the oriented box. Not a corner
    distance (the reference pipeline measured a face or space diagonal, which is wrong).
    Question: ``Which is longer (consider the longest side of the object)? <obj1> or <obj2>?``
``top_height_compare``
    ``value = max_k (corner_k · up)`` over the 8 box corners, with ``up = Scene.up``: the
    elevation of the object's **top** along the scene's up direction (origin at the world
    origin; only the difference matters). Because that is what is measured, the wording
    deviates from the paper's "Which object is taller": ``Which object's top is higher
    (consider the top of the objects)? <obj1> or <obj2>?`` (a cup on a high shelf has a
    higher top than a standing lamp, though the lamp is taller).

``Δ = value1 − value2``. **What a view can resolve** (decision; the paper's 1e-2 m tie cannot be
seen: two sides 1–5 cm apart are neither "the same" to the eye nor decidable):

- the truth is :data:`SAME` ("about the same") when ``|Δ| < max(5 cm, 10 % of the larger
  value)`` (longest side; :data:`SAME_M`, :data:`SAME_FRACTION`) or ``|Δ| < 5 cm`` (top
  elevation: its origin is arbitrary, so only the absolute rule applies);
- the truth is the object with the larger value when ``|Δ| >= max(10 cm, 20 % of the larger
  value)`` (longest side; :data:`DIFFERENT_M`, :data:`DIFFERENT_FRACTION`) or ``|Δ| >= 15 cm``
  (top elevation, :data:`TOP_DIFFERENT_M`);
- in between (a visible but unsure difference) the pair is **skipped**.

Options (:func:`~spacedg.plugins.questions.geometry.build_mcq` with ``n_options=3``, seeded
shuffle): object 1's phrase, object 2's phrase and ``"about the same"``: **three** options,
the three answers that are possible (decision, debiasing: the fourth option the spec named,
"cannot be determined", was never the truth, since both boxes are annotated in metres, and a
blind model eliminated it; a user's chance is one in the options shown, a third).
:data:`NEVER_CORRECT` is kept only so that an object named "cannot be determined" is still
refused.

Object rules (decisions the spec left open):

- each object is clearly visible in its reference view (object 1 in A, object 2 in B) and
  :func:`~spacedg.plugins.questions.view_sampling.description_clash` is False there (no same-label,
  same-description neighbour is seen in that image;
  :func:`~spacedg.plugins.questions.records.referable`);
- the two are distinct instances that can be told apart in words: their labels differ
  (:func:`~spacedg.plugins.questions.view_sampling.label_key`) **or** their descriptions differ
  (:func:`~spacedg.plugins.questions.view_sampling.description_key`), **and** their question phrases
  (:func:`~spacedg.plugins.questions.language.object_phrase`) differ case-insensitively
  (:func:`~spacedg.plugins.questions.records.phrase_key`), so the two options never read the
  same;
- an object may also be visible in the other image; nothing is required there.

Question text: the two marker sentences, then the question on its own line::

    In image A, find the grey fabric sofa. In image B, find the wooden chair.
    Which is longer (consider the longest side of the object)? grey fabric sofa or wooden chair?

Debiasing (the ``selection`` entry, :func:`~spacedg.plugins.questions.records.selection_entry`):
a blind model knows the labels, and label priors (a sofa is longer than a cup) answered most
size comparisons before. The **prior** of a pair is what typical sizes say
(:meth:`Lexicon.typical_size <spacedg.scene.lexicon.Lexicon.typical_size>`: longest side or
top above the floor of a typical instance of each label; a label without one uses the mean of
its instances in this scene, the strongest prior there is), classified by the same rule as the
truth. A record's **role** is its outcome in label terms (``"first"`` / ``"second"``: the
object whose (label, phrase) sorts first / second is larger, or ``"same"``) and its **cell** is
the sub type, the prior's outcome in the same terms and, for the longest side, how sure the
prior is (:func:`prior_strength`; a top depends on what the object stands on, so top cells are
split by the outcome only). Its **features** are the two labels and the two instances by
position (``first:chair``, ``second#12``): the index fills each role of a round with the
candidate whose features that role has had least, so a label (or an object) is not the larger
one more often than the smaller one across a scene's rounds, which a per-label prior of a blind
model would learn. The question index takes whole rounds
of the three roles per cell, so within a scene the prior is right exactly a third of the time:
the pairs kept are ones whose sizes go against their labels as often as with them (two chairs,
a small table and a large chair); a sofa and a cup are never compared. The subject is the sub
type and the unordered pair of instances (a pair is asked once per sub type, whatever the
views).

Order: pairs come in :func:`sample_pairs` order (round-robin over anchor views). Each pair's
candidates ``(object 1, object 2, sub type)`` are shuffled by ``rng.permutation`` the first
time the pair is visited; records are then emitted **round-robin over pairs** (the first valid
candidate of every pair, then the second of every pair, ...; the family is made by
:func:`~spacedg.plugins.questions.pairs.pair_family`), so a caller that stops after
``n`` records gets them spread over as many view pairs as possible. Every draw comes from the
one ``rng``, so a seed fixes the records and their order. Records are built lazily.

Geometry block (JSON): ``pair`` (``a``, ``b``, covisibility, baseline, rotation), ``up``,
``quantity``, ``objects`` (per object: ``id``, ``label``, ``description``, ``view``, box
``center`` / ``extents`` / ``rotation`` (columns = box axes in world coordinates), ``value``
and, for heights, ``top_corner``), ``values`` ``[v1, v2]``, ``delta`` ``v1 − v2``,
``tie_threshold_m`` (``|Δ|`` below it: same) and ``different_threshold_m`` (``|Δ|`` at or above
it: different) for this pair, ``truth`` (``"object1"`` / ``"object2"`` / ``"same"``),
``truth_text``, ``template``, ``refs`` (``id``, ``label``,
``description``, ``view`` of both objects, in question order), ``prior_values`` (the typical
values the cell came from) and ``selection``. Answers, questions and options are invariant
under a rigid motion of the whole scene (``Scene.transformed``): extents are unchanged and
every top elevation shifts by the same ``t · up``.

The ``objects`` and ``refs`` entries are :func:`~spacedg.plugins.questions.records.object_entry`
(plus ``view``, ``value``, ``top_corner``) and :func:`~spacedg.plugins.questions.records.ref_entry`.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from typing import Any, NamedTuple

import numpy as np

from spacedg.plugins.candidates import PASSED_OVER, Candidate, admission, offer
from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Instance, Scene
from spacedg.plugins.questions.view_sampling import (
    PairRules,
    ViewPair,
    VisibilityIndex,
    default_lexicon,
    description_key,
    label_key,
)
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.questions.geometry import build_mcq
from spacedg.seeding import shuffled
from spacedg.plugins.questions.language import find_in_image
from spacedg.plugins.questions.pairs import pair_family
from spacedg.plugins.questions.records import (
    index_memo,
    label_features,
    make_record,
    object_entry,
    phrase,
    phrase_key,
    ref_entry,
    referable_instances,
    selection_entry,
)
from spacedg.plugins.specs import AnswerType, TaskGroup

__all__ = [
    "FAMILY",
    "LONGEST",
    "NAME",
    "NEVER_CORRECT",
    "SAME",
    "SUB_QUESTION_TYPES",
    "TEMPLATES",
    "TIE_THRESHOLD_M",
    "SAME_M",
    "SAME_FRACTION",
    "DIFFERENT_M",
    "DIFFERENT_FRACTION",
    "DELTA_DECIMALS",
    "TOP_DIFFERENT_M",
    "TOP",
    "longest_side",
    "prior_strength",
    "thresholds_for",
    "make_family",
    "render_question",
    "top_elevation",
]

NAME = "object_size_comparison"
LONGEST = "longest_side_compare"
TOP = "top_height_compare"
SUB_QUESTION_TYPES: tuple[str, ...] = (LONGEST, TOP)

#: One template per sub type; ``{obj1}`` / ``{obj2}``: the objects' phrases.
TEMPLATES: dict[str, str] = {
    LONGEST: "Which is longer (consider the longest side of the object)? {obj1} or {obj2}?",
    TOP: "Which object's top is higher (consider the top of the objects)? {obj1} or {obj2}?",
}
#: "About the same" below ``max(SAME_M, SAME_FRACTION × larger value)`` (top elevation: SAME_M).
SAME_M = 0.05
SAME_FRACTION = 0.10
#: Different at or above ``max(DIFFERENT_M, DIFFERENT_FRACTION × larger value)``; between: skipped.
DIFFERENT_M = 0.10
DIFFERENT_FRACTION = 0.20
#: Top elevations are different at or above this many metres.
TOP_DIFFERENT_M = 0.15
#: The absolute part of the "about the same" rule, metres (kept under its old name).
TIE_THRESHOLD_M = SAME_M
#: Option text of a tie.
SAME = "about the same"
#: The never-correct option earlier versions offered (no longer offered; a phrase reading so is refused).
NEVER_CORRECT = "cannot be determined"


# ------------------------------------------------------------------ measures
def longest_side(inst: Instance) -> float:
    """Longest full side of the instance's oriented box, metres (``max(extents)``)."""
    return float(np.max(inst.box.extents))


def _top(inst: Instance, up: np.ndarray) -> tuple[float, np.ndarray]:
    corners = inst.box.corners()
    heights = corners @ np.asarray(up, dtype=np.float64)
    k = int(np.argmax(heights))
    return float(heights[k]), corners[k]


def top_elevation(inst: Instance, up: np.ndarray) -> float:
    """``max_k corner_k · up`` over the 8 box corners: the top's elevation along ``up``, metres."""
    return _top(inst, up)[0]


def thresholds_for(quantity: str, values: tuple[float, float] | list[float]) -> tuple[float, float]:
    """``(same_below, different_from)`` in metres for a pair of values of ``quantity``
    (``"longest_side"`` or ``"top_elevation"``): ``|Δ| < same_below`` is "about the same",
    ``|Δ| >= different_from`` a clear difference, in between is skipped (module docstring;
    ``|Δ|`` is compared rounded to :data:`DELTA_DECIMALS` decimals)."""
    if quantity == "longest_side":
        larger = round(max(abs(float(v)) for v in values), DELTA_DECIMALS)
        return max(SAME_M, SAME_FRACTION * larger), max(DIFFERENT_M, DIFFERENT_FRACTION * larger)
    return SAME_M, TOP_DIFFERENT_M


#: Differences are compared after rounding to this many decimals (metres), so float noise of a
#: rigid motion of the scene never moves a pair across a threshold.
DELTA_DECIMALS = 9


def _outcome(values: tuple[float, float] | list[float], same_below: float) -> int:
    """0: the first value is larger, 1: the second, -1: about the same."""
    delta = round(float(values[0]) - float(values[1]), DELTA_DECIMALS)
    if abs(delta) < same_below:
        return -1
    return 0 if delta > 0 else 1


def prior_strength(quantity: str, prior: tuple[float, float] | list[float]) -> str:
    """How sure the prior is: ``"weak"``, ``"medium"`` or ``"strong"`` (longest side: ratio of the
    typical values below 1.25, 1.6, above; top: difference below 0.1 m, 0.3 m, above)."""
    a, b = (abs(float(v)) for v in prior)
    if quantity == "longest_side":
        ratio = max(a, b) / max(min(a, b), 1e-6)
        return "weak" if ratio < 1.25 else "medium" if ratio < 1.6 else "strong"
    diff = abs(float(prior[0]) - float(prior[1]))
    return "weak" if diff < 0.1 else "medium" if diff < 0.3 else "strong"


def _prior_values(scene: Scene, quantity: str, one: Instance, two: Instance, up: np.ndarray) -> tuple[float, float]:
    """Typical values of the two objects' labels (lexicon: longest side, top above the floor), or,
    for a label without one, the mean of its instances in this scene (tops measured above the
    lowest box corner of the scene, the floor, like the lexicon's)."""
    lexicon = default_lexicon()
    k = 0 if quantity == "longest_side" else 1
    out = []
    for inst in (one, two):
        typical = lexicon.typical_size(inst.label)
        if typical is not None:
            out.append(float(typical[k]))
            continue
        same = [o for o in scene.instances if label_key(o.label) == label_key(inst.label)]
        if quantity == "longest_side":
            values = [longest_side(o) for o in same]
        else:
            floor = min(float(np.min(o.box.corners() @ up)) for o in scene.instances)
            values = [top_elevation(o, up) - floor for o in same]
        out.append(float(np.mean(values)))
    return out[0], out[1]


def _cell(sub: str, quantity: str, prior: tuple[float, float], prior_role: str) -> str:
    """The selection cell: the sub type and the prior's outcome; for the longest side also how
    sure the prior is (:func:`prior_strength`). Top elevations are split by the outcome only:
    a top depends on what the object stands on, so typical tops say less, and finer cells only
    leave rounds incomplete (measured: fewer records, no less blind accuracy)."""
    if quantity == "longest_side":
        return f"{sub}|prior:{prior_role}|{prior_strength(quantity, prior)}"
    return f"{sub}|prior:{prior_role}"


def _size_features(first: Instance, second: Instance) -> list[str]:
    """Selection features of a comparison, in label order (``first`` / ``second`` as the roles):
    each label and each instance by its position, so the rounds give a label, or an object, no
    more wins than losses and ties (what a per-label prior of a blind model would learn)."""
    return [*label_features(plain=False, first=first.label, second=second.label), f"first#{first.id}", f"second#{second.id}"]


def _distinguishable(one: Instance, two: Instance) -> bool:
    """Distinct instances whose labels or descriptions differ and whose phrases read differently
    (case-insensitively, and unlike the fixed option texts)."""
    if one.id == two.id:
        return False
    if label_key(one.label) == label_key(two.label) and description_key(one.description) == description_key(two.description):
        return False
    keys = {phrase_key(inst) for inst in (one, two)}
    return len(keys) == 2 and not keys & {SAME, NEVER_CORRECT}


def render_question(sub: str, phrase1: str, phrase2: str) -> str:
    """Marker sentences for images A and B, then the sub type's question on its own line."""
    markers = f"{find_in_image(phrase1, 0)} {find_in_image(phrase2, 1)}"
    return f"{markers}\n{TEMPLATES[sub].format(obj1=phrase1, obj2=phrase2)}"


# ---------------------------------------------------------------- records
class _Verdict(NamedTuple):
    """What a comparison of two objects in a sub type says, whatever the views (memoised per pair)."""

    quantity: str
    values: tuple[float, float]
    corners: tuple[list[float], list[float]] | None  # the top corners (top elevation only)
    delta: float
    same_below: float
    different_from: float
    truth: str
    truth_text: str
    phrases: tuple[str, str]
    prior: tuple[float, float]
    subject: str
    cell: str
    role: str
    features: list[str]


#: The roles of a comparison's cell, in label order, then a tie.
ROLES = ("first", "second", "same")


def _verdict(scene: Scene, one: Instance, two: Instance, sub: str) -> _Verdict | None:
    """The comparison of ``one`` and ``two`` in ``sub``, or ``None`` when the difference is
    visible but not sure (skipped; module docstring)."""
    up = np.asarray(scene.up, dtype=np.float64)
    corners = None
    if sub == LONGEST:
        values = (longest_side(one), longest_side(two))
        quantity = "longest_side"
    else:
        (v1, c1), (v2, c2) = _top(one, up), _top(two, up)
        values, corners = (v1, v2), (c1.tolist(), c2.tolist())
        quantity = "top_elevation"
    delta = values[0] - values[1]
    same_below, different_from = thresholds_for(quantity, values)
    size = abs(round(delta, DELTA_DECIMALS))
    if same_below <= size < different_from:
        return None  # a difference the eye sees but cannot be sure of: skipped
    phrase1, phrase2 = phrase(one), phrase(two)
    if size < same_below:
        truth, truth_text = "same", SAME
    elif delta > 0:
        truth, truth_text = "object1", phrase1
    else:
        truth, truth_text = "object2", phrase2
    ordered = sorted([(label_key(one.label), phrase_key(one), 0), (label_key(two.label), phrase_key(two), 1)])

    def role_of(outcome: int) -> str:  # outcome in question order → role in label order
        return "same" if outcome < 0 else ROLES[[o[2] for o in ordered].index(outcome)]

    role = role_of(_outcome(values, same_below))
    prior = _prior_values(scene, quantity, one, two, up)
    prior_role = role_of(_outcome(prior, thresholds_for(quantity, prior)[0]))
    return _Verdict(
        quantity, values, corners, delta, same_below, different_from, truth, truth_text, (phrase1, phrase2), prior,
        _subject(one, two, sub), _cell(sub, quantity, prior, prior_role), role,
        _size_features([one, two][ordered[0][2]], [one, two][ordered[1][2]]),
    )


def _subject(one: Instance, two: Instance, sub: str) -> str:
    """The selection subject: the sub type and the unordered object pair."""
    return f"{sub}|objects:{min(one.id, two.id)}|{max(one.id, two.id)}"


def _verdict_of(scene: Scene, one: Instance, two: Instance, sub: str, memo: dict[Any, Any]) -> _Verdict | None:
    """:func:`_verdict` of two :func:`_distinguishable` objects (else ``None``), memoised per
    (object 1, object 2, sub type) in ``memo`` (the index's ``size_verdict`` memo): a pair recurs in many view pairs."""
    key = (one.id, two.id, sub)
    hit = memo.get(key)
    if hit is None or hit[0] is not one or hit[1] is not two:
        hit = memo[key] = (one, two, _verdict(scene, one, two, sub) if _distinguishable(one, two) else None)
    return hit[2]


def _selection(verdict: _Verdict) -> dict[str, Any]:
    """The selection entry of a comparison (module docstring)."""
    return selection_entry(verdict.subject, verdict.cell, verdict.role, ROLES, features=verdict.features)


def _record(
    scene: Scene, pair: ViewPair, one: Instance, two: Instance, sub: str, verdict: _Verdict, drawn: tuple[tuple[str, ...], str],
) -> QARecord:
    """The record of one candidate: the ``verdict`` of its objects, ``drawn`` = (options, letter)."""
    v = verdict
    objects = [{**object_entry(one), "view": pair.a}, {**object_entry(two), "view": pair.b}]
    if v.corners is not None:
        objects[0]["top_corner"], objects[1]["top_corner"] = list(v.corners[0]), list(v.corners[1])
    for entry, value in zip(objects, v.values):
        entry["value"] = value
    options, letter = drawn
    geometry = {
        "pair": {"a": pair.a, "b": pair.b, **pair.to_dict()},
        "up": np.asarray(scene.up, dtype=np.float64).tolist(),
        "quantity": v.quantity,
        "objects": objects,
        "values": list(v.values),
        "delta": v.delta,
        "tie_threshold_m": v.same_below,
        "different_threshold_m": v.different_from,
        "truth": v.truth,
        "truth_text": v.truth_text,
        "template": 0,
        "refs": [ref_entry(one, pair.a), ref_entry(two, pair.b)],
        "prior_values": list(v.prior),
        "selection": _selection(v),
    }
    return make_record(
        scene, NAME, sub, TaskGroup.OBJECT_CENTRIC, AnswerType.MCQ, (pair.a, pair.b), {"objects": [one.id, two.id]},
        question=render_question(sub, *v.phrases), answer=letter, geometry=geometry, options=options,
    )


def _pair_stream(scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, rng: np.random.Generator) -> Iterator[QARecord | Candidate]:
    """The pair's candidates ``(object 1, object 2, sub type)`` in the order of one ``rng.permutation``
    (drawn on the first ``next``); candidate ``k`` = object 1 ``k // (len(twos) · 2)``, object 2
    ``k // 2 % len(twos)``, sub type ``k % 2``. A pair without objects on both sides draws nothing."""
    ones, twos = referable_instances(index, pair.a), referable_instances(index, pair.b)
    size = len(ones) * len(twos) * len(SUB_QUESTION_TYPES)
    if not size:
        return
    views = (pair.a, pair.b)
    admit = admission()
    verdicts = index_memo(index, "size_verdict")
    n_subs, n_twos = len(SUB_QUESTION_TYPES), len(twos)
    for k in shuffled(range(size), rng):  # = rng.permutation(size)
        rest, s = divmod(k, n_subs)
        i, j = divmod(rest, n_twos)
        one, two, sub = ones[i], twos[j], SUB_QUESTION_TYPES[s]
        verdict = _verdict_of(scene, one, two, sub, verdicts)
        if verdict is None:
            continue
        if not admit(sub, views, verdict.subject, (one.id, two.id)):
            yield PASSED_OVER  # the caller passes it over: no draws
            continue
        texts = [*verdict.phrases, SAME]
        drawn = build_mcq(verdict.truth_text, [t for t in texts if t != verdict.truth_text], rng, n_options=3)
        yield offer(sub, views, verdict.subject, (one.id, two.id), functools.partial(_selection, verdict), functools.partial(_record, scene, pair, one, two, sub, verdict, drawn))


#: ``make_family(thresholds, pair_rules)``: this family with other visibility thresholds / pair rules
#: (:func:`~spacedg.plugins.questions.pairs.pair_family`); :data:`FAMILY`, the registered one, uses the defaults.
make_family = pair_family(
    _pair_stream, name=NAME, task_group=TaskGroup.OBJECT_CENTRIC, answer_types={AnswerType.MCQ}, sub_question_types=SUB_QUESTION_TYPES,
    description="Which of two objects, seen in two images, has the longer longest side or the higher top.",
)
FAMILY = make_family()
spacedg_register_question_families = registering(FAMILY)
