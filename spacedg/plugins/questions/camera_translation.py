"""Camera translation (``question_type = "camera_translation"``; camera-centric, two views).

"View A" is the **first** image of a record (``record.views[0]``), "view B" the second. The
motion is ``d = R_a^T (t_b - t_a)``: B's camera centre in A's OpenCV camera frame (x right,
y down, z forward), metres (:func:`~spacedg.plugins.questions.geometry.relative_translation`).
Before labelling, ``d`` is rounded to 1e-9 m (:data:`D_DECIMALS`) and every answer is computed
from the rounded vector stored in the geometry block, so exact ties (1 m right + 1 m forward)
break the same way after a rigid motion of the whole scene.

Sub types (SPEC-QA type 1; wording from the paper's appendix "Question Templates"):

``main_dir`` (MCQ)
    Label ``parts_label(dominant_parts(d), CAMERA_MOTION_WORDS)``: the largest |component|
    names the first part, the second-largest joins when ``>= 0.5774 x`` the largest (tan 30°),
    at most 2 parts, joined with ``-``, largest first ("right-forward", never
    "forward-right" when |x| > |z|). Exact magnitude ties go to the lower axis (x, then y,
    then z), so 1 m right + 1 m forward is "right-forward". Distractors:

    - two-part truth: the three labels with one or both parts flipped (``flipped_labels``),
      so the four options are the four sign combinations of the same two axes;
    - one-part truth: the flipped word plus **both** words of one other axis, chosen by the
      seeded rng (``single_word_pool``). The options are then both signs of two axes and the
      option set never reveals which axis is the truth (padding with one word from each
      other axis would leave the truth axis as the only one shown with both signs). No
      option is a two-part label containing the truth word (never partially correct).

    A label near the 0.5774 boundary is not skipped: the alternative reading ("right" vs
    "right-forward") is never among the options of the other case.
``distance_exact`` (NA)
    ``|d|`` in metres, rounded to 3 decimals.
``distance_threshold`` (YN)
    ``f ~ U(0.6, 1.4)``; inside ``(0.85, 1.15)`` it snaps to the nearer of 0.85 / 1.15 (an exact
    tie at 1.0 by a seeded coin). The side of 1 (``f < 1`` ⇔ "yes") is dealt from a balanced
    yes/no deck and ``f`` is drawn from ``U(0.6, 1.4)`` restricted to that side, so each answer
    keeps the spec's conditional law while yes/no is exactly 50/50 over the generation; threshold ``= round(max(0.05, |d| f), 2)`` metres, printed
    with two decimals; the answer is "yes" iff ``|d| >`` the **printed** threshold. With
    ``|d| >= 0.35`` m the margin is at least ``0.15 x 0.35 - 0.005 = 0.0475`` m. The prompt
    does not mention camera matrices (the reference did, without giving them).

Question texts keep the paper's sentences but not its answer-format lines ("Reply with only
the option letter", "Output format: <answer>…"): options live in ``record.options`` and the
answer format is the evaluation prompt's job (SPEC-QA "Scoring"). The YN text keeps "Return
ONLY one token: 'yes' or 'no'." since it tells what is asked.

Pairs: :func:`~spacedg.plugins.questions.view_sampling.sample_pairs` with
:data:`~spacedg.plugins.questions.view_sampling.TRANSLATION_PAIRS` (covisibility > 0.25, baseline >= 0.35 m;
a view may anchor several pairs; which view is A is a seeded coin). A pair is skipped when its
``d`` is not finite or shorter than the rule's minimum (re-checked on the unrounded pose).

Order and randomness: **all three** sub types are asked for every pair (every valid candidate
is yielded). They come in three passes over the pairs (in ``sample_pairs``' round-robin
order): pass ``p`` gives pair ``k`` the sub type ``SUB_TYPES[(s + k + p) % 3]`` with a seeded
start ``s``, so a caller that stops after ``n <=`` #pairs records gets ``n`` different pairs and
a balanced mix of sub types. Each (pair, sub type) draws from its own child generator
(:func:`~spacedg.plugins.questions.records.child_rngs`, seeded from ``rng``), so its option
texts and threshold factor do not depend on which other pairs were skipped; the correct letter
and the yes/no side come from two shared balanced decks, dealt in order over the records made.

Geometry block (JSON): ``up``, ``cam_to_world_a``, ``cam_to_world_b`` (4×4), ``pair``
(:meth:`ViewPair.to_dict`; these four from
:func:`~spacedg.plugins.questions.records.pair_geometry`), ``d`` (metres, A's camera frame),
``distance_m`` (``|d|``, full precision), ``parts`` (``[[axis, sign], ...]``; axis 0 = x,
1 = y, 2 = z), ``label``, ``thresholds`` (``ratio`` 0.5774, ``max_parts`` 2,
``min_translation_m``), per sub type ``options_source`` (main_dir: how the distractors were
made) or ``factor_drawn``, ``factor``, ``threshold_m`` (distance_threshold), ``template`` 0, and
``refs`` ``[]`` (no objects) and ``selection``
(:func:`~spacedg.plugins.questions.records.selection_entry`): the subject is the unordered view
pair (a pair is asked once per sub type, in one orientation); ``main_dir``'s cell is its option
set (the four options tell which two axes are in play), ``distance_threshold``'s the printed
threshold in half-octave bins (:func:`threshold_cell`: a large threshold alone suggests "no"),
so the index balances the truth within what the text shows.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from spacedg.plugins.candidates import PASSED_OVER, Candidate, admission, offer
from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Scene
from spacedg.plugins.questions.view_sampling import (
    TRANSLATION_PAIRS,
    PairRules,
    ViewPair,
    sample_pairs,
)
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.questions.geometry import (
    CAMERA_MOTION_WORDS,
    MAX_PARTS,
    TAN30,
    BalancedDeck,
    build_mcq,
    dominant_parts,
    flipped_labels,
    parts_label,
    relative_translation,
    single_word_pool,
    vector_length,
)
from spacedg.plugins.questions.records import child_rngs, make_record, pair_geometry, pair_subject, selection_entry
from spacedg.plugins.question_family import FamilyFactory
from spacedg.plugins.specs import AnswerType, TaskGroup
from spacedg.seeding import draw_index

__all__ = [
    "FAMILY",
    "NAME",
    "SUB_TYPES",
    "TEMPLATES",
    "generate",
    "main_dir_options",
    "make_family",
    "snap_factor",
    "threshold_cell",
    "threshold_for",
]

NAME = "camera_translation"
SUB_TYPES: tuple[str, ...] = ("main_dir", "distance_exact", "distance_threshold")

#: One template per sub type (the paper's wording); ``{threshold}`` is printed with 2 decimals.
TEMPLATES: dict[str, str] = {
    "main_dir": "What is the primary camera motion direction from view A to view B in view A's coordinate?",
    "distance_exact": "What is the camera translation distance from view A to view B (meters)?",
    "distance_threshold": (
        "Based on the images, decide whether the camera translation from view A to view B exceeds "
        "{threshold:.2f} meters. Return ONLY one token: 'yes' or 'no'."
    ),
}

#: ``d`` is rounded to this many decimals (metres) before labelling.
D_DECIMALS = 9
#: The NA answer is rounded to this many decimals (metres).
DISTANCE_DECIMALS = 3
#: Threshold factor range and the band around 1 it is pushed out of.
FACTOR_RANGE = (0.6, 1.4)
FACTOR_SNAP = (0.85, 1.15)
#: Smallest threshold ever asked, metres.
MIN_THRESHOLD_M = 0.05


def snap_factor(factor: float, coin: float) -> float:
    """``factor`` pushed out of ``(0.85, 1.15)`` to the nearer end; an exact tie goes low iff ``coin < 0.5``."""
    lo, hi = FACTOR_SNAP
    if not lo < factor < hi:
        return float(factor)
    to_lo, to_hi = factor - lo, hi - factor
    if math.isclose(to_lo, to_hi, rel_tol=0.0, abs_tol=1e-12):
        return lo if coin < 0.5 else hi
    return lo if to_lo < to_hi else hi


def threshold_for(distance_m: float, factor: float) -> float:
    """The threshold shown in the question: ``round(max(0.05, distance·factor), 2)`` metres."""
    return round(max(MIN_THRESHOLD_M, distance_m * factor), 2)


def threshold_cell(threshold_m: float) -> str:
    """The selection cell of a printed threshold: its half-octave bin, ``"threshold:<round(2 log2 t)>"``."""
    return f"threshold:{round(2 * math.log2(max(threshold_m, 1e-3)))}"


def main_dir_options(parts: list[tuple[int, int]], rng: np.random.Generator) -> tuple[str, list[str], str]:
    """``(truth, distractors, how)`` for the main-direction MCQ (see the module docstring)."""
    truth = parts_label(parts, CAMERA_MOTION_WORDS)
    distractors = flipped_labels(parts, CAMERA_MOTION_WORDS)
    if len(parts) == 1:
        others = [axis for axis in range(3) if axis != parts[0][0]]
        pad_axis = others[draw_index(rng, len(others))]
        skip = [parts[0][0], *(a for a in others if a != pad_axis)]
        distractors += single_word_pool(CAMERA_MOTION_WORDS, exclude_axes=skip)
        return truth, distractors, f"flip + both words of axis {pad_axis}"
    return truth, distractors, "flipped parts"


@dataclass(frozen=True)
class _Candidate:
    pair: ViewPair
    d: np.ndarray
    distance: float
    parts: list[tuple[int, int]]


def _candidate(scene: Scene, pair: ViewPair, rules: PairRules) -> _Candidate | None:
    raw = relative_translation(scene.views[pair.a], scene.views[pair.b])
    if not np.isfinite(raw).all() or vector_length(raw) < rules.min_translation_m:
        return None
    d = raw.round(D_DECIMALS) + 0.0  # + 0.0: no negative zeros (ndarray.round: np.round without its dispatch)
    parts = dominant_parts(d)
    if not parts:
        return None
    return _Candidate(pair, d, vector_length(d), parts)


class _Drawn(NamedTuple):
    """What one record of a sub type drew: its options, answer, question, answer type, id key,
    selection entry and geometry additions (:func:`_draw`)."""

    options: tuple[str, ...]
    answer: Any
    question: str
    answer_type: AnswerType
    key: dict[str, Any]
    selection: dict[str, Any]
    extra: dict[str, Any]


def _draw(cand: _Candidate, sub: str, subject: str, rng: np.random.Generator, deck: BalancedDeck | None) -> _Drawn:
    """Every random draw of one record of sub type ``sub`` about ``subject``; ``deck`` deals the
    MCQ letter or the yes/no side (None for NA)."""
    options: tuple[str, ...] = ()
    key: dict[str, Any] = {"sub": sub}
    extra: dict[str, Any] = {}
    if sub == "main_dir":
        truth, distractors, how = main_dir_options(cand.parts, rng)
        assert deck is not None
        options, answer = build_mcq(truth, distractors, rng, slot=deck.next())
        extra["options_source"] = how
        key["label"] = truth
        texts = sorted(o[3:] for o in options)
        return _Drawn(options, answer, TEMPLATES[sub], AnswerType.MCQ, key, selection_entry(subject, "options:" + "|".join(texts), truth, texts), extra)
    if sub == "distance_exact":
        return _Drawn(options, round(cand.distance, DISTANCE_DECIMALS), TEMPLATES[sub], AnswerType.NA, key, selection_entry(subject), extra)
    # balanced yes/no: the side (f < 1 → "yes") comes from the deck, then f is drawn from
    # U(0.6, 1.4) restricted to that side and snapped: the same law as the spec's, per side
    assert deck is not None
    low_side = deck.next() == 0
    drawn = float(rng.uniform(FACTOR_RANGE[0], 1.0) if low_side else rng.uniform(1.0, FACTOR_RANGE[1]))
    factor = snap_factor(drawn, float(rng.random()))
    threshold = threshold_for(cand.distance, factor)
    answer = "yes" if cand.distance > threshold else "no"
    extra.update(factor_drawn=drawn, factor=factor, threshold_m=threshold, min_threshold_m=MIN_THRESHOLD_M)
    key["threshold"] = threshold
    selection = selection_entry(subject, threshold_cell(threshold), str(answer), ("yes", "no"))
    return _Drawn(options, answer, TEMPLATES[sub].format(threshold=threshold), AnswerType.YN, key, selection, extra)


def _record(scene: Scene, cand: _Candidate, sub: str, rules: PairRules, drawn: _Drawn) -> QARecord:
    """One record of sub type ``sub`` from what :func:`_draw` drew."""
    geometry: dict[str, Any] = {
        **pair_geometry(scene, cand.pair),
        "d": cand.d.tolist(),
        "distance_m": cand.distance,
        "parts": [[axis, sign] for axis, sign in cand.parts],
        "label": parts_label(cand.parts, CAMERA_MOTION_WORDS),
        "thresholds": {"ratio": TAN30, "max_parts": MAX_PARTS, "min_translation_m": rules.min_translation_m},
        "template": 0,
        "refs": [],
        **drawn.extra,
        "selection": drawn.selection,
    }
    return make_record(
        scene, NAME, sub, TaskGroup.CAMERA_CENTRIC, drawn.answer_type, (cand.pair.a, cand.pair.b), drawn.key,
        question=drawn.question, answer=drawn.answer, geometry=geometry, options=drawn.options,
    )


def generate(scene: Scene, rng: np.random.Generator, rules: PairRules = TRANSLATION_PAIRS) -> Iterator[QARecord | Candidate]:
    """Every camera-translation question of ``scene`` (3 per valid pair), lazily, in a seeded order
    (:func:`~spacedg.plugins.candidates.offer`: the record is built only if the question index keeps it)."""
    pairs = sample_pairs(scene, rules, rng)
    start = draw_index(rng, len(SUB_TYPES))
    children = child_rngs(rng, len(pairs) * len(SUB_TYPES))  # row-major: pair k, sub type s
    letter_rng, side_rng = child_rngs(rng, 2)
    decks = {"main_dir": BalancedDeck(letter_rng, 4), "distance_threshold": BalancedDeck(side_rng, 2)}
    cands = [(k, c) for k, pair in enumerate(pairs) if (c := _candidate(scene, pair, rules)) is not None]
    admit = admission()
    for p in range(len(SUB_TYPES)):
        for k, cand in cands:
            s = (start + k + p) % len(SUB_TYPES)
            sub, views, subject = SUB_TYPES[s], (cand.pair.a, cand.pair.b), pair_subject(cand.pair)
            if not admit(sub, views, subject, ()):
                yield PASSED_OVER  # the caller passes it over: no draws
                continue
            drawn = _draw(cand, sub, subject, children[k * len(SUB_TYPES) + s], decks.get(sub))
            yield offer(sub, views, subject, (), functools.partial(dict, drawn.selection), functools.partial(_record, scene, cand, sub, rules, drawn))


#: ``make_family(rules)``: this family with other pair rules
#: (:class:`~spacedg.plugins.question_family.FamilyFactory`); :data:`FAMILY`, the registered one, uses the defaults.
make_family = FamilyFactory(
    generate, name=NAME, task_group=TaskGroup.CAMERA_CENTRIC, answer_types={AnswerType.MCQ, AnswerType.NA, AnswerType.YN},
    sub_question_types=SUB_TYPES, num_views=(2,), needs={"covisibility"},
    description="How the camera moved from view A to view B: main direction, distance, distance above a threshold.",
)
FAMILY = make_family()
spacedg_register_question_families = registering(FAMILY)
