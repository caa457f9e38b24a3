"""Camera rotation (``question_type = "camera_rotation"``; camera-centric, two views, MCQ).

"View A" is the **first** image of a record (``record.views[0]``), "view B" the second.

**Reading** (decision: what a person perceives, not the camera-frame Euler angles): the motion
from A to B is read with gravity as reference
(:func:`~spacedg.plugins.questions.geometry.gravity_rotation`): **yaw** = change of heading
about ``Scene.up`` (+ = "turn right"), **pitch** = change of the optical axis's elevation above
the horizon (+ = "tilt up"), **roll** = change of the camera's bank about its optical axis (+ =
"clockwise roll", as the photographer sees the image turn). A person sees a pan, a tilt and a
horizon that rotates; the camera-frame decomposition of ``R_a^T R_b`` (the reading before,
still stored as ``camera_euler_deg``) turns a pan of a downward-looking camera into a yaw plus
a few degrees of "roll" and "tilt" nobody perceives. For a level camera A the two readings
agree exactly. The angles are rounded to 1e-6° (:data:`ANGLE_DECIMALS`) and everything below
is decided on the rounded values stored in the geometry block.

Rule (SPEC-QA type 2), in this order:

1. skip when either camera looks more than 60° above or below the horizon
   (:data:`MAX_ABS_PITCH_DEG`): heading and bank are ill-defined near vertical;
2. skip when yaw or roll exceeds 150° in magnitude (:data:`MAX_ABS_ANGLE_DEG`; not in the spec):
   the turn direction is ambiguous when going the other way round is nearly as short;
3. sort ``|yaw|, |pitch|, |roll|``: ``a1 >= a2`` (ties in the order yaw, pitch, roll); the
   smallest is ignored; skip if ``a1 < 5°``;
4. ``r = a2 / a1``: **single**-dominant if ``a2 < 5°`` or ``r <= 0.4``; **dual**-dominant if
   ``r >= 0.6``; skip the grey zone ``0.4 < r < 0.6``.

Options (4, letters after a seeded shuffle, :func:`~spacedg.plugins.questions.geometry.build_mcq`):

- single: both words of both axes (e.g. "turn right", "turn left", "tilt up", "tilt down"),
  truth = the word of ``a1``'s axis and sign;
- dual: the four sign combinations "<yaw word> and <pitch word>", truth = the actual signs.

The two axes are always written in the order yaw, pitch, roll, in the question text and in
the dual options, **not** in dominance order (which would give the answer away).

``sub_question_type``: dual ``f"{ax1}+{ax2}_dual"`` with ``ax1`` the dominant axis (SPEC-QA);
single ``f"{t1}+{t2}_single"`` with the two axes **in text order** (``yaw+pitch_single``,
``yaw+roll_single``, ``pitch+roll_single``). **Deviation** from SPEC-QA's ``{ax1}+{ax2}`` for
singles: a single's answer *is* its dominant axis's word, so a sub type named by the dominant
axis tells the answer's axis, and the blind rule "always tilt up" scores 50 % on a
``pitch+yaw_single`` of any sign-balanced bench (chance 25 %), 0 % on ``yaw+pitch_single``:
per sub type the bench would read as solvable blind though no model can use it. Named by what
the question shows, the sub type holds both answer axes, balanced. A dual's answer is the signs
of both axes whichever dominates, so its name keeps the spec's order. The dominant axis stays in
the geometry block (``axes``) for breakdowns. The 9 sub types that can occur are declared
(:data:`SUB_TYPES`).

Every named component is perceivable: the answer's axes have ``|angle| >= 5°``
(:data:`MIN_ROTATION_DEG`; a dual answer needs ``a2 >= 0.6 a1 >= 5°``).

Debiasing (the ``selection`` entry): the question text tells a blind model the two axes and
the mode, and pans are far more common than tilts, so the dominant axis was guessable. The
**cell** is the mode and the two axes named in the text; the **roles** are the four option
texts; the question index takes whole rounds (one record per option) per cell (a single cell
is one sub type; a dual cell spans the two sub types of its axes by dominance). The subject is
the unordered view pair.

Pairs: :func:`~spacedg.plugins.questions.view_sampling.sample_pairs` with
:data:`~spacedg.plugins.questions.view_sampling.ROTATION_PAIRS` (covisibility > 0.25, rotation >= 15°; which
view is A is a seeded coin, so turn directions are balanced). One record per qualifying pair,
in ``sample_pairs``' round-robin order; each pair's option shuffle uses its own child
generator seeded from ``rng`` (:func:`~spacedg.plugins.questions.records.child_rngs`).

Geometry block (JSON): ``up``, ``cam_to_world_a``, ``cam_to_world_b`` (4×4), ``pair``,
``r_rel`` (3×3), ``euler_deg`` ``{"yaw", "pitch", "roll"}`` (the gravity-aware reading the
answer uses), ``attitude_a`` / ``attitude_b`` (``elevation_deg``, ``bank_deg``),
``camera_euler_deg`` (the camera-frame decomposition, for comparison), ``axes`` ``[ax1, ax2]``,
``a1_deg``, ``a2_deg``, ``ratio``, ``mode``, ``signs`` (``{axis: ±1}`` of the asked axes),
``thresholds`` (``min_rotation_deg`` 5, ``single_max_ratio`` 0.4, ``dual_min_ratio`` 0.6,
``max_abs_pitch_deg`` 60, ``max_abs_angle_deg`` 150, ``euler`` convention), ``template``
(0 single, 1 dual), ``refs`` ``[]`` and ``selection``.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator, Mapping
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from spacedg.plugins.candidates import PASSED_OVER, Candidate, admission, offer
from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Scene
from spacedg.plugins.questions.view_sampling import ROTATION_PAIRS, PairRules, ViewPair, sample_pairs
from spacedg.plugins.hookspecs import registering
from spacedg.plugins.questions.geometry import (
    ROTATION_WORDS,
    BalancedDeck,
    Heading,
    build_mcq,
    camera_attitude,
    euler_yaw_pitch_roll,
    attitude_change,
    heading,
    relative_rotation,
)
from spacedg.plugins.questions.records import child_rngs, make_record, pair_geometry, pair_subject, selection_entry
from spacedg.plugins.question_family import FamilyFactory
from spacedg.plugins.specs import AnswerType, TaskGroup

__all__ = [
    "AXES",
    "AXIS_PHRASES",
    "FAMILY",
    "NAME",
    "SUB_TYPES",
    "TEMPLATES",
    "RotationCase",
    "classify_rotation",
    "generate",
    "make_family",
]

NAME = "camera_rotation"
#: Axis names in their canonical (text) order.
AXES: tuple[str, ...] = ("yaw", "pitch", "roll")
#: How an axis is named in the question text.
AXIS_PHRASES: dict[str, str] = {
    "yaw": "yaw (turn left/right)",
    "pitch": "pitch (tilt up/down)",
    "roll": "roll (clockwise/counterclockwise)",
}
_LEAD = (
    "Given view A and view B, consider how the camera turned from A to B, with the ground as reference "
    "(yaw: turning left/right about the vertical; pitch: tilting up/down; roll: rotating about the viewing direction). "
)
#: 0: single-axis dominant, 1: two-axis (the paper's wording).
TEMPLATES: tuple[str, ...] = (
    _LEAD + "Which SINGLE rotation direction is the most prominent?\n"
    "(This question focuses on the dominant axis among {axis1} and {axis2}.)",
    _LEAD + "Which option best describes the rotation direction using TWO components: {axis1} and {axis2}?",
)
MODES: tuple[str, ...] = ("single", "dual")
#: Single sub types name the two axes in text order; dual ones dominant axis first (module docstring).
SUB_TYPES: tuple[str, ...] = tuple(f"{a}+{b}_single" for i, a in enumerate(AXES) for b in AXES[i + 1:]) + tuple(
    f"{a}+{b}_dual" for a in AXES for b in AXES if a != b
)


ANGLE_DECIMALS = 6
MIN_ROTATION_DEG = 5.0
SINGLE_MAX_RATIO = 0.4
DUAL_MIN_RATIO = 0.6
MAX_ABS_PITCH_DEG = 60.0
MAX_ABS_ANGLE_DEG = 150.0
EULER_CONVENTION = (
    "gravity-aware: yaw = change of heading about up (+ right), pitch = change of elevation (+ up), "
    "roll = change of bank about the optical axis (+ clockwise), degrees"
)


@dataclass(frozen=True)
class RotationCase:
    """A rotation that can be asked: dominant axis ``ax1``, second ``ax2``, their angles, ratio, mode."""

    ax1: str
    ax2: str
    a1: float
    a2: float
    ratio: float
    mode: str


def classify_rotation(yaw: float, pitch: float, roll: float) -> RotationCase | str:
    """The :class:`RotationCase` of Euler angles (degrees), or why it is skipped (a string)."""
    angles = {"yaw": float(yaw), "pitch": float(pitch), "roll": float(roll)}
    if abs(angles["pitch"]) > MAX_ABS_PITCH_DEG:
        return "gimbal: |pitch| > 60"
    if max(abs(angles["yaw"]), abs(angles["roll"])) > MAX_ABS_ANGLE_DEG:
        return "ambiguous: |angle| > 150"
    ax1, ax2, _ = sorted(AXES, key=lambda a: (-abs(angles[a]), AXES.index(a)))
    a1, a2 = abs(angles[ax1]), abs(angles[ax2])
    if a1 < MIN_ROTATION_DEG:
        return "too small: a1 < 5"
    ratio = a2 / a1
    if a2 < MIN_ROTATION_DEG or ratio <= SINGLE_MAX_RATIO:
        mode = "single"
    elif ratio >= DUAL_MIN_RATIO:
        mode = "dual"
    else:
        return "grey zone: 0.4 < r < 0.6"
    return RotationCase(ax1, ax2, a1, a2, ratio, mode)


def _word(axis: str, sign: int) -> str:
    return ROTATION_WORDS[axis][0 if sign > 0 else 1]


def _options(case: RotationCase, euler: dict[str, float]) -> tuple[str, list[str], list[str]]:
    """``(truth, distractors, text_axes)``; ``text_axes`` = the two axes in canonical order."""
    text_axes = [a for a in AXES if a in (case.ax1, case.ax2)]
    if case.mode == "single":
        sign = 1 if euler[case.ax1] > 0 else -1
        truth = _word(case.ax1, sign)
        words = [_word(a, s) for a in text_axes for s in (1, -1)]
        return truth, [w for w in words if w != truth], text_axes
    signs = [1 if euler[a] > 0 else -1 for a in text_axes]
    truth = f"{_word(text_axes[0], signs[0])} and {_word(text_axes[1], signs[1])}"
    combos = [f"{_word(text_axes[0], s0)} and {_word(text_axes[1], s1)}" for s0 in (1, -1) for s1 in (1, -1)]
    return truth, [c for c in combos if c != truth], text_axes


class _Turn(NamedTuple):
    """A pair's rotation as asked (:func:`_turn`): the relative rotation, both attitudes, the
    gravity-referenced angles, their case and the question's truth and distractors."""

    r_rel: np.ndarray
    attitude_a: tuple[float, float]
    attitude_b: tuple[float, float]
    euler: dict[str, float]
    case: RotationCase
    truth: str
    distractors: list[str]
    text_axes: list[str]

    @property
    def sub(self) -> str:
        """The sub type: singles by their text axes, duals dominant axis first (module docstring)."""
        c, t = self.case, self.text_axes
        return f"{t[0]}+{t[1]}_single" if c.mode == "single" else f"{c.ax1}+{c.ax2}_dual"


def _turn(
    scene: Scene, pair: ViewPair, attitudes: Mapping[str, tuple[tuple[np.ndarray, float, float], Heading | None]], up: np.ndarray,
) -> _Turn | None:
    """The rotation of ``pair`` as a question, or ``None`` when it is not asked (no draws);
    ``attitudes``: each view's :func:`camera_attitude` about ``up`` (the scene's, float64) and its :func:`heading`."""
    cam_a, cam_b = scene.views[pair.a], scene.views[pair.b]
    r_rel = relative_rotation(cam_a, cam_b)
    if not np.isfinite(r_rel).all():
        return None
    (att_a, heading_a), (att_b, heading_b) = attitudes[pair.a], attitudes[pair.b]
    (_, elev_a, bank_a), (_, elev_b, bank_b) = att_a, att_b
    if max(abs(elev_a), abs(elev_b)) > MAX_ABS_PITCH_DEG:
        return None
    yaw, pitch, roll = (round(v, ANGLE_DECIMALS) + 0.0 for v in attitude_change(att_a, att_b, up, (heading_a, heading_b)))
    case = classify_rotation(yaw, pitch, roll)
    if isinstance(case, str):
        return None
    euler = {"yaw": yaw, "pitch": pitch, "roll": roll}
    truth, distractors, text_axes = _options(case, euler)
    return _Turn(r_rel, (elev_a, bank_a), (elev_b, bank_b), euler, case, truth, distractors, text_axes)


def _selection(pair: ViewPair, turn: _Turn, options: tuple[str, ...]) -> dict[str, Any]:
    """The selection entry: cell = mode and text axes, role = the truth, among the options shown."""
    axes = turn.text_axes
    return selection_entry(pair_subject(pair), f"{turn.case.mode}|{axes[0]}+{axes[1]}", turn.truth, sorted(o[3:] for o in options))


def _record(scene: Scene, pair: ViewPair, turn: _Turn, drawn: tuple[tuple[str, ...], str]) -> QARecord:
    """The record of ``pair``'s rotation ``turn`` with the options and letter ``drawn``."""
    case, euler, text_axes, (options, answer) = turn.case, turn.euler, turn.text_axes, drawn
    template = MODES.index(case.mode)
    geometry = {
        **pair_geometry(scene, pair),
        "r_rel": turn.r_rel.tolist(),
        "euler_deg": euler,
        "attitude_a": {"elevation_deg": turn.attitude_a[0], "bank_deg": turn.attitude_a[1]},
        "attitude_b": {"elevation_deg": turn.attitude_b[0], "bank_deg": turn.attitude_b[1]},
        "camera_euler_deg": dict(zip(AXES, euler_yaw_pitch_roll(turn.r_rel))),
        "axes": [case.ax1, case.ax2],
        "a1_deg": case.a1,
        "a2_deg": case.a2,
        "ratio": case.ratio,
        "mode": case.mode,
        "signs": {a: (1 if euler[a] > 0 else -1) for a in text_axes},
        "truth": turn.truth,
        "thresholds": {
            "min_rotation_deg": MIN_ROTATION_DEG, "single_max_ratio": SINGLE_MAX_RATIO,
            "dual_min_ratio": DUAL_MIN_RATIO, "max_abs_pitch_deg": MAX_ABS_PITCH_DEG,
            "max_abs_angle_deg": MAX_ABS_ANGLE_DEG, "euler": EULER_CONVENTION,
        },
        "template": template,
        "refs": [],
        "selection": _selection(pair, turn, options),
    }
    question = TEMPLATES[template].format(axis1=AXIS_PHRASES[text_axes[0]], axis2=AXIS_PHRASES[text_axes[1]])
    return make_record(
        scene, NAME, turn.sub, TaskGroup.CAMERA_CENTRIC, AnswerType.MCQ, (pair.a, pair.b), {"truth": turn.truth, "template": template},
        question=question, answer=answer, geometry=geometry, options=options,
    )


def generate(scene: Scene, rng: np.random.Generator, rules: PairRules = ROTATION_PAIRS) -> Iterator[QARecord | Candidate]:
    """Every camera-rotation question of ``scene`` (at most one per pair), lazily, in a seeded order
    (:func:`~spacedg.plugins.candidates.offer`: the record is built only if the question index keeps it)."""
    pairs = sample_pairs(scene, rules, rng)
    deck_rngs = child_rngs(rng, len(MODES))
    decks = {mode: BalancedDeck(r) for mode, r in zip(MODES, deck_rngs)}  # correct letter per mode, balanced
    up = np.asarray(scene.up, dtype=np.float64)
    attitudes = {view: camera_attitude(cam.cam_to_world, up) for view, cam in scene.views.items()}  # once per view
    attitudes_and_headings = {view: (att, heading(att, up)) for view, att in attitudes.items()}
    children = child_rngs(rng, len(pairs))  # one per pair, made only for a pair that is asked
    admit = admission()
    for k, pair in enumerate(pairs):
        turn = _turn(scene, pair, attitudes_and_headings, up)
        if turn is None:
            continue
        views, subject = (pair.a, pair.b), pair_subject(pair)
        if not admit(turn.sub, views, subject, ()):
            yield PASSED_OVER  # the caller passes it over: no draws
            continue
        drawn = build_mcq(turn.truth, turn.distractors, children[k], slot=decks[turn.case.mode].next())
        yield offer(turn.sub, views, subject, (), functools.partial(_selection, pair, turn, drawn[0]), functools.partial(_record, scene, pair, turn, drawn))


#: ``make_family(rules)``: this family with other pair rules
#: (:class:`~spacedg.plugins.question_family.FamilyFactory`); :data:`FAMILY`, the registered one, uses the defaults.
make_family = FamilyFactory(
    generate, name=NAME, task_group=TaskGroup.CAMERA_CENTRIC, answer_types={AnswerType.MCQ}, sub_question_types=SUB_TYPES,
    num_views=(2,), needs={"covisibility"},
    description="How the camera turned from view A to view B: the dominant rotation axis/axes and their directions.",
)
FAMILY = make_family()
spacedg_register_question_families = registering(FAMILY)
