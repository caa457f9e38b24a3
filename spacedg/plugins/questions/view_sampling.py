"""Which views and objects a question may use: visibility index, view pairs, object rules.

- :class:`VisibilityIndex`: per view, the instances that are clearly visible
  (:func:`~spacedg.scene.visibility.classify` → ``VISIBLE``) and those with any visible pixel.
- :class:`PairRules` + :func:`sample_pairs`: two-view pairs from the scene's covisibility
  (:attr:`Scene.covisibility`, symmetrised with **min**: both views must see the overlap),
  with a minimum camera baseline and relative rotation where a family needs motion.
- :func:`split_across_views`: the three-object rule (the two views together show the three
  objects; neither view shows all three).
- :func:`description_clash` / :func:`same_label_neighbours`: the description ambiguity filter.
- :func:`scene_labels`: the labels a label-only question (counting, existence) may ask about:
  the scene's instance labels and its vocabulary words, grouped by :func:`label_key`.
- :func:`confusable`: two labels a person may take for one another (the scene lexicon,
  :mod:`spacedg.scene.lexicon`: synonyms, kinds such as armchair ⊂ chair, debatable pairs
  such as stool / chair, and one head noun such as "lamp" / "floor lamp");
  :func:`label_ambiguous`: a view shows an instance that makes a label-only question
  (counting, existence) ambiguous: a confusable label, or an object that shows the label
  unannotated (books on a bookshelf). Those families skip such views.

Anchor policy: a view **may** appear in several pairs (scenes with few views would otherwise
yield few questions), but :func:`sample_pairs` returns pairs in a seeded *round-robin over
anchors*: every anchor view's first pair comes before any anchor's second pair, so a family
that stops after ``n`` records spreads them over as many views as possible. Which view of an
unordered pair is A (the anchor) is a seeded coin flip, so motion directions are balanced
(forward/backward, left/right).

Thresholds (SPEC-QA, "View sampling"): covisibility > 0.25; baseline >= 0.35 m for camera
translation, >= 0.2 m for object questions; relative rotation >= 15° for rotation and
object-direction pairs; camera-object direction pairs take covisibility in [0.05, 0.25] so the
object is not trivially in view.
"""

from __future__ import annotations

import contextlib
import contextvars
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spacedg.scene.lexicon import Lexicon, default_lexicon, head_noun, label_key
from spacedg.scene.model import Instance, Scene
from spacedg.scene.visibility_classes import DEFAULT_THRESHOLDS, VisibilityClass, VisibilityThresholds, classify
from spacedg.errors import InvalidDataError, ParameterError

__all__ = [
    "VisibilityIndex", "shared_visibility_tables", "PairRules", "ViewPair", "sample_pairs", "split_across_views",
    "description_key", "label_key", "head_noun", "confusable", "label_ambiguous", "same_label_neighbours", "description_clash",
    "SceneLabel", "scene_labels",
    "Lexicon", "default_lexicon",
    "TRANSLATION_PAIRS", "ROTATION_PAIRS", "OBJECT_PAIRS", "OBJECT_DIRECTION_PAIRS", "LOW_COVIS_DIRECTION_PAIRS",
]


def confusable(label_a: str, label_b: str, lexicon: Lexicon | None = None) -> bool:
    """True for two different labels a viewer asked about one may reasonably take for the other:
    :meth:`Lexicon.related <spacedg.scene.lexicon.Lexicon.related>` of ``lexicon`` (default
    :func:`~spacedg.scene.lexicon.default_lexicon`): one head noun (``"lamp"`` / ``"floor lamp"``),
    synonyms (``"sofa"`` / ``"couch"``), kinds (``"armchair"`` ⊂ ``"chair"``, ``"desk"`` ⊂
    ``"table"``) and debatable pairs (``"stool"`` / ``"chair"``, ``"monitor"`` / ``"tv"``)."""
    return (lexicon or default_lexicon()).related(label_a, label_b)


def description_key(text: str) -> str:
    """Descriptions compare case- and whitespace-insensitively, trailing full stop ignored."""
    return " ".join(str(text).lower().split()).rstrip(".")


@dataclass(frozen=True, eq=False)
class _VisibilityTables:
    """The classification tables of a :class:`VisibilityIndex` (read-only once made): what
    :func:`shared_visibility_tables` lets the indexes of one scene share."""

    scene: Scene
    classes: dict[str, dict[int, VisibilityClass]]
    visible: dict[str, tuple[int, ...]]
    seen: dict[str, tuple[int, ...]]
    visible_sets: dict[str, frozenset[int]]
    seen_sets: dict[str, frozenset[int]]
    by_id: dict[int, Instance]

    @classmethod
    def of(cls, scene: Scene, thresholds: VisibilityThresholds) -> _VisibilityTables:
        classes: dict[str, dict[int, VisibilityClass]] = {}
        visible: dict[str, tuple[int, ...]] = {}
        seen: dict[str, tuple[int, ...]] = {}
        for view, cam in scene.views.items():
            area = cam.width * cam.height
            row = {inst.id: classify(inst.visibility.get(view), thresholds, area) for inst in scene.instances}
            classes[view] = row
            visible[view] = tuple(sorted(i for i, c in row.items() if c is VisibilityClass.VISIBLE))
            seen[view] = tuple(sorted(i for i, c in row.items() if c is not VisibilityClass.HIDDEN))
        return cls(
            scene, classes, visible, seen,
            {view: frozenset(ids) for view, ids in visible.items()}, {view: frozenset(ids) for view, ids in seen.items()},
            {inst.id: inst for inst in scene.instances},
        )


#: (id(scene), thresholds) → tables, inside :func:`shared_visibility_tables` (else ``None``: every index classifies anew).
_SHARED_TABLES: contextvars.ContextVar[dict[tuple[int, VisibilityThresholds], _VisibilityTables] | None] = contextvars.ContextVar(
    "spacedg_visibility_tables", default=None,
)


@contextlib.contextmanager
def shared_visibility_tables() -> Iterator[None]:
    """Within this block, every :class:`VisibilityIndex` of the same scene object and thresholds
    shares one set of classification tables (made by the first; each index keeps its own memos).
    For a caller that runs many families on a scene that does not change meanwhile (question
    generation, :func:`~spacedg.qa.build.generate_records`): the scene's instances and their
    visibility must not be changed inside the block."""
    token = _SHARED_TABLES.set({})
    try:
        yield
    finally:
        _SHARED_TABLES.reset(token)


class VisibilityIndex:
    """Visibility classes of every instance in every view of a scene (built once per generation).

    Attributes:
        visible: view → ids of clearly visible instances (sorted).
        seen: view → ids with at least one visible pixel (``VISIBLE`` or ``PARTIAL``), sorted.
        memos: name → a per-index cache of a family (:func:`~spacedg.plugins.questions.records.index_memo`).

    ``visible``, ``seen`` and ``classes`` are read-only: inside :func:`shared_visibility_tables`
    (all of question generation) every index of the scene with the same thresholds shares them.
    """

    def __init__(self, scene: Scene, thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS) -> None:
        self.scene = scene
        self.thresholds = thresholds
        shared = _SHARED_TABLES.get()
        key = (id(scene), thresholds)  # the block's tables hold the scene: its id stays its own
        try:
            tables = shared.get(key) if shared is not None else None
        except TypeError:  # unhashable thresholds: not shared
            shared = tables = None
        if tables is None:
            tables = _VisibilityTables.of(scene, thresholds)
            if shared is not None:
                shared[key] = tables
        self.visible: dict[str, tuple[int, ...]] = tables.visible
        self.seen: dict[str, tuple[int, ...]] = tables.seen
        self.classes: dict[str, dict[int, VisibilityClass]] = tables.classes
        self._visible_sets, self._seen_sets, self._by_id = tables.visible_sets, tables.seen_sets, tables.by_id
        self._entries: dict[tuple[str, int], dict[str, object]] = {}  # vis_entry, per (view, id)
        self.memos: dict[str, dict[Any, Any]] = {}  # name → a family's per-index cache (records.index_memo)
        self._seen_labels: dict[str, dict[str, tuple[int, ...]]] = {}  # view → label key → seen ids

    def seen_with_label(self, view: str, key: str) -> tuple[int, ...]:
        """Ids of :attr:`seen` of ``view`` whose :func:`label_key` is ``key``, in :attr:`seen` order
        (grouped once per view)."""
        groups = self._seen_labels.get(view)
        if groups is None:
            groups = {}
            for i in self.seen[view]:
                groups.setdefault(label_key(self._by_id[i].label), []).append(i)
            groups = self._seen_labels[view] = {k: tuple(v) for k, v in groups.items()}
        return groups.get(key, ())

    def visible_set(self, view: str) -> frozenset[int]:
        """:attr:`visible` of ``view`` as a set (``KeyError`` for an unknown view)."""
        return self._visible_sets[view]

    def seen_set(self, view: str) -> frozenset[int]:
        """:attr:`seen` of ``view`` as a set (``KeyError`` for an unknown view)."""
        return self._seen_sets[view]

    def instance(self, instance_id: int) -> Instance:
        return self._by_id[instance_id]

    def cls(self, view: str, instance_id: int) -> VisibilityClass:
        return self.classes[view].get(instance_id, VisibilityClass.HIDDEN)

    def vis_entry(self, view: str, instance_id: int) -> dict[str, object]:
        """``{"visible_pixels", "visible_fraction", "class"}`` of one instance in one view (for geometry blocks)."""
        key = (view, instance_id)
        entry = self._entries.get(key)
        if entry is None:
            entry = self._entries[key] = self._vis_entry(view, instance_id)
        return dict(entry)

    def _vis_entry(self, view: str, instance_id: int) -> dict[str, object]:
        vis = self._by_id[instance_id].visibility.get(view)
        return {
            "visible_pixels": 0 if vis is None else vis.visible_pixels,
            "visible_fraction": 0.0 if vis is None else vis.visible_fraction,
            "class": self.cls(view, instance_id).value,
        }


# ------------------------------------------------------------------- pairs
@dataclass(frozen=True)
class PairRules:
    """Constraints on a two-view pair.

    Attributes:
        min_covisibility: symmetrised (min) covisibility must be **greater** than this.
        max_covisibility: ... and at most this (1 = no upper bound).
        min_translation_m: camera baseline ``|t_b - t_a|`` at least this, metres.
        min_rotation_deg: relative rotation angle of ``R_a^T R_b`` at least this, degrees.
    """

    min_covisibility: float = 0.25
    max_covisibility: float = 1.0
    min_translation_m: float = 0.0
    min_rotation_deg: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_covisibility < self.max_covisibility <= 1.0:
            raise ParameterError(f"PairRules: need 0 <= min_covisibility < max_covisibility <= 1, got {self.min_covisibility}, {self.max_covisibility}")
        if not (math.isfinite(self.min_translation_m) and self.min_translation_m >= 0):
            raise ParameterError(f"PairRules: min_translation_m must be >= 0 metres, got {self.min_translation_m}")
        if not 0.0 <= self.min_rotation_deg <= 180.0:
            raise ParameterError(f"PairRules: min_rotation_deg must be in [0, 180], got {self.min_rotation_deg}")

    def to_dict(self) -> dict[str, float]:
        return {
            "min_covisibility": self.min_covisibility, "max_covisibility": self.max_covisibility,
            "min_translation_m": self.min_translation_m, "min_rotation_deg": self.min_rotation_deg,
        }


#: Camera translation questions: covisible, baseline >= 0.35 m.
TRANSLATION_PAIRS = PairRules(min_translation_m=0.35)
#: Camera rotation questions: covisible, rotation >= 15°.
ROTATION_PAIRS = PairRules(min_rotation_deg=15.0)
#: Two-view object questions: covisible, baseline >= 0.2 m.
OBJECT_PAIRS = PairRules(min_translation_m=0.2)
#: Object-direction questions (``relpos_A_facing_B``): covisible, baseline >= 0.2 m, rotation >= 15°.
OBJECT_DIRECTION_PAIRS = PairRules(min_translation_m=0.2, min_rotation_deg=15.0)
#: ``bbox_center_direction``: low covisibility [0.05, 0.25] so the object is not trivially in view B.
LOW_COVIS_DIRECTION_PAIRS = PairRules(min_covisibility=0.05, max_covisibility=0.25, min_translation_m=0.2, min_rotation_deg=15.0)


@dataclass(frozen=True)
class ViewPair:
    """An ordered pair: ``a`` is the anchor (image A), ``b`` image B."""

    a: str
    b: str
    covisibility: float
    translation_m: float
    rotation_deg: float

    def to_dict(self) -> dict[str, float | str]:
        return {"covisibility": self.covisibility, "translation_m": self.translation_m, "rotation_deg": self.rotation_deg}


def _poses(scene: Scene, names: list[str]) -> tuple[np.ndarray, np.ndarray]:
    poses = np.stack([np.asarray(scene.views[n].cam_to_world, dtype=np.float64) for n in names])
    return poses[:, :3, :3], poses[:, :3, 3]


def sample_pairs(scene: Scene, rules: PairRules, rng: np.random.Generator) -> list[ViewPair]:
    """Every pair of views satisfying ``rules``, oriented and ordered by ``rng`` (see module docstring).

    Raises:
        InvalidDataError: the scene has no covisibility (compute it with
            ``spacedg.scene.covisibility.with_covisibility``).
    """
    eligible = _eligible_pairs(scene, rules)
    n = len(eligible.forward)
    order = rng.permutation(n)
    flips = (rng.random(n) < 0.5)[order]
    # position p of the drawn order holds pair order[p], flipped or not; its rank is the number of
    # earlier positions with the same anchor; pairs are returned by (rank, position)
    anchors = np.where(flips, eligible.second[order], eligible.first[order])
    by_anchor = np.argsort(anchors, kind="stable")  # positions grouped by anchor, in position order within a group
    sorted_anchors = anchors[by_anchor]
    group_start = np.flatnonzero(np.r_[True, sorted_anchors[1:] != sorted_anchors[:-1]]) if n else np.zeros(0, np.int64)
    starts = np.repeat(group_start, np.diff(np.r_[group_start, n]))
    rank = np.empty(n, dtype=np.int64)
    rank[by_anchor] = np.arange(n) - starts
    ranked = np.lexsort((np.arange(n), rank))
    return [
        eligible.backward[k] if flip else eligible.forward[k]
        for k, flip in zip(order[ranked].tolist(), flips[ranked].tolist())
    ]


@dataclass(frozen=True)
class _EligiblePairs:
    """The pairs of views of a scene that satisfy one :class:`PairRules`, before any draw, in
    ``np.triu_indices`` order: each as a :class:`ViewPair` both ways (``forward``: the earlier view first)."""

    forward: list[ViewPair]
    backward: list[ViewPair]
    first: np.ndarray = field(compare=False)  # int64: the index (in the covisibility's view order) of each forward pair's view a
    second: np.ndarray = field(compare=False)  # int64: of its view b (the anchor when the pair is flipped)


#: (id(covisibility), rules) → (covisibility, its views' cameras in order, pairs): the pairs every
#: family samples from under the same rules, computed once per scene; a hit needs the same
#: covisibility object and the very same camera objects (kept here, so a reused id never hits).
_ELIGIBLE: dict[tuple[int, PairRules], tuple[Any, tuple[Any, ...], _EligiblePairs]] = {}


def _eligible_pairs(scene: Scene, rules: PairRules) -> _EligiblePairs:
    """The pairs :func:`sample_pairs` orders (memoised per scene and rules: no draw enters them)."""
    cov = scene.covisibility
    if cov is None:
        raise InvalidDataError(
            f"scene {scene.id!r} has no covisibility; two-view questions need it: "
            "scene = spacedg.scene.covisibility.with_covisibility(scene, cache_dir=...)"
        )
    names = [n for n in cov.names if n in scene.views]
    cameras = tuple(scene.views[n] for n in names)  # the memo checks the cameras themselves: views may be edited in place
    key = (id(cov), rules)
    hit = _ELIGIBLE.get(key)
    if hit is not None and hit[0] is cov and len(hit[1]) == len(cameras) and all(a is b for a, b in zip(hit[1], cameras)):
        return hit[2]
    idx = np.array([cov.index(n) for n in names], dtype=np.int64)
    sym = np.minimum(cov.matrix, cov.matrix.T)[np.ix_(idx, idx)].astype(np.float64)
    rot, centre = _poses(scene, names)
    i, j = np.triu_indices(len(names), k=1)
    score = sym[i, j]
    baseline = np.linalg.norm(centre[j] - centre[i], axis=1)
    trace = np.einsum("nij,nij->n", rot[i], rot[j])  # trace(R_i^T R_j)
    angle = np.degrees(np.arccos(np.clip((trace - 1.0) / 2.0, -1.0, 1.0)))
    keep = (
        (score > rules.min_covisibility) & (score <= rules.max_covisibility)
        & (baseline >= rules.min_translation_m) & (angle >= rules.min_rotation_deg)
    )
    first, second = i[keep].tolist(), j[keep].tolist()
    measures = [
        (round(float(c), 6), round(float(t), 6), round(float(r), 6)) for c, t, r in zip(score[keep], baseline[keep], angle[keep])
    ]
    eligible = _EligiblePairs(
        [ViewPair(names[a], names[b], *m) for a, b, m in zip(first, second, measures)],
        [ViewPair(names[b], names[a], *m) for a, b, m in zip(first, second, measures)],
        i[keep].astype(np.int64), j[keep].astype(np.int64),
    )
    if len(_ELIGIBLE) >= 64:
        _ELIGIBLE.clear()
    _ELIGIBLE[key] = (cov, cameras, eligible)
    return eligible


# ------------------------------------------------------------- object rules
def split_across_views(index: VisibilityIndex, view_a: str, view_b: str, ids: tuple[int, ...]) -> bool:
    """The three-object rule: each object clearly visible in A or B, and neither view shows all of them.

    "Shows" means any visible pixel, so a partly visible third object also collapses the task.
    """
    visible_a, visible_b = index.visible_set(view_a), index.visible_set(view_b)  # an unknown view raises KeyError, as always
    objects = set(ids)
    if len(objects) < 3 or not all(i in visible_a or i in visible_b for i in objects):
        return False
    return not (objects <= index.seen_set(view_a) or objects <= index.seen_set(view_b))


@dataclass(frozen=True)
class SceneLabel:
    """A label a label-only question may ask about (:func:`scene_labels`).

    Attributes:
        key: its :func:`label_key` (how labels are grouped and compared).
        text: the label as the question writes it: the first spelling among the instances in id
            order, else among the vocabulary words in their order.
        source: ``"scene"`` (some instance carries it) or ``"vocabulary"`` (only ``Scene.vocabulary`` has it).
        members: the instances of the label, in id order (none for a vocabulary label).
    """

    key: str
    text: str
    source: str
    members: tuple[Instance, ...]


def scene_labels(scene: Scene) -> list[SceneLabel]:
    """The scene's instance labels and the words of ``Scene.vocabulary`` that no instance carries,
    grouped by :func:`label_key`, in key order (the candidates of counting and existence questions).

    A vocabulary word whose key is empty is dropped; an instance label whose key is empty (only
    underscores) stays a group of key ``""``, which a family may skip.
    """
    members: dict[str, list[Instance]] = {}
    text: dict[str, str] = {}
    for inst in sorted(scene.instances, key=lambda i: i.id):
        key = label_key(inst.label)
        members.setdefault(key, []).append(inst)
        text.setdefault(key, inst.label)
    vocabulary: dict[str, str] = {}
    for word in scene.vocabulary:
        key = label_key(word)
        if key and key not in members:
            vocabulary.setdefault(key, word)
    labels = [SceneLabel(k, text[k], "scene", tuple(members[k])) for k in members]
    labels += [SceneLabel(k, w, "vocabulary", ()) for k, w in vocabulary.items()]
    return sorted(labels, key=lambda label: label.key)


def label_ambiguous(index: VisibilityIndex, view: str, label: str, lexicon: Lexicon | None = None) -> list[Instance]:
    """The instances ``view`` shows (any visible pixel) that make a label-only question about
    ``label`` ambiguous (:meth:`Lexicon.confuses <spacedg.scene.lexicon.Lexicon.confuses>`): a
    confusable label (an armchair for "chair"), or an object that shows ``label`` without its own
    annotation (a bookshelf for "book"). Empty when the question is clear."""
    lex = lexicon or default_lexicon()
    return [index.instance(i) for i in index.seen[view] if lex.confuses(label, index.instance(i).label)]


def same_label_neighbours(index: VisibilityIndex, view: str, instance: Instance) -> list[Instance]:
    """Other instances with the same label that ``view`` shows (any visible pixel)."""
    return [index.instance(i) for i in index.seen_with_label(view, label_key(instance.label)) if i != instance.id]


def description_clash(index: VisibilityIndex, view: str, instance: Instance) -> bool:
    """True when ``view`` shows another same-label instance with the same description (drop the question).

    An instance with an empty description is referred to by its label alone, so any visible
    same-label neighbour makes it ambiguous.
    """
    mine = description_key(instance.description)
    for other in same_label_neighbours(index, view, instance):
        if not mine or description_key(other.description) == mine:
            return True
    return False
