"""Units of an imported capture: stated, estimated from the scene itself, and checked.

Every import ends in a :class:`UnitDecision` that says what one file unit is in metres and how
that was decided (``how``, recorded in ``scene.json`` under ``metadata["units"]``):

``"metric"``
    metric by construction: the layout or the annotation is metric (:data:`METRIC_LAYOUTS`,
    :data:`METRIC_INSTANCE_FORMATS`: ScanNet++ laser scans, Holi-Spatial's metric-depth
    reconstructions, EmbodiedScan boxes), or the user stated it (``--units metric``). Not
    second-guessed: the estimate below is still reported.
``"given"``
    the user gave ``--metres-per-unit X``: applied, never refused (a disagreeing estimate is noted).
``"unknown"``
    COLMAP, INRIA, nerfstudio and bare Gaussian files have no metric scale: taken as 1 m per
    file unit **only when the scene's own evidence agrees**; otherwise the import is refused
    (:class:`UnitsImplausibleError`) with the estimate and the option to pass.

The evidence (:func:`estimate_units`, all in file units before any scaling):

- **Objects**: for each labelled box whose label has a typical size (:func:`units_lexicon`: the
  lexicon's sizes, extended by ``typical_sizes.json`` with ScanNet++ / ScanNet200's frequent
  indoor classes; a label not found is tried by its head noun, ``"wooden chair"`` → ``"chair"``,
  and otherwise ignored), ``r_i = typical longest side (m) / box longest side (units)``. The
  estimate is ``exp(median(log r_i))``; its spread is the factor ``exp(1.4826 · MAD(log r_i))``;
  an object *agrees* when its ``r_i`` is within :data:`AGREE_FACTOR` of the estimate. At least
  :data:`MIN_OBJECTS` objects are needed.
- **Camera height**: the floor is the lowest box bottom along ``up`` (refined by the boxes' own
  upright axes when they agree), found when at least
  :data:`MIN_FLOOR_BOXES` box bottoms lie within 10 % of the median box size of it; hand-held
  cameras are held :data:`CAMERA_HEIGHT_M` (1.2–1.7 m, centre 1.45 m) above it, so
  ``1.45 / median camera height (units)`` is a second estimate (reported; the objects decide).

Refusal (:meth:`UnitDecision.implausible`): units unknown, the object estimate differs from the
chosen metres per unit by more than :data:`REFUSE_FACTOR`, and at least :data:`MIN_OBJECTS`
objects, and at least half of them, agree with the estimate.
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

import numpy as np

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.render.camera import Camera
from spacedg.scene.lexicon import BUILTIN, LEXICON_ENV, Lexicon, head_noun, label_key, load_lexicon
from spacedg.scene.model import Instance, Scene
from spacedg.scene.up_evidence import upright_boxes_up

__all__ = [
    "AGREE_FACTOR", "CAMERA_HEIGHT_M", "METRIC_INSTANCE_FORMATS", "METRIC_LAYOUTS", "MIN_FLOOR_BOXES", "MIN_OBJECTS",
    "REFUSE_FACTOR", "TYPICAL_SIZES_FILE", "CameraHeightEvidence", "ObjectEvidence", "UnitDecision", "UnitEstimate",
    "UnitsImplausibleError", "decide_units", "estimate_scene_units", "estimate_units", "scene_units_line", "units_lexicon",
]

#: Layouts whose files are metric by construction → why.
METRIC_LAYOUTS: Mapping[str, str] = {
    "scannetpp": "ScanNet++ scenes are metric by construction (laser-scanner frame, metres)",
    "holi-spatial": "Holi-Spatial's released reconstructions are metric by construction (metric depth, metres)",
}
#: Instance formats whose boxes are metric by construction (the frame check then holds the Gaussians to them) → why.
METRIC_INSTANCE_FORMATS: Mapping[str, str] = {
    "embodiedscan": "EmbodiedScan boxes are metric by construction (the scans' frame, metres)",
    "scannetpp segments_anno": "ScanNet++ boxes are metric by construction (laser-scanner frame, metres)",
}
#: The extension of the lexicon's typical sizes used here (lexicon JSON format, key "sizes": [longest m, top m]).
TYPICAL_SIZES_FILE = Path(__file__).with_name("typical_sizes.json")
#: Fewest sized objects for an object estimate; also the fewest agreeing objects for a refusal.
MIN_OBJECTS = 3
#: An object agrees with the estimate when its metres per unit is within this factor of it.
AGREE_FACTOR = 1.5
#: Units unknown and the estimate off the chosen metres per unit by more than this factor: refused.
REFUSE_FACTOR = 1.5
#: Box bottoms that must meet at the lowest one for a floor.
MIN_FLOOR_BOXES = 2
#: Height of hand-held cameras above the floor, metres: (low, typical, high).
CAMERA_HEIGHT_M = (1.2, 1.45, 1.7)
#: Objects listed in a report's text / recorded in ``scene.json``.
_LISTED, _RECORDED = 6, 64

UnitsKind = Literal["metric", "given", "unknown"]


class UnitsImplausibleError(InvalidDataError):
    """The labelled objects are implausible for their labels at the chosen unit (the message gives the estimate and the fix)."""


@functools.lru_cache(maxsize=8)
def _units_lexicon(env: str) -> Lexicon:
    lexicon = load_lexicon(TYPICAL_SIZES_FILE, BUILTIN)
    for part in filter(None, env.split(os.pathsep)):
        lexicon = load_lexicon(part, lexicon)
    return lexicon


def units_lexicon() -> Lexicon:
    """The lexicon whose typical sizes the estimate uses: the built-in one, ``typical_sizes.json``,
    then the files named in ``SPACEDG_LEXICON`` (a user's sizes win)."""
    return _units_lexicon(os.environ.get(LEXICON_ENV, ""))


# --------------------------------------------------------------------------- evidence
@dataclass(frozen=True)
class ObjectEvidence:
    """One labelled box against its label's typical size.

    Attributes:
        id, label: the instance.
        size_as: the label whose typical size was used (the label itself, a synonym's, or its head noun).
        measured: the box's longest side, file units.
        typical: the typical longest side, metres.
    """

    id: int
    label: str
    size_as: str
    measured: float
    typical: float

    @property
    def metres_per_unit(self) -> float:
        return self.typical / self.measured

    def to_dict(self) -> dict[str, Any]:
        return {"id": self.id, "label": self.label, "size_as": self.size_as, "measured_units": round(self.measured, 6),
                "typical_m": self.typical, "metres_per_unit": round(self.metres_per_unit, 6)}


@dataclass(frozen=True)
class CameraHeightEvidence:
    """Camera height above the floor (lowest box bottoms along up), file units.

    Attributes:
        floor: the floor's height along up, units; floor_boxes: box bottoms that meet there.
        height: median camera height above the floor, units; cameras: how many cameras.
    """

    floor: float
    floor_boxes: int
    height: float
    cameras: int

    @property
    def metres_per_unit(self) -> float:
        return CAMERA_HEIGHT_M[1] / self.height

    @property
    def bounds(self) -> tuple[float, float]:
        """Metres per unit for cameras held at 1.2 m and at 1.7 m."""
        return CAMERA_HEIGHT_M[0] / self.height, CAMERA_HEIGHT_M[2] / self.height

    def to_dict(self) -> dict[str, Any]:
        return {"floor_units": round(self.floor, 6), "floor_boxes": self.floor_boxes, "height_units": round(self.height, 6),
                "cameras": self.cameras, "metres_per_unit": round(self.metres_per_unit, 6),
                "bounds": [round(b, 6) for b in self.bounds]}


@dataclass(frozen=True)
class UnitEstimate:
    """Metres per file unit as the scene's own objects (and cameras) say (module docstring).

    Attributes:
        metres_per_unit: the object estimate, ``None`` when unavailable (``reason`` says why).
        spread: the robust spread of the objects' estimates, a factor ≥ 1 (``None`` when unavailable).
        objects: the sized objects, closest to the estimate first.
        agreeing: how many of them agree (within :data:`AGREE_FACTOR`).
        ignored_labels: labels without a typical size (not used).
        camera: the camera-height evidence, ``None`` when no floor was found.
        reason: why the object estimate is unavailable ("" when available).
    """

    metres_per_unit: float | None
    spread: float | None
    objects: tuple[ObjectEvidence, ...] = ()
    agreeing: int = 0
    ignored_labels: tuple[str, ...] = ()
    camera: CameraHeightEvidence | None = None
    reason: str = ""

    @property
    def available(self) -> bool:
        return self.metres_per_unit is not None

    @property
    def confident(self) -> bool:
        """Enough objects agree for a refusal: at least :data:`MIN_OBJECTS`, and at least half of them."""
        return self.available and self.agreeing >= MIN_OBJECTS and 2 * self.agreeing >= len(self.objects)

    def to_dict(self) -> dict[str, Any]:
        return {
            "metres_per_unit": None if self.metres_per_unit is None else round(self.metres_per_unit, 6),
            "spread": None if self.spread is None else round(self.spread, 4), "agreeing": self.agreeing,
            "objects_used": len(self.objects), "objects": [o.to_dict() for o in self.objects[:_RECORDED]],
            "ignored_labels": list(self.ignored_labels), "camera_height": None if self.camera is None else self.camera.to_dict(),
            "reason": self.reason,
        }


def _sized_objects(instances: Iterable[Instance], lexicon: Lexicon) -> tuple[list[ObjectEvidence], list[str]]:
    """Boxes whose label (or its head noun) has a typical size; the labels that have none."""
    found, ignored = [], set()
    for inst in instances:
        size, used = lexicon.typical_size(inst.label), label_key(inst.label)
        if size is None and head_noun(inst.label) != used:
            used = head_noun(inst.label)
            size = lexicon.typical_size(used)
        measured = float(np.max(inst.box.extents))
        if size is None or not size[0] > 0:
            ignored.add(label_key(inst.label))
        elif math.isfinite(measured) and measured > 0:
            found.append(ObjectEvidence(int(inst.id), inst.label, used, measured, float(size[0])))
    return found, sorted(ignored)


def _camera_height(instances: Sequence[Instance], views: Mapping[str, Camera], up: np.ndarray) -> CameraHeightEvidence | None:
    """The floor as the lowest box bottoms along up (refined by :func:`~spacedg.scene.up_evidence.upright_boxes_up`) and the cameras' median height above it, or ``None``."""
    if len(instances) < MIN_FLOOR_BOXES or not views:
        return None
    refined = upright_boxes_up(instances, up)
    up = up if refined is None else refined
    bottoms = np.array([inst.box.extent_along(up)[0] for inst in instances])
    sizes = np.array([float(np.max(inst.box.extents)) for inst in instances])
    tol = 0.1 * float(np.median(sizes))
    near = bottoms[bottoms <= bottoms.min() + tol]
    if len(near) < MIN_FLOOR_BOXES:
        return None
    floor = float(np.median(near))
    heights = np.array([float(np.asarray(c.cam_to_world)[:3, 3] @ up) for c in views.values()]) - floor
    height = float(np.median(heights))
    if not (math.isfinite(height) and height > tol):
        return None
    return CameraHeightEvidence(floor, len(near), height, len(heights))


def estimate_units(
    instances: Sequence[Instance], views: Mapping[str, Camera] | None = None, up: Sequence[float] | np.ndarray | None = None,
    *, lexicon: Lexicon | None = None,
) -> UnitEstimate:
    """Metres per file unit from labelled boxes against typical sizes, and from the camera height
    above the floor (module docstring). Boxes, cameras in file units; ``up`` a unit vector (the
    camera evidence needs ``views`` and ``up``)."""
    objects, ignored = _sized_objects(instances, lexicon or units_lexicon())
    camera = None
    if views is not None and up is not None:
        u = np.asarray(up, dtype=np.float64)
        camera = _camera_height(list(instances), views, u / np.linalg.norm(u))
    if len(objects) < MIN_OBJECTS:
        reason = (f"only {len(objects)} labelled object(s) with a typical size (need {MIN_OBJECTS})"
                  + (f"; labels without one: {', '.join(ignored[:8])}" if ignored else ""))
        return UnitEstimate(None, None, tuple(objects), 0, tuple(ignored), camera, reason)
    logs = np.log([o.metres_per_unit for o in objects])
    centre = float(np.median(logs))
    spread = math.exp(1.4826 * float(np.median(np.abs(logs - centre))))
    order = np.argsort(np.abs(logs - centre), kind="stable")
    agreeing = int((np.abs(logs - centre) <= math.log(AGREE_FACTOR) + 1e-12).sum())
    return UnitEstimate(math.exp(centre), spread, tuple(objects[i] for i in order), agreeing, tuple(ignored), camera)


def estimate_scene_units(scene: Scene) -> UnitEstimate:
    """:func:`estimate_units` on a scene's instances, views and up (metres per scene unit: ≈ 1 for a metric scene)."""
    return estimate_units(scene.instances, scene.views, scene.up)


# --------------------------------------------------------------------------- decision
def _g(x: float) -> str:
    """A metres-per-unit number as the user would type it (3 significant digits)."""
    return f"{x:.3g}"


@dataclass(frozen=True)
class UnitDecision:
    """What one file unit is and how that was decided (module docstring).

    Attributes:
        kind: ``"metric"``, ``"given"`` or ``"unknown"``.
        metres_per_unit: the chosen scale, applied to Gaussians, cameras and boxes.
        how: one sentence: how the scale was decided.
        estimate: the evidence (file units).
    """

    kind: UnitsKind
    metres_per_unit: float
    how: str
    estimate: UnitEstimate = field(default_factory=lambda: UnitEstimate(None, None, reason="not estimated"))

    @property
    def ratio(self) -> float | None:
        """Estimate / chosen metres per unit (``None`` without an estimate)."""
        e = self.estimate.metres_per_unit
        return None if e is None else e / self.metres_per_unit

    def implausible(self) -> bool:
        """Units unknown, and confidently estimated more than :data:`REFUSE_FACTOR` off the chosen scale."""
        r = self.ratio
        return self.kind == "unknown" and r is not None and self.estimate.confident and abs(math.log(r)) > math.log(REFUSE_FACTOR)

    def disagrees(self) -> bool:
        """The estimate is more than :data:`REFUSE_FACTOR` off the chosen scale (any kind, any confidence)."""
        r = self.ratio
        return r is not None and abs(math.log(r)) > math.log(REFUSE_FACTOR)

    def _objects_text(self, n: int = _LISTED) -> str:
        parts = [f"{o.label} {o.measured:.3g} u (typ. {o.typical:g} m → {_g(o.metres_per_unit)})" for o in self.estimate.objects[:n]]
        more = len(self.estimate.objects) - n
        return ", ".join(parts) + (f", … {more} more" if more > 0 else "")

    def estimate_text(self) -> str:
        """One line: the object estimate against the chosen scale, its spread and its objects; or why none."""
        e = self.estimate
        if not e.available:
            return f"estimate unavailable: {e.reason}"
        return (f"estimate {_g(e.metres_per_unit)} m/unit (×{self.ratio:.2f} the chosen {_g(self.metres_per_unit)}), "
                f"spread ×{e.spread:.2f}, {e.agreeing} of {len(e.objects)} objects agree: {self._objects_text()}")

    def camera_text(self) -> str | None:
        """One line on the camera-height evidence, or ``None`` without a floor."""
        c = self.estimate.camera
        if c is None:
            return None
        lo, hi = c.bounds
        return (f"cameras {c.height:.3g} units above the floor ({c.floor_boxes} box bottoms): {_g(c.metres_per_unit)} m/unit "
                f"at 1.45 m ({_g(lo)}–{_g(hi)} for 1.2–1.7 m)")

    def text(self) -> str:
        """The short human-readable report: decision, estimate vs chosen, spread, objects, camera height."""
        lines = [f"units        {_g(self.metres_per_unit)} m per file unit: {self.how}", f"             {self.estimate_text()}"]
        camera = self.camera_text()
        if camera:
            lines.append(f"             {camera}")
        if self.estimate.ignored_labels:
            lines.append(f"             labels without a typical size (ignored): {', '.join(self.estimate.ignored_labels[:12])}")
        if self.kind == "unknown" and not self.estimate.available:
            lines.append("             NOT VERIFIED: pass --metres-per-unit X (a known length in metres / the same length in file units) "
                         "or --units metric if the files are in metres")
        elif self.disagrees() and not self.implausible():
            lines.append(f"             WARNING: the objects suggest {_g(self.estimate.metres_per_unit)} m/unit; check the scale")
        return "\n".join(lines)

    def line(self) -> str:
        """One line for ``spacedg scenes info``."""
        e = self.estimate
        est = (f"estimate {_g(e.metres_per_unit)} (spread ×{e.spread:.2f}, {e.agreeing}/{len(e.objects)} objects)"
               if e.available else "estimate unavailable")
        return f"{_g(self.metres_per_unit)} m per file unit, {self.kind}: {self.how}; {est}"

    def refusal(self, where: str, layout: str) -> UnitsImplausibleError:
        """The error of an implausible decision: the estimate, its evidence and the exact options to pass."""
        e = self.estimate
        worst = ", ".join(f"{o.label} would be {o.measured * self.metres_per_unit:.3g} m (typically {o.typical:g} m)"
                          for o in e.objects[:3])
        camera = self.camera_text()
        return UnitsImplausibleError(
            f"{where}: the units of this {layout} capture are unknown and its labelled objects are implausible at "
            f"{_g(self.metres_per_unit)} m per file unit: {worst}. {e.agreeing} of {len(e.objects)} objects agree on "
            f"{_g(e.metres_per_unit)} m per unit (spread ×{e.spread:.2f})" + (f"; {camera}" if camera else "") +
            f". Pass --metres-per-unit {_g(e.metres_per_unit)} (import_scene(metres_per_unit={_g(e.metres_per_unit)})) "
            "if that is right (better: a known length in metres / the same length in file units), "
            "or --units metric if the files really are in metres"
        )

    def to_dict(self) -> dict[str, Any]:
        """The record kept in ``scene.json`` (``metadata["units"]``)."""
        return {"kind": self.kind, "metres_per_unit": self.metres_per_unit, "how": self.how, "estimate": self.estimate.to_dict()}


def _stated(layout: str, instances_format: str | None, units: str, metres_per_unit: float | None) -> tuple[UnitsKind, float, str]:
    if units not in ("auto", "metric"):
        raise ParameterError(f"--units {units!r}: choose auto (decide from the layout, check against the objects) or metric")
    if units == "metric":
        if metres_per_unit is not None and metres_per_unit != 1.0:
            raise ParameterError(f"--units metric and --metres-per-unit {metres_per_unit:g} contradict each other: pass one of them")
        return "metric", 1.0, "stated metric by the user (--units metric)"
    if metres_per_unit is not None:
        return "given", float(metres_per_unit), f"given by the user (--metres-per-unit {metres_per_unit:g})"
    if layout in METRIC_LAYOUTS:
        return "metric", 1.0, METRIC_LAYOUTS[layout]
    if instances_format in METRIC_INSTANCE_FORMATS:
        return "metric", 1.0, METRIC_INSTANCE_FORMATS[instances_format]
    return "unknown", 1.0, f"unknown ({layout} files carry no metric scale); file units taken as metres"


def decide_units(
    layout: str, instances: Sequence[Instance], views: Mapping[str, Camera] | None = None, up: Sequence[float] | np.ndarray | None = None,
    *, instances_format: str | None = None, units: str = "auto", metres_per_unit: float | None = None,
) -> UnitDecision:
    """The unit of an import (module docstring); boxes, cameras in file units. Check with
    :meth:`UnitDecision.implausible` and raise :meth:`UnitDecision.refusal` to refuse.

    Raises:
        ParameterError: ``units`` is not ``"auto"``/``"metric"``, or ``"metric"`` with a ``metres_per_unit`` other than 1.
    """
    kind, chosen, how = _stated(layout, instances_format, units, metres_per_unit)
    estimate = estimate_units(instances, views, up)
    if kind == "unknown" and estimate.available:
        r = estimate.metres_per_unit / chosen  # type: ignore[operator]
        if abs(math.log(r)) <= math.log(REFUSE_FACTOR):
            how += f": the labelled objects agree (estimate {_g(estimate.metres_per_unit)} m/unit)"  # type: ignore[arg-type]
    elif kind == "unknown":
        how += ", not verified (estimate unavailable)"
    return UnitDecision(kind, chosen, how, estimate)


def scene_units_line(scene: Scene) -> str:
    """How a scene's scale was decided, one line (``spacedg scenes info``): the import's record, or what is known without one."""
    record = scene.metadata.get("units")
    if isinstance(record, Mapping) and isinstance(record.get("how"), str):
        est = record.get("estimate") if isinstance(record.get("estimate"), Mapping) else {}
        value = est.get("metres_per_unit")
        spread = est.get("spread")
        tail = (f"estimate {_g(value)} m/unit (spread ×{spread:.2f}, {est.get('agreeing')}/{est.get('objects_used')} objects)"
                if isinstance(value, (int, float)) and isinstance(spread, (int, float)) else "estimate unavailable")
        return f"{_g(float(record.get('metres_per_unit', 1.0)))} m per file unit, {record.get('kind')}: {record['how']}; {tail}"
    scale = scene.metadata.get("scale_to_metres")
    if isinstance(scale, (int, float)):
        return f"{_g(scale)} m per file unit (imported before units were checked: not verified; re-import to check)"
    return "metres (no import record: a scene made by spacedg)"
