"""Cross-view cardinal direction (``question_type = "cross_view_cardinal_direction"``; camera-object, 2 views, MCQ).

Sub type ``assumed_direction`` (SPEC-QA, type 5; paper appendix "Camera-Object Cardinal
Direction"). Object 1 is clearly visible in image A, object 2 clearly visible in image B; the
question tells the compass direction of object 1 as seen from where image A was taken and asks
the compass direction of object 2 as seen from where image B was taken.

Frame (exact definition; every vector in world metres, ``up = Scene.up``):

- ground plane: the plane orthogonal to ``up``; ``horizontal(v) = v − (v·up) up``;
- **reference** (defines north): origin = camera A's centre ``t_A`` (translation of A's
  ``cam_to_world``), vector ``u = c_1 − t_A`` to object 1's box centre. The assumed direction
  ``d`` is drawn by ``rng`` from :data:`~spacedg.plugins.questions.geometry.CARDINALS`
  (north, east, south, west at 0°, 90°, 180°, 270° clockwise seen from above); **north** is the
  unit ground vector such that ``horizontal(u)`` lies at angle ``angle(d)`` from north, i.e.
  north = ``horizontal(u)`` turned by ``−angle(d)`` about ``up`` (:func:`compass_frame`);
  **east = north × up** (right-handed world, up against gravity: with z up and north = +x,
  east = −y). Camera A's orientation plays no part (the reference pipeline used camera A's
  x–z plane; we use the ground plane, so the answer survives any camera tilt or roll);
- **query**: origin = camera B's centre ``t_B``, vector ``v = c_2 − t_B`` to object 2's box
  centre; ``angle = ground_angle(north, v, up)`` in [0, 360), clockwise from north towards
  east seen from above. The truth is ``COMPASS_SECTORS.classify(angle)``: by the 0.5774 rule
  on the (north, east) components a cardinal label covers ±30° around its axis and a diagonal
  label the 30° between (north [330, 30), northeast [30, 60), east [60, 120), …).

Skipped: ``|horizontal(u)|`` or ``|horizontal(v)|`` below :data:`MIN_HORIZONTAL_M` = 0.25 m, or
``u`` or ``v`` vertical-dominant (vertical ≥ :data:`VERTICAL_FACTOR` = 1.2 × horizontal).

Options: the truth and three of the seven other compass labels
(``COMPASS_SECTORS.distractors``: seeded order; when ``angle`` is within
:data:`~spacedg.plugins.questions.geometry.BOUNDARY_GUARD_DEG` = 3° of a sector boundary the
label across that boundary is never offered), letters by
:func:`~spacedg.plugins.questions.geometry.build_mcq`.

Objects (decisions): pairs of views from :func:`~spacedg.data.view_sampling.sample_pairs` with
:data:`~spacedg.data.view_sampling.OBJECT_PAIRS` (covisibility > 0.25, baseline ≥ 0.2 m; no
rotation minimum: camera B's orientation does not enter the answer). Object 1 is clearly
visible in A and object 2 clearly visible in B, each without a description clash in that view
(:func:`~spacedg.data.view_sampling.description_clash`); they are distinct instances and their
phrases (:func:`~spacedg.plugins.questions.language.object_phrase`) differ case-insensitively
(the same phrase twice would read as the same object). Either object may also be seen in the
other image; nothing is required there.

Question (paper wording, objects named by their phrases, the same as in the markers)::

    In image A, find the red lamp. In image B, find the wooden chair.
    The direction of red lamp relative to image A is north. What is the direction of wooden chair relative to image B?

Order: pairs in ``sample_pairs`` order, visited round-robin (one record per pair per round);
each pair's (object 1, object 2) candidates in a lazily drawn seeded permutation
(:func:`lazy_permutation`); for each accepted candidate ``rng`` draws the assumed direction,
then the distractor order and the letter. All draws come from the one ``rng``: same seed, same
records in the same order; everything is lazy.

Geometry block (JSON): ``up``; ``cameras`` (view → 4×4 ``cam_to_world``); ``objects`` (id,
label, description, box ``center``/``extents``/``rotation``); ``refs`` (``[{"id", "label",
"description", "view"}]`` in question order); ``visibility``; ``visibility_thresholds``;
``reference`` and ``query`` (``origin_view``, ``origin``, ``object``, ``vector``,
``horizontal``, ``horizontal_m``, ``vertical_m``); ``assumed_dir``; ``assumed_angle_deg``;
``north``; ``east``; ``angle_deg``; ``sector_index``; ``sector_label``; ``sector_labels``;
``sector_starts_deg``; ``boundary_distance_deg``; ``neighbour_index``; ``banned_labels``;
``thresholds`` (``min_horizontal_m``, ``vertical_factor``, ``boundary_guard_deg``,
``cardinal_ratio``); ``template`` (always 0); ``pair``; ``pair_rules``.

Helpers shared by the compass families (:func:`compass_frame`, :func:`compass_answer`,
:func:`lazy_permutation`, :func:`usable`, :func:`phrase_key`, :func:`ground_leg`) live here
(``geometry.py`` has none of them); ``inter_object_distance`` and
``object_proxy_cardinal_direction`` import them. Generic geometry-block helpers come from
``camera_object_distance_estimation``.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator
from typing import Any

import numpy as np

from spacedg.data.qa import QARecord, make_record_id
from spacedg.data.scene import Instance, Scene
from spacedg.data.view_sampling import (
    OBJECT_PAIRS,
    PairRules,
    ViewPair,
    VisibilityIndex,
    description_clash,
    sample_pairs,
)
from spacedg.data.visibility import DEFAULT_THRESHOLDS, VisibilityThresholds
from spacedg.errors import InvalidDataError
from spacedg.plugins.hookspecs import hookimpl
from spacedg.plugins.questions.camera_object_distance_estimation import (
    camera_entry,
    object_entry,
    ref_entry,
    round_robin,
    visibility_entry,
    visibility_thresholds,
)
from spacedg.plugins.questions.geometry import (
    BOUNDARY_GUARD_DEG,
    CARDINALS,
    COMPASS_SECTORS,
    TAN30,
    SectorHit,
    build_mcq,
    camera_center,
    ground_angle,
    horizontal,
    vertical_dominates,
)
from spacedg.plugins.questions.language import find_in_image, object_phrase
from spacedg.plugins.specs import AnswerType, QuestionFamily, TaskGroup

__all__ = [
    "FAMILY",
    "MIN_HORIZONTAL_M",
    "NAME",
    "SUB_QUESTION_TYPE",
    "TEMPLATE",
    "VERTICAL_FACTOR",
    "compass_answer",
    "compass_block",
    "compass_frame",
    "generate",
    "ground_leg",
    "lazy_permutation",
    "make_family",
    "phrase_key",
    "render_question",
    "usable",
]

NAME = "cross_view_cardinal_direction"
SUB_QUESTION_TYPE = "assumed_direction"
#: The paper's wording after the markers; ``{obj1}``, ``{obj2}``: phrases; ``{assumed}``: a cardinal.
TEMPLATE = (
    "The direction of {obj1} relative to image A is {assumed}. "
    "What is the direction of {obj2} relative to image B?"
)
#: A ground-plane leg shorter than this (metres) has no reliable direction: skipped.
MIN_HORIZONTAL_M = 0.25
#: A leg whose |vertical part| >= this × its horizontal length is skipped.
VERTICAL_FACTOR = 1.2

#: (cos, sin) of 0°, 90°, 180°, 270°: exact, so the frame has no rounding from trigonometry.
_QUARTER_TURNS: tuple[tuple[float, float], ...] = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))


# ------------------------------------------------------------ shared helpers
def compass_frame(reference: np.ndarray, assumed_dir: str, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(north, east)`` unit ground vectors such that ``reference`` points towards ``assumed_dir``.

    ``assumed_dir`` is one of :data:`CARDINALS` at ``90·k`` degrees clockwise from north (seen
    from above). With ``f = horizontal(reference)/|…|`` and ``r = f × up`` (f's right):
    ``north = cos(90k) f − sin(90k) r`` (f turned back by 90k), ``east = north × up``. So
    ``ground_angle(north, reference, up) == 90k``. Raises :class:`InvalidDataError` when
    ``reference`` has no ground component.
    """
    if assumed_dir not in CARDINALS:
        raise InvalidDataError(f"compass_frame: assumed_dir must be one of {CARDINALS}, got {assumed_dir!r}")
    u = np.asarray(up, dtype=np.float64)
    u = u / np.linalg.norm(u)
    flat = horizontal(reference, u)
    norm = float(np.linalg.norm(flat))
    if norm <= 1e-12:
        raise InvalidDataError("compass_frame: the reference vector is vertical; it defines no direction on the ground")
    f = flat / norm
    r = np.cross(f, u)
    c, s = _QUARTER_TURNS[CARDINALS.index(assumed_dir)]
    north = c * f - s * r
    return north, np.cross(north, u)


def compass_answer(reference: np.ndarray, assumed_dir: str, query: np.ndarray, up: np.ndarray) -> tuple[str, float, SectorHit, np.ndarray, np.ndarray]:
    """``(label, angle_deg, hit, north, east)`` of ``query`` in the frame where ``reference`` points to ``assumed_dir``."""
    north, east = compass_frame(reference, assumed_dir, up)
    angle = ground_angle(north, query, up)
    hit = COMPASS_SECTORS.classify(angle)
    return COMPASS_SECTORS.labels[hit.index], angle, hit, north, east


def lazy_permutation(n: int, rng: np.random.Generator, batch: int = 256) -> Iterator[int]:
    """The integers ``0 … n−1`` in a uniformly random order drawn lazily (Fisher–Yates with a sparse swap map).

    Memory and time grow with the number of items taken, not with ``n``, so a huge candidate
    space (ordered triplets) can be walked in a seeded order and abandoned early. Uniform
    floats are drawn from ``rng`` in batches of ``batch``; the sequence is a pure function of
    the generator's state.
    """
    swaps: dict[int, int] = {}
    i = 0
    while i < n:
        for x in rng.random(min(batch, n - i)):
            j = min(n - 1, i + int(float(x) * (n - i)))
            value = swaps.get(j, j)
            swaps[j] = swaps.pop(i, i)
            yield value
            i += 1


def usable(index: VisibilityIndex, view: str, instance_id: int) -> bool:
    """An object a question may name in ``view``: clearly visible there and no description clash."""
    return instance_id in index.visible[view] and not description_clash(index, view, index.instance(instance_id))


def phrase_key(inst: Instance) -> str:
    """The object's question phrase, lower case, whitespace collapsed (to test that names differ)."""
    return " ".join(object_phrase(inst.label, inst.description).lower().split())


def ground_leg(vector: np.ndarray, up: np.ndarray, min_horizontal_m: float = MIN_HORIZONTAL_M, factor: float = VERTICAL_FACTOR) -> dict[str, Any] | None:
    """``{"vector", "horizontal", "horizontal_m", "vertical_m"}`` of a leg, or ``None`` when it is skipped.

    Skipped: horizontal length ``< min_horizontal_m`` metres, or vertical-dominant
    (``|vertical| >= factor × horizontal``).
    """
    v = np.asarray(vector, dtype=np.float64)
    flat = horizontal(v, up)
    length = float(np.linalg.norm(flat))
    if length < min_horizontal_m or vertical_dominates(v, up, factor):
        return None
    return {"vector": v.tolist(), "horizontal": flat.tolist(), "horizontal_m": length, "vertical_m": float(v @ np.asarray(up, dtype=np.float64))}


def compass_block(reference: np.ndarray, assumed_dir: str, query: np.ndarray, up: np.ndarray) -> tuple[str, SectorHit, dict[str, Any]]:
    """Truth label, sector hit and the compass part of a geometry block (frame, angle, sector, guard)."""
    label, angle, hit, north, east = compass_answer(reference, assumed_dir, query, up)
    banned = [COMPASS_SECTORS.labels[hit.neighbour]] if hit.boundary_distance_deg < BOUNDARY_GUARD_DEG else []
    block = {
        "assumed_dir": assumed_dir,
        "assumed_angle_deg": 90.0 * CARDINALS.index(assumed_dir),
        "north": north.tolist(),
        "east": east.tolist(),
        "angle_deg": angle,
        "sector_index": hit.index,
        "sector_label": label,
        "sector_labels": list(COMPASS_SECTORS.labels),
        "sector_starts_deg": list(COMPASS_SECTORS.starts),
        "boundary_distance_deg": hit.boundary_distance_deg,
        "neighbour_index": hit.neighbour,
        "banned_labels": banned,
        "thresholds": {
            "min_horizontal_m": MIN_HORIZONTAL_M, "vertical_factor": VERTICAL_FACTOR,
            "boundary_guard_deg": BOUNDARY_GUARD_DEG, "cardinal_ratio": TAN30,
        },
    }
    return label, hit, block


# ------------------------------------------------------------------ records
def render_question(phrase1: str, phrase2: str, assumed_dir: str) -> str:
    """Markers for object 1 in image A and object 2 in image B, then the paper's question."""
    markers = f"{find_in_image(phrase1, 0)} {find_in_image(phrase2, 1)}"
    return markers + "\n" + TEMPLATE.format(obj1=phrase1, obj2=phrase2, assumed=assumed_dir)


def _pair_stream(scene: Scene, index: VisibilityIndex, pair: ViewPair, rules: PairRules, rng: np.random.Generator) -> Iterator[QARecord]:
    up = np.asarray(scene.up, dtype=np.float64)
    views = (pair.a, pair.b)
    ones = [i for i in index.visible[pair.a] if usable(index, pair.a, i)]
    twos = [i for i in index.visible[pair.b] if usable(index, pair.b, i)]
    if not ones or not twos:
        return
    origin_a, origin_b = camera_center(scene.views[pair.a]), camera_center(scene.views[pair.b])
    for k in lazy_permutation(len(ones) * len(twos), rng):
        i, j = divmod(k, len(twos))
        one, two = index.instance(ones[i]), index.instance(twos[j])
        if one.id == two.id or phrase_key(one) == phrase_key(two):
            continue
        ref = ground_leg(one.box.center - origin_a, up)
        query = ground_leg(two.box.center - origin_b, up)
        if ref is None or query is None:
            continue
        assumed = CARDINALS[int(rng.integers(len(CARDINALS)))]
        truth, hit, compass = compass_block(np.asarray(ref["vector"]), assumed, np.asarray(query["vector"]), up)
        options, letter = build_mcq(truth, COMPASS_SECTORS.distractors(hit, rng), rng)
        phrase1, phrase2 = object_phrase(one.label, one.description), object_phrase(two.label, two.description)
        geometry = {
            "up": up.tolist(),
            "cameras": camera_entry(scene, views),
            "objects": [object_entry(one), object_entry(two)],
            "refs": [ref_entry(one, pair.a), ref_entry(two, pair.b)],
            "visibility": visibility_entry(index, views, [one.id, two.id]),
            "visibility_thresholds": visibility_thresholds(scene, index, views),
            "reference": {"origin_view": pair.a, "origin": origin_a.tolist(), "object": one.id, **ref},
            "query": {"origin_view": pair.b, "origin": origin_b.tolist(), "object": two.id, **query},
            **compass,
            "template": 0,
            "pair": pair.to_dict(),
            "pair_rules": rules.to_dict(),
        }
        yield QARecord(
            id=make_record_id(scene.id, NAME, SUB_QUESTION_TYPE, views, {"objects": [one.id, two.id], "assumed_dir": assumed}),
            scene_id=scene.id,
            question_type=NAME,
            sub_question_type=SUB_QUESTION_TYPE,
            task_group=TaskGroup.CAMERA_OBJECT,
            answer_type=AnswerType.MCQ,
            views=views,
            question=render_question(phrase1, phrase2, assumed),
            options=options,
            answer=letter,
            geometry=geometry,
        )


def generate(
    scene: Scene,
    rng: np.random.Generator,
    thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS,
    pair_rules: PairRules = OBJECT_PAIRS,
) -> Iterator[QARecord]:
    """Every valid cross-view cardinal question of ``scene``, lazily, in a seeded order (module docstring)."""
    index = VisibilityIndex(scene, thresholds)
    pairs = sample_pairs(scene, pair_rules, rng)
    yield from round_robin([_pair_stream(scene, index, p, pair_rules, rng) for p in pairs])


def make_family(thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS, pair_rules: PairRules = OBJECT_PAIRS) -> QuestionFamily:
    """The family with custom visibility thresholds / pair rules (the registered one uses the defaults)."""
    return QuestionFamily(
        name=NAME,
        task_group=TaskGroup.CAMERA_OBJECT,
        answer_types=frozenset({AnswerType.MCQ}),
        sub_question_types=(SUB_QUESTION_TYPE,),
        num_views=(2,),
        generate=functools.partial(generate, thresholds=thresholds, pair_rules=pair_rules),
        needs=frozenset({"visibility", "covisibility"}),
        description="Given the compass direction of an object seen from image A, the compass direction of another seen from image B.",
    )


FAMILY = make_family()


@hookimpl
def spacedg_register_question_families(register: Any) -> None:
    """Register :data:`FAMILY`."""
    register(FAMILY)
