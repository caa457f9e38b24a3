"""Up is verified, never assumed: the evidence a capture has about which way is up.

Whatever up an import uses (given by ``--up``, a layout's convention such as ScanNet++'s +z, or
estimated from the cameras), :func:`decide_up` gathers three kinds of evidence and decides
whether they support or contradict it:

* **cameras** (strong, sign-aware): handheld, tripod and robot cameras keep the image's up
  direction near world up. For an OpenCV camera (x right, y down, z forward) the image's up in
  world coordinates is ``-R[:, 1]`` of its camera-to-world rotation. Their mean vector gives a
  direction and a resultant length in [0, 1] (1: all views agree); the share of views within 30°
  of each signed axis is recorded too. Views looking along the candidate up (a nadir capture)
  carry no information about it and make the cameras undecided.
* **floor** (medium, sign-aware): furniture rests on a floor and small objects on a table, so
  the boxes' lowest points along the true up share one level, while their highest points do
  not. The densest horizontal slab of Gaussians at the low end of the heights (a floor) is
  recorded when Gaussians are given; it decides alone only when fewer than 3 boxes exist.
* **box axes** (axis only): oriented boxes of furniture usually have one axis along up.

Everything is relative (shares, ratios, tolerances as fractions of the scene's extent), so the
evidence holds for captures of unknown units. The cameras decide when they can; otherwise the
floor; otherwise the box axes (which can only reject a wrong axis, never a wrong sign). A
contradicted up raises :class:`UpContradictedError` naming the evidence and the fix (the
supported up, or ``trust=True`` / ``--trust-up``, which keeps it and records the override); an
``auto`` up that nothing decides raises :class:`UpUndecidedError`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.render.camera import Camera
from spacedg.scene.model import Instance, Scene

__all__ = [
    "AXES", "MIN_UP_AGREEMENT", "BoxAxesEvidence", "CameraEvidence", "FloorEvidence", "UpContradictedError", "UpEvidence", "UpUndecidedError",
    "axis_name", "camera_evidence", "level_up", "refine_up", "upright_boxes_up", "box_axes_evidence", "box_up_axes", "estimate_up", "decide_up", "evidence_report", "floor_evidence", "gather_up_evidence",
    "scene_up_evidence",
]

#: The six signed world axes, by name.
AXES: dict[str, np.ndarray] = {
    f"{s}{a}": (1.0 if s == "+" else -1.0) * np.eye(3)[i] for a, i in (("x", 0), ("y", 1), ("z", 2)) for s in "+-"
}
#: Smallest length of the mean camera −y axis accepted as an up estimate (1 = all agree).
MIN_UP_AGREEMENT = 0.5
#: Cameras decide only when their image-up vectors' resultant length reaches this (estimate_up's own threshold).
MIN_RESULTANT = MIN_UP_AGREEMENT
#: Cameras support an up within this angle of their mean image-up, and contradict it beyond CONTRADICT_DEG, degrees.
SUPPORT_DEG, CONTRADICT_DEG = 30.0, 60.0
#: A view is "within" an axis when its image-up is within this angle of it, degrees.
WITHIN_DEG = 30.0
#: A box "rests" on the common lowest level when its bottom is within this share of the boxes' extent along up.
REST_TOLERANCE = 0.03
#: A box has an axis "along" a direction when the angle is under this, degrees.
BOX_AXIS_DEG = 10.0


class UpContradictedError(InvalidDataError):
    """The up an import would use is contradicted by the capture's evidence (``evidence`` attached)."""

    def __init__(self, message: str, evidence: UpEvidence) -> None:
        super().__init__(message)
        self.evidence = evidence


class UpUndecidedError(InvalidDataError):
    """``up="auto"`` and no evidence decides which way is up (``evidence`` attached when gathered)."""

    def __init__(self, message: str, evidence: UpEvidence | None = None) -> None:
        super().__init__(message)
        self.evidence = evidence


def axis_name(vector: Sequence[float] | np.ndarray, tolerance_deg: float = 15.0) -> str:
    """``"+z"``-style name of the signed axis within ``tolerance_deg`` of ``vector``, else ``"x,y,z"`` (3 decimals),
    as ``--up`` takes it."""
    v = np.asarray(vector, dtype=np.float64)
    v = v / max(float(np.linalg.norm(v)), 1e-12)
    for name, axis in AXES.items():
        if float(v @ axis) >= math.cos(math.radians(tolerance_deg)):
            return name
    return ",".join(f"{x:.3f}" for x in v)


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle between two vectors, degrees."""
    na, nb = float(np.linalg.norm(a)), float(np.linalg.norm(b))
    if na == 0 or nb == 0:
        return 180.0
    return math.degrees(math.acos(max(-1.0, min(1.0, float(a @ b) / (na * nb)))))


# --------------------------------------------------------------------------- evidence records
@dataclass(frozen=True)
class CameraEvidence:
    """What the cameras' image-up vectors (``-R[:, 1]`` of cam-to-world) say about a candidate up.

    Attributes:
        views: number of cameras.
        mean_up: unit direction of the mean image-up vector (files' frame).
        resultant: length of the mean image-up vector, 0 (all directions) … 1 (all views agree).
        angle_deg: angle between ``mean_up`` and the candidate up, degrees.
        within: share of views whose image-up is within :data:`WITHIN_DEG` of each signed axis and of ``"up"`` (the candidate).
        looking_along_up: share of views whose viewing direction is within 30° of ± the candidate (nadir views).
        verdict: ``"supports"``, ``"contradicts"``, ``"tilted"`` (between the two angles) or ``"undecided"``.
        reason: one phrase saying why.
    """

    views: int
    mean_up: tuple[float, float, float]
    resultant: float
    angle_deg: float
    within: dict[str, float]
    looking_along_up: float
    verdict: str
    reason: str


@dataclass(frozen=True)
class FloorEvidence:
    """What the boxes' bottoms and the Gaussians' heights say about the sign of a candidate up.

    Attributes:
        boxes: number of boxes.
        resting_up: boxes whose lowest point along up is on the common lowest level (within :data:`REST_TOLERANCE`).
        resting_down: the same along -up (boxes whose tops share the highest level).
        slab_low, slab_high: density of the densest height bin in the lowest / highest quarter of the Gaussians'
            heights along up, relative to a uniform spread (``None`` without Gaussians).
        floor_height: height of the low slab along up, file units (``None`` without Gaussians).
        cameras_above: share of camera centres above ``floor_height`` (``None`` without Gaussians).
        verdict: ``"supports"``, ``"contradicts"`` or ``"undecided"``; ``reason`` says why.
    """

    boxes: int
    resting_up: int
    resting_down: int
    slab_low: float | None
    slab_high: float | None
    floor_height: float | None
    cameras_above: float | None
    verdict: str
    reason: str


@dataclass(frozen=True)
class BoxAxesEvidence:
    """What the oriented boxes' own axes say about the axis (not the sign) of a candidate up.

    Attributes:
        boxes: number of boxes.
        along_up: share of boxes with an axis within :data:`BOX_AXIS_DEG` of the candidate's line.
        other_axis: the world axis (``"x"``, ``"y"``, ``"z"``) far from the candidate that most boxes have an axis along.
        along_other: that share.
        verdict: ``"supports"``, ``"contradicts"`` or ``"undecided"``; ``reason`` says why.
    """

    boxes: int
    along_up: float
    other_axis: str | None
    along_other: float
    verdict: str
    reason: str


@dataclass
class UpEvidence:
    """The evidence about one candidate up and the decision taken on it.

    Attributes:
        up: the candidate up (unit vector, files' frame).
        source: where it came from (``"given"``, a layout's convention, ``"estimated ..."``).
        cameras, floor, box_axes: the three kinds of evidence.
        decision: ``"supported"``, ``"contradicted"``, ``"overridden"`` (contradicted, kept by ``trust``)
            or ``"unverified"`` (nothing decides).
        decided_by: ``"cameras"``, ``"floor"``, ``"box axes"`` or ``None``.
        supported: the up the deciding evidence supports, as ``--up`` takes it (``None`` when undecided).
        notes: conflicts between kinds of evidence that did not decide.
    """

    up: tuple[float, float, float]
    source: str
    cameras: CameraEvidence
    floor: FloorEvidence
    box_axes: BoxAxesEvidence
    decision: str = "unverified"
    decided_by: str | None = None
    supported: str | None = None
    notes: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready record (what ``scene.json`` keeps under ``metadata.up_evidence``)."""
        out = asdict(self)
        out["up"] = [round(float(v), 6) for v in self.up]
        return _rounded(out)

    def summary(self) -> str:
        """One line: decision, by what, and the cameras' numbers."""
        return _summary(self.to_dict())

    def report(self) -> str:
        """A short human-readable report, one kind of evidence per line (:func:`evidence_report`)."""
        return evidence_report(self.to_dict())


def _rounded(value: Any) -> Any:
    if isinstance(value, float):
        return round(value, 4)
    if isinstance(value, dict):
        return {k: _rounded(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_rounded(v) for v in value]
    return value


# --------------------------------------------------------------------------- gathering
def _image_ups(views: Mapping[str, Camera]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per view: image-up (−y) and viewing direction (+z) in world, and the centre; (N, 3) each."""
    poses = np.array([np.asarray(c.cam_to_world, dtype=np.float64) for c in views.values()]).reshape(-1, 4, 4)
    return -poses[:, :3, 1], poses[:, :3, 2], poses[:, :3, 3]


def camera_evidence(views: Mapping[str, Camera], up: np.ndarray) -> CameraEvidence:
    """The cameras' verdict on ``up`` (a unit vector); see :class:`CameraEvidence`."""
    ups, forwards, _ = _image_ups(views)
    n = len(ups)
    if n == 0:
        return CameraEvidence(0, (0.0, 0.0, 0.0), 0.0, 180.0, {}, 0.0, "undecided", "no cameras")
    cos_within = math.cos(math.radians(WITHIN_DEG))
    within = {name: float(np.mean(ups @ axis >= cos_within)) for name, axis in AXES.items()}
    within["up"] = float(np.mean(ups @ up >= cos_within))
    mean = ups.mean(axis=0)
    resultant = float(np.linalg.norm(mean))
    direction = mean / resultant if resultant > 0 else mean
    angle = _angle(mean, up)
    nadir = float(np.mean(np.abs(forwards @ up) >= cos_within))
    if nadir >= 0.5:
        verdict = "undecided"
        reason = f"{nadir:.0%} of the views look along the candidate up (a top-down capture): their image-up says nothing about it"
    elif resultant < MIN_RESULTANT:
        verdict, reason = "undecided", f"their image-up vectors point all over (resultant {resultant:.2f} < {MIN_RESULTANT})"
    elif angle <= SUPPORT_DEG:
        verdict, reason = "supports", f"their mean image-up is {angle:.0f}° from it"
    elif angle >= CONTRADICT_DEG:
        verdict, reason = "contradicts", f"their mean image-up is {angle:.0f}° from it, along {axis_name(direction)}"
    else:
        verdict, reason = "tilted", f"their mean image-up is {angle:.0f}° from it (between {SUPPORT_DEG:.0f}° and {CONTRADICT_DEG:.0f}°)"
    return CameraEvidence(n, tuple(float(v) for v in direction), resultant, angle, within, nadir, verdict, reason)  # type: ignore[arg-type]


def _box_heights(instances: Sequence[Instance], up: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Lowest and highest point of every box along ``up``."""
    if not instances:
        return np.zeros(0), np.zeros(0)
    heights = np.array([inst.box.corners() @ up for inst in instances])
    return heights.min(axis=1), heights.max(axis=1)


def _slabs(means: np.ndarray, up: np.ndarray, bins: int = 40) -> tuple[float, float, float]:
    """(low slab density, high slab density, low slab height): the densest bin of the lowest and highest quarter
    of the Gaussians' heights (1st–99th percentile range), relative to a uniform spread."""
    h = means.astype(np.float64) @ up
    lo, hi = np.percentile(h, [1.0, 99.0])
    if not hi > lo:
        return 1.0, 1.0, float(lo)
    counts, edges = np.histogram(h, bins=bins, range=(lo - 0.01 * (hi - lo), hi + 0.01 * (hi - lo)))
    density = counts / max(counts.sum(), 1) * bins
    q = bins // 4
    k = int(np.argmax(density[:q]))
    return float(density[:q].max()), float(density[-q:].max()), float(0.5 * (edges[k] + edges[k + 1]))


def floor_evidence(
    instances: Sequence[Instance], up: np.ndarray, means: np.ndarray | None = None, centres: np.ndarray | None = None,
) -> FloorEvidence:
    """The floor's verdict on the sign of ``up``; see :class:`FloorEvidence`. ``means``: Gaussian centres (N, 3),
    optional; ``centres``: camera centres (M, 3), optional."""
    bottoms, tops = _box_heights(instances, up)
    n = len(bottoms)
    resting_up = resting_down = 0
    if n:
        tol = REST_TOLERANCE * max(float(tops.max() - bottoms.min()), 1e-12)
        resting_up = int(np.sum(bottoms - bottoms.min() <= tol))
        resting_down = int(np.sum(tops.max() - tops <= tol))
    slab_low = slab_high = floor_h = above = None
    if means is not None and len(means):
        slab_low, slab_high, floor_h = _slabs(np.asarray(means), up)
        if centres is not None and len(centres):
            above = float(np.mean(np.asarray(centres) @ up > floor_h))
    verdict, reason = "undecided", "fewer than 3 boxes and no dense floor slab"
    if n >= 3:
        reason = f"{resting_up} of {n} boxes rest on one lowest level along it, {resting_down} share one highest level"
        if resting_up >= 3 and resting_up >= 2 * resting_down:
            verdict = "supports"
        elif resting_down >= 3 and resting_down >= 2 * resting_up:
            verdict = "contradicts"
    elif slab_low is not None and slab_high is not None:
        reason = f"densest Gaussian slab {slab_low:.1f}× uniform at the low end, {slab_high:.1f}× at the high end"
        if slab_low >= 3.0 and slab_low >= 1.5 * slab_high:
            verdict = "supports"
        elif slab_high >= 3.0 and slab_high >= 1.5 * slab_low:
            verdict = "contradicts"
    return FloorEvidence(n, resting_up, resting_down, slab_low, slab_high, floor_h, above, verdict, reason)


def estimate_up(views: Mapping[str, Camera]) -> np.ndarray:
    """Up estimated as the normalised mean of the cameras' −y axes (image "up" in the world).

    Photographs are mostly taken upright, so the image's up direction averages to gravity's.
    Raises when there are no cameras or their up axes disagree (mean length <
    :data:`MIN_UP_AGREEMENT`), e.g. for a camera looking straight down: pass ``up`` then.
    """
    if not views:
        raise InvalidDataError("cannot estimate up without cameras; pass up=(x, y, z)")
    axes = np.array([-cam.cam_to_world[:3, 1] for cam in views.values()])
    mean = axes.mean(axis=0)
    norm = float(np.linalg.norm(mean))
    if norm < MIN_UP_AGREEMENT:
        raise InvalidDataError(
            f"cannot estimate up: the {len(views)} cameras' up axes disagree (mean length {norm:.2f} < {MIN_UP_AGREEMENT}); pass up=(x, y, z)"
        )
    return mean / norm


#: The cameras' x axes must spread this much in yaw (second eigenvalue of their scatter) to define a level plane.
MIN_LEVEL_SPREAD = 0.05
#: ... and lie this close to one plane (smallest eigenvalue: ~sin² of their typical roll; 0.03 is about 10°).
MAX_LEVEL_ROLL = 0.03
#: A refinement (level plane or box axes) is taken only within this angle of the mean image-up, in degrees.
MAX_REFINE_DEG = 20.0


def level_up(views: Mapping[str, Camera], up: np.ndarray) -> np.ndarray | None:
    """Up as the normal of the plane the cameras' x axes lie in, signed like ``up``; ``None`` when undetermined.

    People and robots hold cameras level (little roll) while pitching them freely, so the image x axis stays
    horizontal while the image-up (−y) tilts with the pitch: the mean image-up of cameras looking down at a
    table leans towards their viewing direction by the mean pitch, the x axes' plane does not. Needs x axes
    that spread in yaw (:data:`MIN_LEVEL_SPREAD`) and lie near one plane (:data:`MAX_LEVEL_ROLL`), and a
    normal within :data:`MAX_REFINE_DEG` of ``up``."""
    if len(views) < 3:
        return None
    x_axes = np.array([np.asarray(c.cam_to_world, dtype=np.float64)[:3, 0] for c in views.values()])
    x_axes = x_axes / np.linalg.norm(x_axes, axis=1, keepdims=True)
    values, vectors = np.linalg.eigh(x_axes.T @ x_axes / len(x_axes))
    if not (values[1] >= MIN_LEVEL_SPREAD and values[0] <= MAX_LEVEL_ROLL):
        return None
    normal = vectors[:, 0] * (1.0 if float(vectors[:, 0] @ up) >= 0.0 else -1.0)
    return normal if _angle(normal, up) <= MAX_REFINE_DEG else None


def upright_boxes_up(instances: Sequence[Instance], up: np.ndarray) -> np.ndarray | None:
    """The mean of the boxes' axes nearest ``up`` when they agree (at least 60 % within 5° of their mean,
    the mean within :data:`MAX_REFINE_DEG` of ``up``), else ``None``: annotated boxes stand upright, so each
    has an axis along gravity, usually far more exactly than any camera estimate."""
    axes = box_up_axes(instances, up)
    mean = np.sum(axes, axis=0)
    if not np.linalg.norm(mean) > 0:
        return None
    mean = mean / np.linalg.norm(mean)
    close = axes @ mean >= math.cos(math.radians(5.0))
    return mean if _angle(mean, up) <= MAX_REFINE_DEG and close.mean() >= 0.6 else None


def refine_up(views: Mapping[str, Camera], instances: Sequence[Instance], up: np.ndarray) -> tuple[np.ndarray, str]:
    """An estimated ``up`` (the cameras' mean image-up) made exact where the capture allows, and how:
    the boxes' upright axes when they agree (:func:`upright_boxes_up`), else the cameras' level plane
    (:func:`level_up`), else ``up`` unchanged."""
    boxes = upright_boxes_up(instances, up)
    if boxes is not None:
        return boxes, f"the upright axes of {len(instances)} boxes"
    level = level_up(views, up)
    if level is not None:
        return level, f"the plane of {len(views)} cameras' level x axes"
    return up, f"the mean -y axis of {len(views)} cameras"


def box_up_axes(instances: Sequence[Instance], up: np.ndarray) -> np.ndarray:
    """(n, 3): every box's own axis nearest the line of ``up`` (a unit vector), signed to point along ``up``.

    The one place the boxes' axes are matched to an up: :func:`box_axes_evidence` counts how many lie along
    a line, :func:`upright_boxes_up` refines an estimated up with their mean."""
    if not instances:
        return np.zeros((0, 3))
    rotations = np.array([inst.box.rotation for inst in instances])  # (n, 3, 3), columns = box axes
    dots = np.einsum("nij,i->nj", rotations, np.asarray(up, dtype=np.float64))
    rows = np.arange(len(rotations))
    nearest = np.argmax(np.abs(dots), axis=1)
    signs = np.where(dots[rows, nearest] < 0.0, -1.0, 1.0)
    return rotations[rows, :, nearest] * signs[:, None]


def box_axes_evidence(instances: Sequence[Instance], up: np.ndarray) -> BoxAxesEvidence:
    """The boxes' own axes' verdict on the axis of ``up``; see :class:`BoxAxesEvidence`."""
    if not instances:
        return BoxAxesEvidence(0, 0.0, None, 0.0, "undecided", "no boxes")
    cos_along = math.cos(math.radians(BOX_AXIS_DEG))

    def share(direction: np.ndarray) -> float:
        return float(np.mean(box_up_axes(instances, direction) @ direction >= cos_along))

    along = share(up)
    others = [(share(np.eye(3)[i]), "xyz"[i]) for i in range(3) if abs(float(up[i])) < math.cos(math.radians(45.0))]
    along_other, other = max(others) if others else (0.0, None)
    n = len(instances)
    reason = f"{along:.0%} of {n} boxes have an axis along its line (axis only, not the sign)"
    reason += f", {along_other:.0%} along {other}" if other else ""
    if along >= 0.6 and along >= along_other + 0.3:
        verdict = "supports"
    elif along_other >= 0.6 and along <= 0.3:
        verdict = "contradicts"
    else:
        verdict = "undecided"
    return BoxAxesEvidence(n, along, other, along_other, verdict, reason)


def gather_up_evidence(
    views: Mapping[str, Camera], instances: Sequence[Instance], up: Sequence[float] | np.ndarray, *,
    means: np.ndarray | None = None, source: str = "given",
) -> UpEvidence:
    """All the evidence about ``up`` and the decision (without raising): cameras decide when they can, else the
    floor, else the box axes (a different axis only). ``means``: Gaussian centres (N, 3), optional."""
    g = np.asarray(up, dtype=np.float64)
    g = g / float(np.linalg.norm(g))
    _, _, centres = _image_ups(views)
    ev = UpEvidence(tuple(float(v) for v in g), source, camera_evidence(views, g),  # type: ignore[arg-type]
                    floor_evidence(instances, g, means, centres), box_axes_evidence(instances, g))
    if ev.cameras.verdict in ("supports", "contradicts"):
        ev.decided_by = "cameras"
        ev.decision = "supported" if ev.cameras.verdict == "supports" else "contradicted"
        ev.supported = axis_name(g) if ev.decision == "supported" else axis_name(ev.cameras.mean_up)
    elif ev.floor.verdict in ("supports", "contradicts"):
        ev.decided_by = "floor"
        ev.decision = "supported" if ev.floor.verdict == "supports" else "contradicted"
        ev.supported = axis_name(g if ev.decision == "supported" else -g)
    elif ev.box_axes.verdict == "contradicts":
        ev.decided_by, ev.decision, ev.supported = "box axes", "contradicted", f"+{ev.box_axes.other_axis} or -{ev.box_axes.other_axis}"
    _note_conflicts(ev)
    return ev


def _note_conflicts(ev: UpEvidence) -> None:
    """Notes where evidence that did not decide disagrees with the decision (box axes judge the axis only)."""
    if ev.decided_by is None:
        return
    supported = ev.decision == "supported"
    if ev.decided_by != "floor" and ev.floor.verdict != "undecided" and (ev.floor.verdict == "supports") != supported:
        ev.notes.append(f"the floor {ev.floor.verdict} it ({ev.floor.reason}) against the {ev.decided_by}")
    if ev.decided_by != "box axes" and supported and ev.box_axes.verdict == "contradicts":
        ev.notes.append(f"the box axes contradict its axis ({ev.box_axes.reason}) against the {ev.decided_by}")


def scene_up_evidence(scene: Scene, *, with_gaussians: bool = True) -> UpEvidence:
    """The evidence about a loaded scene's own up (its views, boxes and, unless ``with_gaussians=False``, its
    Gaussians' heights), e.g. for a benchmark to print with :func:`evidence_report`. Never raises on a contradiction."""
    means = scene.gaussians.means if with_gaussians else None
    source = str(scene.metadata.get("up_source", "the scene's up"))
    return gather_up_evidence(scene.views, scene.instances, scene.up, means=means, source=source)


# --------------------------------------------------------------------------- deciding
def _fallback_up(views: Mapping[str, Camera], instances: Sequence[Instance], means: np.ndarray | None) -> np.ndarray | None:
    """An up from the boxes alone when the cameras cannot tell: the axis most boxes have, the sign the floor gives."""
    if not instances:
        return None
    _, _, centres = _image_ups(views)
    for axis in np.eye(3):
        if box_axes_evidence(instances, axis).verdict != "supports":
            continue
        for signed in (axis, -axis):
            if floor_evidence(instances, signed, means, centres).verdict == "supports":
                return signed
    return None


def _contradiction_message(ev: UpEvidence, where: str) -> str:
    given = axis_name(ev.up)
    return (
        f"{where}up {given} ({ev.source}) is contradicted by the capture's evidence (decided by the {ev.decided_by}):\n"
        f"{evidence_report(ev.to_dict())}\n"
        f"Fix: pass --up {ev.supported} (what the evidence supports), or --trust-up (trust_up=True) to write the scene "
        f"with up {given} anyway (scene.json records the override)"
    )


def decide_up(
    views: Mapping[str, Camera], instances: Sequence[Instance], *, given: np.ndarray | None,
    default: np.ndarray | None = None, default_note: str = "", means: np.ndarray | None = None,
    trust: bool = False, where: str = "",
) -> tuple[np.ndarray, str, UpEvidence]:
    """The up an import uses, its source, and the evidence about it.

    ``given`` (``--up``) wins, then ``default`` (a layout's convention, e.g. ScanNet++'s +z), then the
    cameras' mean image-up when they decide, then the boxes (axis from their own axes, sign from the
    floor). A given or default up that the evidence contradicts raises :class:`UpContradictedError`
    unless ``trust`` (then its decision reads ``"overridden"``); an estimate that nothing decides
    raises :class:`UpUndecidedError`.

    Args:
        views: cameras (OpenCV, cam-to-world), files' frame.
        instances: the boxes, files' frame.
        given: ``--up`` as a unit vector (``None``: auto).
        default, default_note: a layout's up and its description.
        means: Gaussian centres (N, 3), optional (the floor slab).
        trust: keep a contradicted up (the user overrides the evidence).
        where: prefix of error messages (e.g. the capture's path and ": ").
    """
    if given is not None or default is not None:
        up = np.asarray(given if given is not None else default, dtype=np.float64)
        if up.shape != (3,) or not np.isfinite(up).all() or not np.linalg.norm(up) > 0:
            raise ParameterError(f"{where}up {up.tolist()}: give three finite numbers, not all zero (e.g. 0,0,1)")
        source = "given" if given is not None else default_note
        ev = gather_up_evidence(views, instances, up, means=means, source=source)
        if ev.decision == "contradicted":
            if not trust:
                raise UpContradictedError(_contradiction_message(ev, where), ev)
            ev.decision = "overridden"
            ev.notes.append("contradicted, kept by --trust-up (the user overrode the evidence)")
        return up, source, ev
    probe = camera_evidence(views, np.array([0.0, 0.0, 1.0])) if views else None
    if probe is not None and probe.resultant >= MIN_RESULTANT:
        up, how = refine_up(views, instances, estimate_up(views))
        ev = gather_up_evidence(views, instances, up, means=means, source=f"estimated from {how}")
        if ev.cameras.verdict == "supports" and ev.box_axes.verdict != "contradicts":
            return up, ev.source, ev
        if ev.cameras.verdict == "supports":
            raise UpUndecidedError(
                f"{where}cannot decide up: the cameras' mean image-up is {axis_name(up)} (resultant {ev.cameras.resultant:.2f}) but "
                f"the boxes' axes reject that axis ({ev.box_axes.reason}); a top-down capture has image-up vectors that say nothing "
                f"about up. Pass --up with the axis that points up in the files (+{ev.box_axes.other_axis} or -{ev.box_axes.other_axis}?)",
                ev)
    fallback = _fallback_up(views, instances, means)
    if fallback is not None:
        ev = gather_up_evidence(views, instances, fallback, means=means, source="estimated from the boxes (cameras undecided)")
        return fallback, ev.source, ev
    ev = gather_up_evidence(views, instances, np.array([0.0, 0.0, 1.0]), means=means, source="auto")
    raise UpUndecidedError(
        f"{where}cannot decide up: the cameras are undecided ({ev.cameras.reason}) and the boxes give no axis and sign "
        f"(box axes: {ev.box_axes.reason}; floor: {ev.floor.reason}). Pass --up with the axis that points up in the files "
        "(+z, -y, ... or x,y,z)", ev)


# --------------------------------------------------------------------------- reports
def _summary(ev: Mapping[str, Any]) -> str:
    cams = ev["cameras"]
    by = f" by the {ev['decided_by']}" if ev.get("decided_by") else ""
    return (f"up {axis_name(ev['up'])} {ev['decision']}{by}; cameras: resultant {cams['resultant']:.2f}, "
            f"mean image-up {axis_name(cams['mean_up'])} {cams['angle_deg']:.0f}° away, "
            f"{cams['within'].get('up', 0.0):.0%} of {cams['views']} views within {WITHIN_DEG:.0f}°")


def evidence_report(evidence: UpEvidence | Mapping[str, Any]) -> str:
    """A short human-readable report of up evidence (an :class:`UpEvidence` or its ``to_dict()``, e.g. from
    ``scene.metadata["up_evidence"]``): the decision, then one line per kind of evidence with its numbers."""
    ev = evidence.to_dict() if isinstance(evidence, UpEvidence) else evidence
    cams, floor, axes = ev["cameras"], ev["floor"], ev["box_axes"]
    shares = ", ".join(f"{k} {v:.0%}" for k, v in cams["within"].items() if k != "up" and v > 0)
    lines = [
        f"up {axis_name(ev['up'])} ({ev['source']}): {ev['decision']}"
        + (f" by the {ev['decided_by']}" if ev.get("decided_by") else "")
        + (f"; the evidence supports {ev['supported']}" if ev.get("supported") and ev["decision"] != "supported" else ""),
        f"  cameras  {cams['verdict']}: {cams['reason']}; {cams['views']} views, mean image-up "
        f"{[round(v, 3) for v in cams['mean_up']]} (resultant {cams['resultant']:.2f}), within {WITHIN_DEG:.0f}°: "
        f"{shares or 'no axis'}",
        f"  floor    {floor['verdict']}: {floor['reason']}"
        + (f"; Gaussian slabs {floor['slab_low']:.1f}× (low) / {floor['slab_high']:.1f}× (high) uniform"
           if floor.get("slab_low") is not None and floor["boxes"] >= 3 else "")
        + (f", {floor['cameras_above']:.0%} of cameras above the low slab" if floor.get("cameras_above") is not None else ""),
        f"  box axes {axes['verdict']}: {axes['reason']}",
    ]
    lines += [f"  note     {n}" for n in ev.get("notes", [])]
    return "\n".join(lines)
