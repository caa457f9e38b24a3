"""Geometry shared by every question family: relative poses, direction words, sectors, options,
the ground-plane compass frame and the box-intersection tolerance.

No family re-implements these (the helpers that build records and their ``geometry`` blocks
live in :mod:`~spacedg.plugins.questions.records`); the independent recomputation test
re-derives answers with its own code from the stored ``geometry`` blocks.

Conventions (SPEC-QA):

- Cameras are OpenCV: x right, y down, z forward; ``Camera.cam_to_world`` maps camera to world.
  The relative pose of view B seen from view A is ``R_rel = R_a^T R_b`` and the translation
  ``d = R_a^T (t_b - t_a)`` (metres, in A's camera frame).
- "Up" is always ``Scene.up``; the *ground plane* is the plane orthogonal to it.
- **Dominant-part labels** (:func:`dominant_parts`): the axis with the largest |component| is the
  first part; the second-largest is added only when ``|c2| >= TAN30 * |c1|`` (0.5774, a 30°
  angular ratio), and at most :data:`MAX_PARTS` = 2 parts are used (3-part labels invite
  partially-correct distractors).
- **Ground angles** (:func:`ground_angle`): the angle of a vector on the ground plane measured
  from a reference direction ``forward`` towards ``right = forward x up``, in degrees [0, 360):
  0 = ahead, 90 = right, seen from above. Compass labels use north as ``forward`` and east =
  north x up.
- **Ground legs** (:func:`ground_leg`): a vector whose ground-plane length is below
  :data:`MIN_HORIZONTAL_M` = 0.25 m, or whose vertical part is at least
  :data:`VERTICAL_FACTOR` = 1.2 × its horizontal length, has no reliable direction on the
  ground; compass and relative-position questions skip it.
- **Compass frame** (:func:`compass_frame`): given a reference vector declared to point
  towards a cardinal ``d`` (90·k° clockwise from north seen from above), north is the unit
  ground vector the reference's ground projection lies ``90·k``° clockwise from, and
  east = north × up.
- **Box intersection** (:func:`boxes_intersect`): boxes intersect only when they overlap by
  more than :data:`INTERSECT_TOL_M` = 1 mm along every separating axis, so touching boxes (a
  lamp on a table) are apart whatever the float noise of a rigid motion of the scene.
- **Sectors**: relative-position questions split the ground plane into eight 45° sectors
  centred on front, front-right, ... (:data:`RELPOS_SECTORS`); compass questions use the
  0.5774 rule on the (north, east) components, so a cardinal label covers ±30° around its axis
  and a diagonal label the 30° between (:data:`COMPASS_SECTORS`). When the angle lies within
  :data:`BOUNDARY_GUARD_DEG` = 3° of a sector boundary, the neighbouring label on that side is
  never used as a distractor (:meth:`Sectors.classify`).
- **Options** (:func:`build_mcq`): the truth and three distinct distractors; the correct letter
  is dealt from shuffled A–D blocks drawn from the family's seeded ``rng``, so it is uniform
  over A–D exactly (within one block of 4) across a family's generation.
"""

from __future__ import annotations

import functools
import math
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacedg.scene.box import OrientedBox, cross3
from spacedg.seeding import shuffled
from spacedg.plugins.answers import MCQ_LETTERS, MCQ_OPTION_COUNTS
from spacedg.errors import InvalidDataError
from spacedg.render.camera import Camera

__all__ = [
    "TAN30", "MAX_PARTS", "BOUNDARY_GUARD_DEG", "CAMERA_MOTION_WORDS", "BODY_DIRECTION_WORDS",
    "vector_length", "relative_rotation", "relative_translation", "camera_center", "camera_distance", "point_in_camera",
    "dominant_parts", "parts_label", "flipped_labels", "single_word_pool", "build_mcq", "BalancedDeck",
    "horizontal", "ground_angle", "ground_axes", "angle_on_ground", "vertical_dominates",
    "Sectors", "SectorHit", "RELPOS_SECTORS", "COMPASS_SECTORS", "CARDINALS",
    "euler_yaw_pitch_roll", "ROTATION_WORDS", "camera_attitude", "gravity_rotation", "attitude_change", "Heading", "heading",
    "MIN_HORIZONTAL_M", "VERTICAL_FACTOR", "COMPASS_RULE_BAND_DEG", "on_compass_boundary", "ground_leg", "compass_frame", "compass_basis", "compass_turn", "compass_answer",
    "INTERSECT_TOL_M", "boxes_intersect",
]

#: Secondary-axis ratio: a second part is named only when |c2| >= TAN30 * |c1| (30°).
TAN30 = 0.5774
#: At most this many parts in a direction label ("right-up", never "right-up-forward").
MAX_PARTS = 2
#: Within this many degrees of a sector boundary, the neighbour across it is no distractor.
BOUNDARY_GUARD_DEG = 3.0
#: A compass angle within this many degrees of a sector boundary is not asked: SPEC-QA states the
#: compass sectors both as ±30° and by the 0.5774 ratio, which puts each boundary 0.0013° apart
#: (atan 0.5774 = 30.0013°), and an independent recomputation's float noise is far below 0.01°;
#: inside the band the label depends on which reading a checker takes (one of 11,366 records did).
COMPASS_RULE_BAND_DEG = 0.01
#: A ground-plane leg shorter than this (metres) has no reliable direction: skipped.
MIN_HORIZONTAL_M = 0.25
#: A vector whose |vertical part| >= this × its horizontal length is vertical-dominant.
VERTICAL_FACTOR = 1.2
#: Boxes "intersect" only when they overlap by more than this (metres) along every separating
#: axis: touching boxes (a lamp standing on a table) are not intersecting, and float noise of
#: a rigid motion of the scene must not flip the decision.
INTERSECT_TOL_M = 1e-3

#: Camera-frame words per axis (x, y, z): (positive, negative). Camera translation questions.
CAMERA_MOTION_WORDS: tuple[tuple[str, str], ...] = (("right", "left"), ("down", "up"), ("forward", "backward"))
#: Camera-frame words for where an object is relative to the camera (x, y, z).
BODY_DIRECTION_WORDS: tuple[tuple[str, str], ...] = (("Right", "Left"), ("Down", "Up"), ("Front", "Back"))

#: Rotation words per axis name: (positive, negative); see :func:`euler_yaw_pitch_roll`.
ROTATION_WORDS: dict[str, tuple[str, str]] = {
    "yaw": ("turn right", "turn left"),
    "pitch": ("tilt up", "tilt down"),
    "roll": ("clockwise roll", "counterclockwise roll"),
}


# ------------------------------------------------------------------ poses
def vector_length(vector: np.ndarray) -> float:
    """``float(np.linalg.norm(vector))``, bit for bit: for a float64 array, the same operations without
    numpy's dispatch (numpy computes the 2-norm as ``sqrt(x.dot(x))`` of ``x = vector.ravel(order="K")``;
    a square root is correctly rounded either way), for the per-candidate lengths; any other input
    goes to ``np.linalg.norm`` itself."""
    if type(vector) is not np.ndarray or vector.dtype != np.float64:
        return float(np.linalg.norm(vector))
    x = vector.ravel(order="K")
    return math.sqrt(x.dot(x))


def camera_center(camera: Camera) -> np.ndarray:
    """Camera centre in world metres."""
    return np.asarray(camera.cam_to_world, dtype=np.float64)[:3, 3].copy()


def camera_distance(camera: Camera, point: np.ndarray) -> float:
    """Straight-line distance from ``camera``'s centre to the world ``point`` (an object's box centre), metres."""
    return vector_length(np.asarray(point, dtype=np.float64) - camera_center(camera))


def relative_rotation(cam_a: Camera, cam_b: Camera) -> np.ndarray:
    """``R_a^T R_b``: B's camera axes expressed in A's camera frame (3, 3)."""
    ra = np.asarray(cam_a.cam_to_world, dtype=np.float64)[:3, :3]
    rb = np.asarray(cam_b.cam_to_world, dtype=np.float64)[:3, :3]
    return ra.T @ rb


def relative_translation(cam_a: Camera, cam_b: Camera) -> np.ndarray:
    """``R_a^T (t_b - t_a)``: B's centre in A's camera frame, metres (x right, y down, z forward)."""
    ra = np.asarray(cam_a.cam_to_world, dtype=np.float64)[:3, :3]
    return ra.T @ (camera_center(cam_b) - camera_center(cam_a))


def point_in_camera(camera: Camera, point: np.ndarray) -> np.ndarray:
    """World ``point`` in ``camera``'s frame (OpenCV axes), metres."""
    pose = np.asarray(camera.cam_to_world, dtype=np.float64)
    return pose[:3, :3].T @ (np.asarray(point, dtype=np.float64) - pose[:3, 3])


def euler_yaw_pitch_roll(rotation: np.ndarray) -> tuple[float, float, float]:
    """``(yaw, pitch, roll)`` in degrees with ``rotation = R_y(yaw) @ R_x(pitch) @ R_z(roll)``.

    Camera-frame convention (OpenCV axes, intrinsic y–x–z): **yaw** about the camera's y (down)
    axis, positive = the forward axis turns towards +x ("turn right"); **pitch** about x,
    positive = the forward axis rises towards −y ("tilt up"); **roll** about z (forward),
    positive = the camera's right axis turns towards +y, i.e. the camera rolls clockwise as
    seen from behind it ("clockwise roll"). ``|pitch| <= 90``; near ±90 yaw and roll are
    ill-defined (gimbal lock), so callers skip ``|pitch| >`` a limit.
    """
    r = np.asarray(rotation, dtype=np.float64)
    # R_y(a) R_x(b) R_z(c): third column (sa cb, -sb, ca cb), second row (cb sc, cb cc, -sb).
    b = math.asin(float(np.clip(-r[1, 2], -1.0, 1.0)))
    a = math.atan2(r[0, 2], r[2, 2])
    c = math.atan2(r[1, 0], r[1, 1])
    # a positive rotation about +x sends forward (z) towards -y, which is up: pitch up.
    return math.degrees(a), math.degrees(b), math.degrees(c)


def camera_attitude(cam_to_world: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, float, float]:
    """``(forward_ground, elevation_deg, bank_deg)`` of an OpenCV camera pose with gravity as reference.

    ``forward_ground``: the optical axis projected on the ground plane (unit; zero when it is
    vertical); ``elevation_deg``: the optical axis's angle above the horizon (+ = looking up);
    ``bank_deg``: the camera's rotation about its optical axis away from level, + = its right
    axis dips towards the ground (the image turns clockwise as the photographer sees it). A
    level camera's right axis is ``forward × up``, horizontal.
    """
    pose = np.asarray(cam_to_world, dtype=np.float64)
    u = np.asarray(up, dtype=np.float64)
    u = u / np.linalg.norm(u)
    right, forward = pose[:3, 0], pose[:3, 2]
    elevation = math.degrees(math.asin(float(np.clip(forward @ u, -1.0, 1.0))))
    flat = horizontal(forward, u)
    norm = float(np.linalg.norm(flat))
    if norm <= 1e-12:
        return np.zeros(3), elevation, 0.0
    level_right = cross3(forward, u)
    level_right /= np.linalg.norm(level_right)
    level_down = cross3(forward, level_right)
    bank = math.degrees(math.atan2(float(right @ level_down), float(right @ level_right)))
    return flat / norm, elevation, bank


def _wrap180(angle: float) -> float:
    """``angle`` degrees wrapped to (-180, 180]."""
    a = (float(angle) + 180.0) % 360.0 - 180.0
    return 180.0 if a == -180.0 else a


def gravity_rotation(cam_a: Camera, cam_b: Camera, up: np.ndarray) -> tuple[float, float, float]:
    """``(yaw, pitch, roll)`` degrees of the camera motion from A to B **as a person perceives it**
    (gravity-aware reading; :func:`camera_attitude` of each camera, then :func:`attitude_change`):

    - ``yaw``: the change of heading about ``up`` (+ = turned right, clockwise seen from above),
      wrapped to (-180, 180];
    - ``pitch``: the change of elevation of the optical axis (+ = tilted up);
    - ``roll``: the change of bank (+ = rolled clockwise), wrapped to (-180, 180].

    Panning a tilted camera about the vertical is a pure yaw here, whereas the camera-frame
    Euler angles of ``R_a^T R_b`` (:func:`euler_yaw_pitch_roll`) also show a few degrees of
    "roll" and "tilt" nobody perceives. For a level camera A both readings agree exactly.
    Heading and bank are ill-defined for a camera looking (nearly) straight up or down:
    callers skip large elevations.
    """
    return attitude_change(camera_attitude(cam_a.cam_to_world, up), camera_attitude(cam_b.cam_to_world, up), up)


def attitude_change(
    attitude_a: tuple[np.ndarray, float, float], attitude_b: tuple[np.ndarray, float, float], up: np.ndarray,
    headings: tuple[Heading | None, Heading | None] | None = None,
) -> tuple[float, float, float]:
    """:func:`gravity_rotation` from the two cameras' :func:`camera_attitude` about ``up`` (for a
    caller that has each view's attitude already): ``(yaw, pitch, roll)`` degrees. ``headings``:
    the two attitudes' :func:`heading` when the caller keeps them per view (the same numbers,
    not computed again for every pair)."""
    (fa, ea, ba), (fb, eb, bb) = attitude_a, attitude_b
    if headings is None:
        yaw = 0.0 if not (fa.any() and fb.any()) else _wrap180(ground_angle(fa, fb, up))
    else:
        ha, hb = headings  # = ground_angle(fa, fb, up): angle_on_ground(ground_axes(fa, up), horizontal(fb, up))
        yaw = 0.0 if ha is None or hb is None else _wrap180(angle_on_ground(ha[0], hb[1]))
    return yaw, eb - ea, _wrap180(bb - ba)


#: A camera's heading as :func:`attitude_change` reads it: its :func:`ground_axes` and its :func:`horizontal` projection.
Heading = tuple[tuple[np.ndarray, np.ndarray], np.ndarray]


def heading(attitude: tuple[np.ndarray, float, float], up: np.ndarray) -> Heading | None:
    """The :data:`Heading` of a :func:`camera_attitude` about ``up``, or ``None`` for a camera without
    one (looking straight up or down: its yaw is 0), for :func:`attitude_change`'s ``headings``."""
    forward = attitude[0]
    if not forward.any():
        return None
    u = np.asarray(up, dtype=np.float64)
    return ground_axes(forward, u), horizontal(forward, u)


# ------------------------------------------------------ dominant-part words
def dominant_parts(components: Sequence[float], ratio: float = TAN30, max_parts: int = MAX_PARTS) -> list[tuple[int, int]]:
    """``[(axis, sign), ...]`` of the components that name a direction, largest first.

    The largest |component| always names the first part; each further one joins only when
    ``|c| >= ratio * max|c|``, up to ``max_parts``. ``sign`` is +1 or -1. Empty for a zero vector.
    """
    values = np.asarray(components, dtype=np.float64).tolist()  # plain floats: the same values, cheaper to compare
    mags = [abs(v) for v in values]
    if not all(math.isfinite(m) for m in mags):
        return []  # as numpy's max, which a NaN or an infinity makes non-finite
    top = max(mags) if mags else 0.0
    if top <= 0.0:
        return []
    order = sorted(range(len(values)), key=lambda i: (-mags[i], i))
    parts = [(i, 1 if values[i] > 0 else -1) for i in order if mags[i] >= ratio * top]
    return parts[:max_parts]


def parts_label(parts: Sequence[tuple[int, int]], words: Sequence[tuple[str, str]], sep: str = "-") -> str:
    """``"right-up"`` from ``[(0, +1), (1, -1)]`` with :data:`CAMERA_MOTION_WORDS`."""
    return sep.join(words[axis][0 if sign > 0 else 1] for axis, sign in parts)


def flipped_labels(parts: Sequence[tuple[int, int]], words: Sequence[tuple[str, str]], sep: str = "-") -> list[str]:
    """Labels with one or both parts flipped (never partially correct): 1 label for 1 part, 3 for 2."""
    parts = list(parts)
    out: list[str] = []
    for mask in range(1, 2 ** len(parts)):
        flipped = [(axis, -sign if mask >> k & 1 else sign) for k, (axis, sign) in enumerate(parts)]
        out.append(parts_label(flipped, words, sep))
    return out


def single_word_pool(words: Sequence[tuple[str, str]], exclude_axes: Sequence[int] = ()) -> list[str]:
    """Every one-word label of axes not in ``exclude_axes`` (positive then negative)."""
    return [w for axis, pair in enumerate(words) if axis not in exclude_axes for w in pair]


#: Letter decks of recently used generators, most recent last: (id(rng), options) → its deck (which keeps rng alive).
_DECKS: OrderedDict[tuple[int, int], BalancedDeck] = OrderedDict()
_MAX_DECKS = 256


def _next_letter(rng: np.random.Generator, n_options: int = 4) -> int:
    """Index of the next correct letter for ``rng``: shuffled blocks of A–D (A–C for three
    options), so over any generation the correct letter is uniform to within one block (exact balance)."""
    key = (id(rng), n_options)
    deck = _DECKS.get(key)
    if deck is None or deck.rng is not rng:
        deck = _DECKS[key] = BalancedDeck(rng, n_options)
        while len(_DECKS) > _MAX_DECKS:
            _DECKS.popitem(last=False)
    _DECKS.move_to_end(key)
    return deck.next()


class BalancedDeck:
    """Draws ``0 … k-1`` in shuffled blocks of ``k`` from its own generator, so any prefix of
    ``n`` draws holds each value ``n/k`` times to within one block: exact balance, seeded.

    Families whose records each use a private child generator keep one deck per sub type
    and pass ``slot=deck.next()`` to :func:`build_mcq` (or use it for a yes/no side).
    """

    def __init__(self, rng: np.random.Generator, k: int = 4) -> None:
        self.rng = rng
        self.k = k
        self._left: list[int] = []

    def next(self) -> int:
        if not self._left:
            self._left = shuffled(range(self.k), self.rng)  # = rng.permutation(k)
        return self._left.pop()


def build_mcq(
    truth: str, distractors: Sequence[str], rng: np.random.Generator, slot: int | None = None, n_options: int = 4,
) -> tuple[tuple[str, ...], str]:
    """``n_options`` (4, or 3 where only three answers are possible) ``"A. text"`` option lines
    and the correct letter.

    ``distractors`` are the candidates in preference order; the first ``n_options − 1`` distinct
    ones that differ from ``truth`` are used, in an order shuffled by ``rng``. The correct letter is
    ``slot`` (0 … n_options − 1) when given, else it comes from a deck of shuffled A–D (A–C) blocks drawn from the
    same ``rng`` (one deck per generator and option count), so the letters of one family's generation are
    balanced exactly, not only in expectation; the sequence is still a pure function of the seed.
    Raises :class:`InvalidDataError` if too few usable distractors exist.
    """
    if n_options not in MCQ_OPTION_COUNTS:
        raise InvalidDataError(f"build_mcq: n_options must be one of {list(MCQ_OPTION_COUNTS)}, got {n_options!r}")
    need = n_options - 1
    others: list[str] = []
    for text in distractors:
        if text != truth and text not in others:
            others.append(text)
            if len(others) == need:
                break
    if len(others) < need:
        raise InvalidDataError(f"build_mcq: need {need} distractors different from {truth!r}, got {list(distractors)}")
    rng.shuffle(others)  # = [chosen[i] for i in rng.permutation(need)] (spacedg.seeding.shuffled, in place)
    if slot is None:
        slot = _next_letter(rng, n_options)
    elif slot not in range(n_options):
        raise InvalidDataError(f"build_mcq: slot must be 0-{need} (the correct letter's position), got {slot!r}")
    others.insert(slot, truth)
    if n_options == 4:  # written out: a third of the call's time went to the comprehension
        a, b, c, d = others
        return (f"{MCQ_LETTERS[0]}. {a}", f"{MCQ_LETTERS[1]}. {b}", f"{MCQ_LETTERS[2]}. {c}", f"{MCQ_LETTERS[3]}. {d}"), MCQ_LETTERS[slot]
    return tuple([f"{letter}. {text}" for letter, text in zip(MCQ_LETTERS, others)]), MCQ_LETTERS[slot]


# ---------------------------------------------------------------- ground plane
def horizontal(vector: np.ndarray, up: np.ndarray) -> np.ndarray:
    """``vector`` with its component along ``up`` removed (the ground-plane projection)."""
    v = np.asarray(vector, dtype=np.float64)
    u = np.asarray(up, dtype=np.float64)
    return v - float(v @ u) * u


def _ground_unit(vector: np.ndarray, up: np.ndarray, caller: str) -> np.ndarray:
    """``horizontal(vector, up)`` scaled to unit length; :class:`InvalidDataError` when it is (nearly) zero."""
    flat = horizontal(vector, up)
    norm = vector_length(flat)
    if norm <= 1e-12:
        raise InvalidDataError(f"{caller}: the reference direction is vertical; it has no direction on the ground")
    return flat / norm


def vertical_dominates(vector: np.ndarray, up: np.ndarray, factor: float = VERTICAL_FACTOR) -> bool:
    """True when ``|vertical part| >= factor * |horizontal part|`` (direction on the ground ill-defined)."""
    v = np.asarray(vector, dtype=np.float64)
    vertical = abs(float(v @ np.asarray(up, dtype=np.float64)))
    return vertical >= factor * vector_length(horizontal(v, up))


def ground_angle(forward: np.ndarray, vector: np.ndarray, up: np.ndarray) -> float:
    """Angle of ``vector`` on the ground plane from ``forward`` towards ``forward x up``, degrees in [0, 360).

    Both vectors are flattened on the ground plane first; 90 means "to the right" of
    ``forward`` seen from above (right-handed world, ``up`` against gravity).
    """
    u = np.asarray(up, dtype=np.float64)
    return angle_on_ground(ground_axes(forward, u), horizontal(vector, u))


def ground_axes(forward: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(f, right)``: ``forward`` flattened on the ground plane to unit length and ``f × up``
    (the axes :func:`ground_angle` measures in; ``up`` as given, float64)."""
    u = np.asarray(up, dtype=np.float64)
    f = _ground_unit(forward, u, "ground_angle")
    return f, cross3(f, u)


def angle_on_ground(axes: tuple[np.ndarray, np.ndarray], flat: np.ndarray) -> float:
    """:func:`ground_angle` of a vector already flattened (``flat = horizontal(vector, up)``) in
    :func:`ground_axes` ``axes``, degrees in [0, 360): for callers that reuse the axes or the flattened vector."""
    f, right = axes
    angle = math.degrees(math.atan2(float(flat @ right), float(flat @ f)))
    return angle % 360.0


def ground_leg(vector: np.ndarray, up: np.ndarray, min_horizontal_m: float = MIN_HORIZONTAL_M, factor: float = VERTICAL_FACTOR) -> dict[str, Any] | None:
    """``{"vector", "horizontal", "horizontal_m", "vertical_m"}`` of a leg (world metres), or ``None`` when it is skipped.

    ``horizontal`` is the ground-plane projection, ``horizontal_m`` its length, ``vertical_m``
    the signed component along ``up``. Skipped: horizontal length ``< min_horizontal_m``
    metres, or vertical-dominant (``|vertical| >= factor × horizontal``).
    """
    v = np.asarray(vector, dtype=np.float64)
    flat = horizontal(v, up)
    length = vector_length(flat)
    if length < min_horizontal_m or vertical_dominates(v, up, factor):
        return None
    vertical = float(v @ np.asarray(up, dtype=np.float64))
    return {"vector": v.tolist(), "horizontal": flat.tolist(), "horizontal_m": length, "vertical_m": vertical}


# ---------------------------------------------------------------- boxes
def boxes_intersect(a: OrientedBox, b: OrientedBox) -> bool:
    """True when the boxes overlap by more than :data:`INTERSECT_TOL_M` (1 mm) along every
    separating axis (:meth:`~spacedg.scene.box.OrientedBox.intersects`); touching boxes do not intersect.

    Memoised per pair of box objects (the same pairs recur in many views' candidates)."""
    key = (id(a), id(b))
    hit = _INTERSECTS.get(key)
    if hit is not None and hit[0] is a and hit[1] is b:
        return hit[2]
    if len(_INTERSECTS) >= 65_536:
        _INTERSECTS.clear()
    result = a.intersects(b, tol=INTERSECT_TOL_M)
    _INTERSECTS[key] = (a, b, result)
    return result


#: (id(a), id(b)) → (a, b, :func:`boxes_intersect`); the boxes are kept, so a reused id never hits.
_INTERSECTS: dict[tuple[int, int], tuple[OrientedBox, OrientedBox, bool]] = {}


# ---------------------------------------------------------------- sectors
@dataclass(frozen=True)
class SectorHit:
    """Where an angle falls: its label index, the distance to the nearest sector boundary (°),
    and the label index across that boundary (the near-boundary neighbour)."""

    index: int
    boundary_distance_deg: float
    neighbour: int


@dataclass(frozen=True)
class Sectors:
    """Eight labels around the ground plane; sector ``k`` spans ``[starts[k], starts[k+1])`` degrees.

    Angles are measured as in :func:`ground_angle` (clockwise seen from above from label 0's
    centre direction).
    """

    labels: tuple[str, ...]
    starts: tuple[float, ...]

    @functools.cached_property
    def _bounds(self) -> tuple[tuple[int, float, float], ...]:
        """``(k, lo, hi)`` of each sector: its start and the next sector's, in [0, 360) degrees."""
        n = len(self.labels)
        return tuple((k, self.starts[k] % 360.0, self.starts[(k + 1) % n] % 360.0) for k in range(n))

    def classify(self, angle_deg: float) -> SectorHit:
        a = float(angle_deg) % 360.0
        n = len(self.labels)
        for k, lo, hi in self._bounds:
            inside = lo <= a < hi if lo < hi else (a >= lo or a < hi)
            if inside:
                to_lo = (a - lo) % 360.0
                to_hi = (hi - a) % 360.0
                if to_lo <= to_hi:
                    return SectorHit(k, to_lo, (k - 1) % n)
                return SectorHit(k, to_hi, (k + 1) % n)
        raise AssertionError("sectors do not cover the circle")  # pragma: no cover

    def distractors(self, hit: SectorHit, rng: np.random.Generator, guard_deg: float = BOUNDARY_GUARD_DEG) -> list[str]:
        """The other labels in a seeded order, without the near-boundary neighbour when within ``guard_deg``."""
        pool = self._others[hit.index, hit.neighbour if hit.boundary_distance_deg < guard_deg else hit.index]
        return shuffled(pool, rng)  # = [pool[i] for i in rng.permutation(len(pool))]

    @functools.cached_property
    def _others(self) -> dict[tuple[int, int], tuple[str, ...]]:
        """``(index, banned)`` → the labels other than those two, in label order."""
        n = len(self.labels)
        return {(i, j): tuple(label for k, label in enumerate(self.labels) if k not in (i, j)) for i in range(n) for j in range(n)}


#: Relative position around a person: eight 45° sectors centred on front, front-right, …
RELPOS_SECTORS = Sectors(
    ("front", "front-right", "right", "back-right", "back", "back-left", "left", "front-left"),
    tuple((-22.5 + 45.0 * k) % 360.0 for k in range(8)),
)
#: Compass labels by the 0.5774 rule on (north, east): cardinals ±30°, diagonals the 30° between.
COMPASS_SECTORS = Sectors(
    ("north", "northeast", "east", "southeast", "south", "southwest", "west", "northwest"),
    (330.0, 30.0, 60.0, 120.0, 150.0, 210.0, 240.0, 300.0),
)


def on_compass_boundary(hit: SectorHit) -> bool:
    """Whether a compass hit lies within :data:`COMPASS_RULE_BAND_DEG` of a sector boundary, where
    its label depends on the reading of the rule (such a question is not asked)."""
    return hit.boundary_distance_deg < COMPASS_RULE_BAND_DEG


#: The four cardinal labels (the assumed direction of compass questions is one of them).
CARDINALS: tuple[str, ...] = ("north", "east", "south", "west")


# ---------------------------------------------------------------- compass frame
#: (cos, sin) of 0°, 90°, 180°, 270°: exact, so the frame has no rounding from trigonometry.
_QUARTER_TURNS: tuple[tuple[float, float], ...] = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))


def compass_frame(reference: np.ndarray, assumed_dir: str, up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(north, east)`` unit ground vectors such that ``reference`` points towards ``assumed_dir``.

    ``assumed_dir`` is one of :data:`CARDINALS` at ``90·k`` degrees clockwise from north (seen
    from above). With ``f = horizontal(reference)/|…|`` and ``r = f × up`` (f's right):
    ``north = cos(90k) f − sin(90k) r`` (f turned back by 90k), ``east = north × up``. So
    ``ground_angle(north, reference, up) == 90k``. World metres; ``up`` is normalised first.
    Raises :class:`InvalidDataError` when ``reference`` has no ground component.
    """
    if assumed_dir not in CARDINALS:  # before the basis: a bad cardinal is named whatever the reference
        raise InvalidDataError(f"compass_frame: assumed_dir must be one of {CARDINALS}, got {assumed_dir!r}")
    return compass_turn(compass_basis(reference, up), assumed_dir)


def compass_basis(reference: np.ndarray, up: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(u, f, r)``: ``up`` normalised, ``reference`` flattened on the ground to unit length and
    ``f × u``: the part of :func:`compass_frame` that does not depend on the assumed cardinal
    (a caller asking several cardinals of one reference computes it once)."""
    u = np.asarray(up, dtype=np.float64)
    u = u / np.linalg.norm(u)
    f = _ground_unit(reference, u, "compass_frame")
    return u, f, cross3(f, u)


def compass_turn(basis: tuple[np.ndarray, np.ndarray, np.ndarray], assumed_dir: str) -> tuple[np.ndarray, np.ndarray]:
    """:func:`compass_frame`'s ``(north, east)`` from :func:`compass_basis`' ``basis``; raises
    :class:`InvalidDataError` for an ``assumed_dir`` not in :data:`CARDINALS`."""
    if assumed_dir not in CARDINALS:
        raise InvalidDataError(f"compass_turn: assumed_dir must be one of {CARDINALS}, got {assumed_dir!r}")
    u, f, r = basis
    c, s = _QUARTER_TURNS[CARDINALS.index(assumed_dir)]
    north = c * f - s * r
    return north, cross3(north, u)


def compass_answer(reference: np.ndarray, assumed_dir: str, query: np.ndarray, up: np.ndarray) -> tuple[str, float, SectorHit, np.ndarray, np.ndarray]:
    """``(label, angle_deg, hit, north, east)`` of ``query`` in the frame where ``reference`` points to ``assumed_dir``.

    ``angle_deg`` is :func:`ground_angle` from north (clockwise seen from above, [0, 360));
    ``label``/``hit`` are its :data:`COMPASS_SECTORS` classification (the 0.5774 rule).
    """
    north, east = compass_frame(reference, assumed_dir, up)
    angle = ground_angle(north, query, up)
    hit = COMPASS_SECTORS.classify(angle)
    return COMPASS_SECTORS.labels[hit.index], angle, hit, north, east
