"""The checks every path that builds a scene from a foreign capture runs, in one place.

``spacedg scenes import`` (:func:`~spacedg.scene.importer.import_scene`) and the Python API
:func:`~spacedg.scene.io.scene_from_files` both call these, with the same override arguments and
the same errors:

1. :func:`decide_frame` (files' units, before any scaling): **up** verified against the capture's
   evidence (:func:`~spacedg.scene.up_evidence.decide_up`: ``up`` given / a layout's convention /
   estimated; ``trust_up`` keeps a contradicted one) and **units** decided and checked
   (:func:`~spacedg.scene.units.decide_units`: ``metres_per_unit`` given, ``units="metric"``
   stated, metric by construction, or unknown and checked against the labelled objects).
   Raises :class:`~spacedg.scene.up_evidence.UpContradictedError`,
   :class:`~spacedg.scene.up_evidence.UpUndecidedError` or
   :class:`~spacedg.scene.units.UnitsImplausibleError`.
2. :func:`check_box_fill` (metres, after scaling): every box must hold its object
   (:mod:`spacedg.scene.box_fill`); refused with :class:`~spacedg.scene.box_fill.BoxFillError`
   unless ``frame_check="warn"``, which returns the note to keep instead.

Scaling itself (``metres_per_unit`` applied once to Gaussians, cameras and boxes) stays with the
callers (:mod:`spacedg.scene.io.capture`), between the two steps.
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from spacedg.errors import ParameterError
from spacedg.render.camera import Camera
from spacedg.scene.box_fill import BoxFillError, BoxFillReport, measure_box_fill
from spacedg.scene.model import Instance
from spacedg.scene.units import UnitDecision, decide_units
from spacedg.scene.up_evidence import UpEvidence, decide_up

__all__ = ["FRAME_CHECKS", "FrameDecision", "check_box_fill", "check_metres_per_unit", "decide_frame", "parse_up"]

#: What ``frame_check`` accepts: refuse (``"error"``) or note and write anyway (``"warn"``).
FRAME_CHECKS = ("error", "warn")
_AXES = {"x": 0, "y": 1, "z": 2}


def parse_up(text: str | Iterable[float] | None) -> np.ndarray | None:
    """``"auto"``/``None`` → None; ``"+z"``, ``"-y"``, ``"z"``, ``"x,y,z"`` or three numbers → a unit vector.

    Raises:
        ParameterError: anything else (naming ``--up`` and what it accepts).
    """
    if text is None or (isinstance(text, str) and text.strip().lower() == "auto"):
        return None
    if isinstance(text, str):
        t = text.strip().lower()
        match = re.fullmatch(r"([+-]?)([xyz])", t)
        if match:
            out = np.zeros(3)
            out[_AXES[match.group(2)]] = -1.0 if match.group(1) == "-" else 1.0
            return out
        parts: Any = t.split(",")
    else:
        parts = list(text)
    try:
        vec = np.array([float(v) for v in parts], dtype=np.float64)
    except (TypeError, ValueError):
        vec = np.zeros(0)
    if vec.shape != (3,) or not np.isfinite(vec).all() or np.linalg.norm(vec) == 0:
        raise ParameterError(f"--up (up=) {text!r}: give auto, an axis (+z, -y, x, ...) or three numbers x,y,z, not all zero")
    return vec / np.linalg.norm(vec)


def check_metres_per_unit(value: Any) -> float | None:
    """``None`` (decide) or a positive finite number of metres per file unit.

    Raises:
        ParameterError: anything else.
    """
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (math.isfinite(value) and value > 0):
        raise ParameterError(f"--metres-per-unit (metres_per_unit=) must be a positive number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class FrameDecision:
    """The up and the unit a capture is imported with, and the evidence for both.

    Attributes:
        up: unit vector against gravity, files' frame.
        up_source: where it came from (``"given"``, a layout's convention, ``"estimated ..."``).
        up_evidence: the evidence and its verdict.
        units: how many metres one file unit is and how that was decided.
    """

    up: np.ndarray
    up_source: str
    up_evidence: UpEvidence
    units: UnitDecision

    @property
    def metres_per_unit(self) -> float:
        return self.units.metres_per_unit

    def note(self) -> str:
        """The up evidence, one line (a report's note)."""
        return f"up evidence  {self.up_evidence.summary()}" + "".join(f"; {n}" for n in self.up_evidence.notes)

    def metadata(self) -> dict[str, Any]:
        """What ``scene.json`` records: ``scale_to_metres``, ``up_source``, ``up_evidence``, ``units``."""
        return {"scale_to_metres": self.metres_per_unit, "up_source": self.up_source,
                "up_evidence": self.up_evidence.to_dict(), "units": self.units.to_dict()}


def decide_frame(
    views: Mapping[str, Camera], instances: Sequence[Instance], *, where: str, layout: str,
    up: str | Iterable[float] | None = None, default_up: np.ndarray | None = None, default_note: str = "",
    means: np.ndarray | None = None, instances_format: str | None = None, units: str = "auto",
    metres_per_unit: float | None = None, trust_up: bool = False,
) -> FrameDecision:
    """Up and units of a capture, both checked (module docstring, step 1); everything in file units.

    Args:
        views, instances: cameras (OpenCV, cam-to-world) and boxes, files' frame and units.
        where: the capture, named at the front of every error.
        layout: the capture's layout (:data:`~spacedg.scene.importer.LAYOUTS`; decides metric by construction).
        up: ``None``/``"auto"``, an axis (``"+z"``) or three numbers, files' frame.
        default_up, default_note: a layout's own up convention and its description.
        means: Gaussian centres (N, 3), optional (the floor slab).
        instances_format: the annotation's format (some are metric by construction).
        units: ``"auto"`` or ``"metric"`` (stated by the user).
        metres_per_unit: given by the user (``None``: decided).
        trust_up: keep an up the evidence contradicts (recorded as overridden).
    """
    mpu = check_metres_per_unit(metres_per_unit)
    vec, source, evidence = decide_up(views, instances, given=parse_up(up), default=default_up, default_note=default_note,
                                      means=means, trust=trust_up, where=f"{where}: ")
    decision = decide_units(layout, instances, views, vec, instances_format=instances_format, units=units, metres_per_unit=mpu)
    if decision.implausible():
        raise decision.refusal(where, layout)
    return FrameDecision(vec, source, evidence, decision)


def check_box_fill(
    means: np.ndarray, instances: Sequence[Instance], *, where: str, layout: str, frame_check: str = "error",
    fill: BoxFillReport | None = None,
) -> tuple[BoxFillReport | None, str | None]:
    """Whether every box holds its object (module docstring, step 2); metres, after scaling.

    Returns ``(report, note)``: the fill report (``None`` without boxes; ``fill`` when already measured) and,
    with ``frame_check="warn"``, the note on boxes that do not hold their objects (``None`` when all do).

    Raises:
        BoxFillError: an empty or misplaced box, with ``frame_check="error"``.
        ParameterError: ``frame_check`` not in :data:`FRAME_CHECKS`.
    """
    if frame_check not in FRAME_CHECKS:
        raise ParameterError(f"frame_check {frame_check!r}: choose one of {', '.join(FRAME_CHECKS)}")
    if not instances:
        return None, None
    report = fill if fill is not None else measure_box_fill(means, instances)
    try:
        report.raise_if_bad(where, layout)
    except BoxFillError:
        if frame_check == "error":
            raise
        return report, "BOXES NOT HOLDING THEIR OBJECTS written anyway (frame_check='warn'): " + report.message("boxes", layout)
    return report, None
