"""What every family's records are built from: seeded orders, the objects a question may name,
and the entries of the ``geometry`` block.

Shared by the question families (:mod:`~spacedg.plugins.questions.geometry` holds the maths:
poses, direction words, sectors, the compass frame, options;
:mod:`~spacedg.plugins.questions.language` the wording). No family defines any of these itself.

Randomness and order (every draw comes from the family's seeded ``rng``, so the same seed gives
the same records in the same order; everything that can be lazy is):

- :func:`child_rngs`: independent child generators, one per sub type / pair / candidate, so a
  skipped candidate does not shift the draws of the others;
- :func:`round_robin`, :func:`round_robin_views`, :func:`round_robin_pairs`: one record from
  each stream in turn (views in a seeded order; pairs in
  :func:`~spacedg.plugins.questions.view_sampling.sample_pairs` order), so a caller that stops after ``n``
  records gets them spread over as many views or pairs as possible; :func:`round_robin_sub_types`:
  the same over the sub types of a family with one single-view and some two-view sub types;
- :func:`seeded_order` (one ``rng.permutation`` of a small list) and :func:`lazy_permutation`
  (a huge candidate space walked in a random order drawn lazily);
- :func:`role_rounds`: whole rounds of each key's roles in a seeded order (a label asked once
  with each answer per round: counting, existence).

Objects: :func:`referable` is the one rule for naming an object in a view (clearly visible
there and no :func:`~spacedg.plugins.questions.view_sampling.description_clash`); :func:`phrase` and
:func:`phrase_key` are how a question names it and how two names are compared.

Geometry-block entries (JSON types; world metres; cameras are OpenCV ``cam_to_world`` 4×4):
:func:`object_entry` (``id``, ``label``, ``description``, box ``center``/``extents``/``rotation``),
:func:`ref_entry` (``id``, ``label``, ``description``, ``view``: where the question says to find
the object), :func:`camera_entry` (view → ``cam_to_world``), :func:`pair_geometry` (``up``,
``cam_to_world_a``, ``cam_to_world_b``, ``pair``: the camera-motion families),
:func:`visibility_entry`, :func:`visibility_thresholds`, :func:`objects_block` (the common head
of every object question's block: ``up``, ``cameras``, ``objects``, ``refs``, ``visibility``,
``visibility_thresholds``) and :func:`compass_block` / :func:`compass_question` (the compass
part of the two compass families' blocks, with the seeded assumed direction and options).
:func:`make_record` builds the :class:`~spacedg.plugins.qa_record.QARecord` with its deterministic id.

Selection (:func:`selection_entry`, the block's ``selection`` entry): what the question index
needs to debias its choice among a family's candidates: the **subject** (asked at most once
per sub type and scene), the **cell** (what a text-only model can tell about the question:
its labels, the shape of its options, the template's axes) and the record's **role** among
the cell's live **roles** (its truth in the cell's terms). The index takes whole rounds of a
cell (one record of every role), so within a scene no function of the cell beats chance.
"""

from __future__ import annotations

import functools
import math
from collections import deque
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from typing import Any, TypeVar

import numpy as np

from spacedg.plugins.qa_record import Answer, QARecord, make_record_id
from spacedg.scene.box import OrientedBox
from spacedg.scene.model import Instance, Scene
from spacedg.plugins.questions.view_sampling import (
    PairRules,
    ViewPair,
    VisibilityIndex,
    description_clash,
    label_key,
    sample_pairs,
)
from spacedg.plugins.questions.geometry import (
    BOUNDARY_GUARD_DEG,
    CARDINALS,
    COMPASS_SECTORS,
    MIN_HORIZONTAL_M,
    TAN30,
    VERTICAL_FACTOR,
    SectorHit,
    build_mcq,
    camera_center,
    compass_answer,
    ground_leg,
    on_compass_boundary,
)
from spacedg.plugins.questions.language import object_phrase
from spacedg.seeding import draw_index, generator_from_state, pcg64_states, shuffled
from spacedg.plugins.specs import AnswerType, TaskGroup

__all__ = [
    "camera_entry",
    "child_rngs",
    "compass_block",
    "compass_distractors",
    "compass_entries",
    "compass_question",
    "label_features",
    "lazy_permutation",
    "make_record",
    "object_leg",
    "object_entry",
    "objects_block",
    "pair_geometry",
    "phrase",
    "phrase_key",
    "ref_entry",
    "referable",
    "referable_ids",
    "referable_instances",
    "view_centre",
    "role_rounds",
    "round_robin",
    "round_robin_pairs",
    "round_robin_sub_types",
    "round_robin_views",
    "seeded_order",
    "selection_entry",
    "index_memo",
    "visibility_entry",
    "visibility_thresholds",
]

T = TypeVar("T")
#: A per-view record stream: ``stream(scene, index, view, rng)``.
ViewStream = Callable[[Scene, VisibilityIndex, str, np.random.Generator], Iterator[QARecord]]
#: A per-pair record stream: ``stream(scene, index, pair, rules, rng)``.
PairStream = Callable[[Scene, VisibilityIndex, ViewPair, PairRules, np.random.Generator], Iterator[QARecord]]


# ------------------------------------------------------------ randomness and order
class ChildGenerators(Sequence[np.random.Generator]):
    """:func:`child_rngs`' result: a read-only sequence of generators, each made from its seed the
    first time it is read (and the same object on every later read), so a family that skips most
    of its candidates never pays for their generators."""

    #: Generators made one by one (``default_rng``, ~9 µs each) before the rest are made from their
    #: seeds' PCG64 states computed in one vectorised pass (:func:`~spacedg.seeding.pcg64_states`,
    #: ~140 µs for any count up to a few hundred, then < 1 µs each): the same generators either way.
    ONE_BY_ONE = 16

    def __init__(self, seeds: np.ndarray) -> None:
        self._seeds = seeds
        self._made: dict[int, np.random.Generator] = {}
        self._states: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self._seeds)

    def __getitem__(self, i):  # type: ignore[override]
        if type(i) is int and 0 <= i < len(self._seeds):
            k = i
        elif isinstance(i, slice):
            return [self[k] for k in range(*i.indices(len(self)))]
        else:
            k = range(len(self))[i]  # IndexError and negative indices as a list
        made = self._made.get(k)
        if made is None:
            seed = int(self._seeds[k])
            if self._states is None and len(self._made) >= self.ONE_BY_ONE:
                self._states = pcg64_states(self._seeds)
            if self._states is None:
                made = np.random.default_rng(seed)
            else:
                made = generator_from_state(self._states[k], seed)  # = default_rng(seed), bit for bit
            self._made[k] = made
        return made


def child_rngs(rng: np.random.Generator, n: int) -> ChildGenerators:
    """``n`` independent generators seeded from ``rng`` (one draw of ``n`` integers in [0, 2**63 − 1)),
    as a sequence that makes each generator when it is first read (:class:`ChildGenerators`).

    A family that needs a grid of children (pair × sub type) takes ``n = rows × cols`` and
    indexes ``row * cols + col``: the seeds are drawn in that (row-major) order.
    """
    return ChildGenerators(rng.integers(0, 2**63 - 1, size=n, dtype=np.int64))


def round_robin(streams: Iterable[Iterable[T]]) -> Iterator[T]:
    """One item from each stream in turn until all are exhausted (streams are started lazily;
    each is iterated once, so a list takes its turns item by item like a generator)."""
    queue = deque(map(iter, streams))
    popleft, append = queue.popleft, queue.append
    while queue:
        stream = popleft()
        for item in stream:  # one item, then the stream goes to the back; an exhausted one is dropped
            yield item
            append(stream)
            break


def seeded_order(items: Sequence[T], rng: np.random.Generator) -> Iterator[T]:
    """``items`` in the order of ``rng.permutation(len(items))`` (drawn on the first ``next``; :func:`~spacedg.seeding.shuffled`)."""
    yield from shuffled(items, rng)


def role_rounds(roles_by_key: Mapping[str, Sequence[Sequence[T]]], rng: np.random.Generator) -> list[list[tuple[T, ...]]]:
    """Whole rounds of each key's roles, for a family balanced per key (a label asked equally often with each answer).

    ``roles_by_key``: key → its candidates of each role, in role order. Only the keys with a
    candidate of every role are kept: in sorted order, then in the order of one
    ``rng.permutation``; each such key's candidates of each role (roles in order) are shuffled by
    one ``rng.permutation``, and its round ``k`` is its ``k``-th candidate of every role (as many
    rounds as its scarcest role has candidates). Visit the keys with
    ``round_robin(iter(rounds) for rounds in ...)``: one round of each key in turn.
    """
    keys = sorted(key for key, roles in roles_by_key.items() if all(roles))
    out: list[list[tuple[T, ...]]] = []
    for i in rng.permutation(len(keys)):
        shuffled = [[group[int(j)] for j in rng.permutation(len(group))] for group in roles_by_key[keys[int(i)]]]
        out.append(list(zip(*shuffled)))
    return out


def lazy_permutation(n: int, rng: np.random.Generator, batch: int = 256) -> Iterator[int]:
    """The integers ``0 … n−1`` in a uniformly random order drawn lazily (Fisher–Yates with a sparse swap map).

    Memory and time grow with the number of items taken, not with ``n``, so a huge candidate
    space (ordered triplets) can be walked in a seeded order and abandoned early. Uniform
    floats are drawn from ``rng`` in batches of ``batch``; the sequence is a pure function of
    the generator's state. (Not the same draws as :func:`seeded_order`, which permutes a small
    list in one ``rng.permutation`` call.)
    """
    swaps: dict[int, int] = {}
    i = 0
    while i < n:
        count = min(batch, n - i)
        # j = min(n − 1, i + ⌊x·(n − i)⌋) for the batch's uniforms, in one pass (the same float64 products)
        steps = np.arange(i, i + count, dtype=np.int64)
        targets = np.minimum(n - 1, steps + (rng.random(count) * (n - steps)).astype(np.int64))
        for j in targets.tolist():
            value = swaps.get(j, j)
            swaps[j] = swaps.pop(i, i)
            yield value
            i += 1


def round_robin_views(scene: Scene, index: VisibilityIndex, rng: np.random.Generator, stream: ViewStream) -> Iterator[QARecord]:
    """The scene's views in a seeded order (:func:`seeded_order`), one record of each view's ``stream`` in turn.

    Lazy: nothing is drawn before the first ``next``; every stream gets the same ``rng``.
    """
    yield from round_robin([stream(scene, index, view, rng) for view in seeded_order(list(scene.views), rng)])


def round_robin_pairs(scene: Scene, index: VisibilityIndex, rules: PairRules, rng: np.random.Generator, stream: PairStream) -> Iterator[QARecord]:
    """The pairs of :func:`~spacedg.plugins.questions.view_sampling.sample_pairs` (``rules``, ``rng``), one record of each pair's ``stream`` in turn.

    Lazy: not even the pairs are sampled before the first ``next``; every stream gets the same ``rng``.
    """
    pairs = sample_pairs(scene, rules, rng)
    yield from round_robin([stream(scene, index, pair, rules, rng) for pair in pairs])


def round_robin_sub_types(
    scene: Scene, index: VisibilityIndex, rng: np.random.Generator, view_stream: ViewStream, *pair_streams: tuple[PairRules, PairStream],
) -> Iterator[QARecord]:
    """A family with a single-view sub type and two-view ones: its sub types interleaved, one record of each in turn.

    ``view_stream`` is the single-view sub type (:func:`round_robin_views`); each ``(rules, stream)``
    of ``pair_streams`` a two-view one (:func:`round_robin_pairs` under its own ``rules``). Each sub
    type gets its own child generator (:func:`child_rngs` of ``rng``, single view first, then the
    pair streams in order), so one sub type's draws never shift another's. Lazy: nothing is
    drawn, and no pair sampled, before the first ``next``.
    """
    view_rng, *pair_rngs = child_rngs(rng, 1 + len(pair_streams))
    yield from round_robin([
        round_robin_views(scene, index, view_rng, view_stream),
        *(round_robin_pairs(scene, index, rules, pair_rng, stream) for (rules, stream), pair_rng in zip(pair_streams, pair_rngs)),
    ])


# ------------------------------------------------------------------ objects
def referable(index: VisibilityIndex, view: str, instance_id: int) -> bool:
    """An object a question may name in ``view``: clearly visible there and no description clash
    (no other same-label instance with the same description is seen in that image)."""
    memo = index_memo(index, "referable")
    key = (view, instance_id)
    hit = memo.get(key)
    if hit is None:
        hit = memo[key] = instance_id in index.visible[view] and not description_clash(index, view, index.instance(instance_id))
    return hit


def referable_ids(index: VisibilityIndex, view: str) -> list[int]:
    """Ids of the objects a question may name in ``view`` (:func:`referable`), in id order."""
    memo = index_memo(index, "referable_ids")
    ids = memo.get(view)
    if ids is None:
        ids = memo[view] = [i for i in index.visible[view] if referable(index, view, i)]
    return list(ids)


def referable_instances(index: VisibilityIndex, view: str) -> tuple[Instance, ...]:
    """The instances of :func:`referable_ids` in ``view``, memoised per view on the index (a tuple:
    shared by every view pair the view is in)."""
    memo = index_memo(index, "referable_instances")
    insts = memo.get(view)
    if insts is None:
        insts = memo[view] = tuple(index.instance(i) for i in referable_ids(index, view))
    return insts


def index_memo(index: VisibilityIndex, name: str) -> dict[Any, Any]:
    """A per-index cache named ``name`` (an index is built once per generation of a scene and
    never changes): for quantities a family computes again for every view pair an object or a
    pair of objects recurs in."""
    try:
        memos = index.memos
    except AttributeError:  # an index object made without VisibilityIndex.__init__
        memos = index.__dict__.setdefault("memos", {})
    memo = memos.get(name)
    if memo is None:
        memo = memos[name] = {}
    return memo


def camera_inside(index: VisibilityIndex, view: str, inst: Instance) -> bool:
    """Whether ``view``'s camera centre lies inside ``inst``'s box (a question about the object's
    direction or distance from that camera is then not asked): memoised per ``(view, object)`` on
    the index, as the same camera and object recur in many view pairs."""
    memo = index_memo(index, "camera_inside")
    key = (view, inst.id)
    inside = memo.get(key)
    if inside is None:
        centre = _camera_centre(index, view)
        spheres = index_memo(index, "box_spheres")  # object id → bounding_sphere(box)
        sphere = spheres.get(inst.id, spheres)
        if sphere is spheres:  # not worked out yet (None: no shortcut for this box)
            sphere = spheres[inst.id] = bounding_sphere(inst.box)
        if sphere is not None and _farther(centre[1], sphere):
            inside = memo[key] = False  # beyond the box's bounding sphere: outside, whatever the rounding
        else:
            inside = memo[key] = bool(inst.box.contains(centre[0][None, :])[0])
    return inside


def view_centre(index: VisibilityIndex, view: str) -> np.ndarray:
    """``view``'s camera centre (world metres, float64), memoised per view on the index: a shared array, read it only."""
    return _camera_centre(index, view)[0]


def _camera_centre(index: VisibilityIndex, view: str) -> tuple[np.ndarray, tuple[float, float, float]]:
    """``view``'s camera centre and its coordinates as floats (memoised per view on the index)."""
    centres = index_memo(index, "camera_centres")
    centre = centres.get(view)
    if centre is None:
        point = camera_center(index.scene.views[view])
        centre = centres[view] = (point, tuple(point.tolist()))
    return centre


def bounding_sphere(box: OrientedBox) -> tuple[tuple[float, float, float], float] | None:
    """``(centre, r²)`` of a sphere holding every point ``box.contains`` accepts (tolerance 0), for a
    cheap "surely outside" test: ``contains`` checks ``|(p − c) R| ≤ h`` per axis, so an accepted
    point has ``|(p − c) R|² ≤ |h|²`` and ``|p − c| ≤ |h| / σ_min(R)``, with ``σ_min(R) ≥ 1 − ‖RᵀR − I‖``
    for a rotation stored with rounding; r² carries a relative margin of 1e-9 for the float
    arithmetic. ``None`` (no shortcut) for a rotation that far from orthonormal or non-finite numbers."""
    rotation = np.asarray(box.rotation, dtype=np.float64)
    deviation = float(np.linalg.norm(rotation.T @ rotation - np.eye(3)))
    half = np.asarray(box.extents, dtype=np.float64) / 2.0
    reach = float(half @ half)
    centre = np.asarray(box.center, dtype=np.float64)
    if not (deviation < 0.5 and math.isfinite(reach) and np.isfinite(centre).all()):
        return None
    return tuple(centre.tolist()), reach / (1.0 - deviation) ** 2 * (1.0 + 1e-9) + 1e-12  # type: ignore[return-value]


def _farther(point: tuple[float, float, float], sphere: tuple[tuple[float, float, float], float]) -> bool:
    """Whether ``point`` lies beyond ``sphere`` (:func:`bounding_sphere`); False for a non-finite point."""
    (x, y, z), (cx, cy, cz) = point, sphere[0]
    dx, dy, dz = x - cx, y - cy, z - cz
    return dx * dx + dy * dy + dz * dz > sphere[1]


def object_leg(index: VisibilityIndex, to_id: int, origin_id: int, up: np.ndarray) -> dict[str, Any] | None:
    """:func:`~spacedg.plugins.questions.geometry.ground_leg` from object ``origin_id``'s box centre
    to object ``to_id``'s (world metres, ``up`` = the scene's up, float64): memoised per ordered pair
    on the index, as a leg recurs in many triplets and view pairs (the compass and relative-position families share it)."""
    memo = index_memo(index, "object_legs")
    key = (to_id, origin_id)
    if key not in memo:
        memo[key] = ground_leg(index.instance(to_id).box.center - index.instance(origin_id).box.center, up)
    return memo[key]


def pair_subject(pair: ViewPair) -> str:
    """The selection subject of a question about a view pair itself (camera motion): the unordered pair, ``views:<a>|<b>``."""
    return f"views:{min(pair.a, pair.b)}|{max(pair.a, pair.b)}"


def phrase(inst: Instance) -> str:
    """How a question names ``inst``: :func:`~spacedg.plugins.questions.language.object_phrase` of its label and description."""
    return object_phrase(inst.label, inst.description)


def phrase_key(inst: Instance) -> str:
    """The object's question phrase, lower case, whitespace collapsed (to test that names differ);
    computed once per (label, description): candidates compare the same objects' names thousands of times."""
    label, description = inst.label, inst.description
    if type(label) is not str or type(description) is not str:
        return " ".join(phrase(inst).lower().split())
    return _phrase_key(label, description)


@functools.lru_cache(maxsize=65_536)
def _phrase_key(label: str, description: str) -> str:
    return " ".join(object_phrase(label, description).lower().split())


# ------------------------------------------------------------ geometry-block entries
#: id → (object, its entry): entries that depend on one immutable scene object only, computed
#: once per object (a scene's instances and cameras recur in thousands of candidates). The object
#: is kept with its entry, so an id reused by another object never reads a stale entry.
_ENTRIES: dict[tuple[str, int], tuple[Any, Any]] = {}
_ENTRIES_MAX = 65_536


def _entry_of(kind: str, obj: Any, make: Callable[[Any], Any]) -> Any:
    """``make(obj)``, memoised per object (:data:`_ENTRIES`); the caller copies what it hands out."""
    key = (kind, id(obj))
    hit = _ENTRIES.get(key)
    if hit is not None and hit[0] is obj:
        return hit[1]
    if len(_ENTRIES) >= _ENTRIES_MAX:
        _ENTRIES.clear()
    value = make(obj)
    _ENTRIES[key] = (obj, value)
    return value


def _object_entry(inst: Instance) -> dict[str, Any]:
    return {
        "id": inst.id, "label": inst.label, "description": inst.description,
        "center": inst.box.center.tolist(), "extents": inst.box.extents.tolist(), "rotation": inst.box.rotation.tolist(),
    }


def object_entry(inst: Instance) -> dict[str, Any]:
    """An object's identity and oriented box (world metres): ``id``, ``label``, ``description``,
    ``center``, ``extents`` (full side lengths) and ``rotation`` (columns = box axes in world coordinates).

    Computed once per instance; every call returns a new dict whose lists are shared between calls
    (a record's geometry is copied into plain JSON types when the record is made: never mutate them)."""
    return dict(_entry_of("object", inst, _object_entry))


def ref_entry(inst: Instance, view: str) -> dict[str, Any]:
    """``{"id", "label", "description", "view"}``: an object named in the question and the view it is found in."""
    return {"id": inst.id, "label": inst.label, "description": inst.description, "view": view}


def camera_entry(scene: Scene, views: Sequence[str]) -> dict[str, list[list[float]]]:
    """View → 4×4 ``cam_to_world`` (OpenCV axes, metres) of the views a question uses."""
    return {v: _entry_of("camera", scene.views[v], _pose_list) for v in views}


def _pose_list(camera: Any) -> list[list[float]]:
    """A camera's 4×4 ``cam_to_world`` as nested lists (memoised per camera by :func:`camera_entry`;
    the record copies it)."""
    return np.asarray(camera.cam_to_world, dtype=np.float64).tolist()


def pair_geometry(scene: Scene, pair: ViewPair) -> dict[str, Any]:
    """The pose part of a two-view camera-motion block: ``up``, both 4×4 ``cam_to_world`` (``_a``, ``_b``; OpenCV axes, metres) and ``pair``."""
    return {
        "up": [float(v) for v in scene.up],
        "cam_to_world_a": np.asarray(scene.views[pair.a].cam_to_world, dtype=np.float64).tolist(),
        "cam_to_world_b": np.asarray(scene.views[pair.b].cam_to_world, dtype=np.float64).tolist(),
        "pair": pair.to_dict(),
    }


def visibility_entry(index: VisibilityIndex, views: Sequence[str], ids: Sequence[int]) -> list[dict[str, Any]]:
    """Visibility (pixels, fraction, class) of every object in every view of the question."""
    return [{"view": v, "id": i, **index.vis_entry(v, i)} for v in views for i in ids]


def visibility_thresholds(scene: Scene, index: VisibilityIndex, views: Sequence[str]) -> dict[str, Any]:
    """The "clearly visible" thresholds scaled to each view's image size."""
    out: dict[str, Any] = {"min_fraction": float(index.thresholds.min_fraction), "min_pixels": {}}
    for v in views:
        cam = scene.views[v]
        out["min_pixels"][v] = index.thresholds.pixels_for(cam.width * cam.height)
    return out


def objects_block(
    scene: Scene, index: VisibilityIndex, views: Sequence[str], objects: Sequence[Instance], refs: Iterable[tuple[Instance, str]],
) -> dict[str, Any]:
    """The head of an object question's geometry block, in this key order: ``up``, ``cameras``
    (:func:`camera_entry`), ``objects`` (:func:`object_entry` of each of ``objects``), ``refs``
    (:func:`ref_entry` of each ``(object, view)`` in question order), ``visibility``
    (:func:`visibility_entry` of ``objects`` in ``views``) and ``visibility_thresholds``."""
    return {
        "up": scene.up.tolist(),
        "cameras": camera_entry(scene, views),
        "objects": [object_entry(inst) for inst in objects],
        "refs": [ref_entry(inst, view) for inst, view in refs],
        "visibility": visibility_entry(index, views, [inst.id for inst in objects]),
        "visibility_thresholds": visibility_thresholds(scene, index, views),
    }


def compass_block(reference: np.ndarray, assumed_dir: str, query: np.ndarray, up: np.ndarray) -> tuple[str, SectorHit, dict[str, Any]]:
    """Truth label, sector hit and the compass part of a geometry block (frame, angle, sector, guard).

    ``reference`` points towards ``assumed_dir`` (:func:`~spacedg.plugins.questions.geometry.compass_answer`);
    the block holds ``assumed_dir``, ``assumed_angle_deg``, ``north``, ``east`` (unit ground vectors),
    ``angle_deg`` of ``query`` (clockwise from north seen from above), the sector (``sector_index``,
    ``sector_label``, ``sector_labels``, ``sector_starts_deg``, ``boundary_distance_deg``,
    ``neighbour_index``), ``banned_labels`` (the neighbour across a boundary within
    :data:`~spacedg.plugins.questions.geometry.BOUNDARY_GUARD_DEG`) and ``thresholds``.
    """
    label, angle, hit, north, east = compass_answer(reference, assumed_dir, query, up)
    return label, hit, compass_entries(assumed_dir, label, angle, hit, north, east)


def compass_entries(assumed_dir: str, label: str, angle: float, hit: SectorHit, north: np.ndarray, east: np.ndarray) -> dict[str, Any]:
    """The compass part of a geometry block (:func:`compass_block`) from the answer's parts
    (:func:`~spacedg.plugins.questions.geometry.compass_answer`)."""
    banned = [COMPASS_SECTORS.labels[hit.neighbour]] if hit.boundary_distance_deg < BOUNDARY_GUARD_DEG else []
    return {
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


def compass_question(
    reference: np.ndarray, query: np.ndarray, up: np.ndarray, rng: np.random.Generator,
) -> tuple[str, tuple[str, ...], str, dict[str, Any]] | None:
    """``(assumed_dir, options, letter, block)`` of a compass question, drawn from ``rng`` in this order:
    the assumed cardinal (``rng.integers`` over :data:`~spacedg.plugins.questions.geometry.CARDINALS`),
    then the distractor order (``COMPASS_SECTORS.distractors``) and the options and letter
    (:func:`~spacedg.plugins.questions.geometry.build_mcq`). ``block`` is :func:`compass_block`'s.
    ``None`` (after the assumed cardinal's draw only) when the angle lies within
    :data:`~spacedg.plugins.questions.geometry.COMPASS_RULE_BAND_DEG` of a sector boundary."""
    assumed = CARDINALS[draw_index(rng, len(CARDINALS))]
    truth, hit, block = compass_block(reference, assumed, query, up)
    if on_compass_boundary(hit):
        return None
    options, letter = build_mcq(truth, COMPASS_SECTORS.distractors(hit, rng), rng)
    return assumed, options, letter, block


def compass_distractors(block: dict[str, Any]) -> list[str]:
    """The compass labels that may be distractors of a compass question (:func:`compass_block`'s
    ``block``): all but the truth and a banned neighbour, for :func:`selection_entry`."""
    banned = set(block.get("banned_labels", ())) | {block["sector_label"]}
    return [t for t in COMPASS_SECTORS.labels if t not in banned]


#: id → tuple of str that :func:`_str_list` has read (held, so that the id stays that tuple's): most
#: families pass a cell's roles and a label's features as one cached tuple in every candidate that names them.
_STR_TUPLES: dict[int, tuple[str, ...]] = {}
_STR_TUPLES_MAX = 4096


def _str_list(items: Sequence[Any]) -> list[str]:
    """``list(map(str, items))``; for a tuple of exact ``str`` it has read before (that very object),
    ``list(items)`` without the conversions. The memo is emptied when it holds :data:`_STR_TUPLES_MAX`
    tuples (a family that makes a new tuple per candidate only fills it). Only tuples of exact ``str``
    are remembered: their conversion cannot go stale."""
    if type(items) is tuple:
        if _STR_TUPLES.get(id(items)) is items:
            return list(items)
        if all(type(x) is str for x in items):
            if len(_STR_TUPLES) >= _STR_TUPLES_MAX:
                _STR_TUPLES.clear()
            _STR_TUPLES[id(items)] = items
            return list(items)
    return list(map(str, items))


def selection_entry(
    subject: str, cell: str | None = None, role: str | None = None, roles: Sequence[str] = (), *, all_roles: bool = True,
    features: Sequence[str] = (), distractors: Sequence[str] = (),
) -> dict[str, Any]:
    """The ``selection`` entry of a geometry block (module docstring, "Selection").

    ``subject``: what the question is about (``"object:12"``, ``"pair:3|7"``, ``"view:frame_0004|label:chair"``);
    the question index asks one subject at most once per sub type and scene (a re-ask in another
    view has the same answer). ``cell``: what a text-only model can tell (``None``: the record's
    answer is metric or not balanced); ``role``: this record's truth in the cell's terms;
    ``roles``: every role the cell's questions can have (the index balances over exactly these,
    taking whole rounds; a cell missing a role gives no records). ``all_roles=False``: the
    rounds go over the roles the scene offers in the cell (at least two), for cells whose
    options name directions the geometry rarely or never produces ("Up" of an object seen
    from a camera at eye height). ``features``: what else the text tells a blind model, beyond
    the cell, that may go with the answer (the labels it names, by position: ``"anchor:chair"``);
    the index fills each role of a round with the candidate whose features that role has had
    least so far in the sub type, so no label names a role more often than the others
    (:func:`~spacedg.qa.selection.select_records`). ``distractors``: for a question whose three
    distractors are any of a fixed set of texts (sector labels), every text that may be one
    (the truth and a banned neighbour left out); the index deals the distractors of the records
    it keeps again so that every text is offered equally often in a sub type
    (:func:`~spacedg.qa.deal.deal_distractors`): a text offered more often than others
    would be right less often when offered, and a blind model could learn that.
    """
    if cell is None:
        return {"subject": str(subject)}
    if role is None or role not in roles:
        raise ValueError(f"selection_entry: role {role!r} must be one of roles {list(roles)}")
    out: dict[str, Any] = {"subject": str(subject), "cell": str(cell), "role": str(role), "roles": _str_list(roles)}
    if not all_roles:
        out["all_roles"] = False
    if features:
        out["features"] = _str_list(features)
    if distractors:
        if len(set(distractors)) < 3:
            raise ValueError(f"selection_entry: distractors must hold at least 3 texts, got {list(distractors)}")
        out["distractors"] = list(map(str, distractors))
    return out


def label_features(*, plain: bool = True, **named: str) -> list[str]:
    """Selection features of the labels a question names: ``"<position>:<label>"`` for each
    (``anchor="chair"`` → ``"anchor:chair"``) and, with ``plain``, each label alone
    (``"label:chair"``); labels compared as :func:`~spacedg.scene.lexicon.label_key` does."""
    keys = {pos: label_key(label) for pos, label in named.items()}
    out = [f"{pos}:{key}" for pos, key in keys.items()]
    return out + sorted({f"label:{key}" for key in keys.values()}) if plain else out


# ------------------------------------------------------------------ records
def make_record(
    scene: Scene,
    question_type: str,
    sub_question_type: str,
    task_group: TaskGroup,
    answer_type: AnswerType,
    views: tuple[str, ...],
    key: Any,
    question: str,
    answer: Answer,
    geometry: dict[str, Any],
    options: tuple[str, ...] = (),
) -> QARecord:
    """A :class:`~spacedg.plugins.qa_record.QARecord` of ``scene`` whose id is
    ``make_record_id(scene.id, question_type, sub_question_type, views, key)`` (``key``: what
    identifies the question within its family and views)."""
    return QARecord(
        id=make_record_id(scene.id, question_type, sub_question_type, views, key),
        scene_id=scene.id,
        question_type=question_type,
        sub_question_type=sub_question_type,
        task_group=task_group,
        answer_type=answer_type,
        views=views,
        question=question,
        options=options,
        answer=answer,
        geometry=geometry,
    )
