"""Bounds on annotation numbers: instance ids and box sizes a scene can hold.

Gaussians carry instance ids as int32 with -1 for none, so an id is an integer in
``[0, MAX_INSTANCE_ID]``; a larger one (2^70 in a hostile file) would overflow where ids are
stored. A box's side lengths must be finite, >= 0, with at least one > 0, and at most
:data:`MAX_BOX_SIDE` file units; its centre at most :data:`MAX_COORDINATE` from the origin (a
box of 1e308 units fills nothing sensible and overflows its volume). Readers call these with the
file and instance named, so the message says where and how to fix it.
"""

from __future__ import annotations

import numpy as np

from spacedg.files import FileValueError
from spacedg.scene.box import OrientedBox

__all__ = ["MAX_INSTANCE_ID", "MAX_BOX_SIDE", "MAX_COORDINATE", "check_instance_id", "check_box_size", "check_coordinates"]

#: Largest instance id (int32, -1 reserved for "no instance").
MAX_INSTANCE_ID = 2**31 - 1
#: Largest box side length, file units (a kilometre in metres; 1e6 mm is still a kilometre).
MAX_BOX_SIDE = 1e6
#: Largest distance of a box centre from the origin along any axis, file units.
MAX_COORDINATE = 1e7


def check_instance_id(where: str, key: str, value: int) -> int:
    """``value`` if it fits an instance id, else :class:`FileValueError` naming ``where`` and ``key``."""
    if not 0 <= value <= MAX_INSTANCE_ID:
        shown = str(value) if abs(value) < 10**20 else f"a {len(str(abs(value))):,}-digit number"
        raise FileValueError(
            f"{where}: '{key}' {shown} is out of range: instance ids are integers in [0, {MAX_INSTANCE_ID}] "
            "(Gaussians store them as int32); renumber the instances (e.g. 0, 1, 2, ...)"
        )
    return value


def check_box_size(where: str, box: OrientedBox) -> OrientedBox:
    """``box`` if its sizes are plausible numbers (module docstring), else :class:`FileValueError` with the fix."""
    ext = box.extents
    if not (ext > 0).any() or (ext > MAX_BOX_SIDE).any():
        raise FileValueError(
            f"{where}: box side lengths {ext.tolist()} are out of range: give full side lengths > 0 and at most "
            f"{MAX_BOX_SIDE:g} file units (check the units and that 'obb_extents' are side lengths, not corners)"
        )
    if (np.abs(box.center) > MAX_COORDINATE).any():
        raise FileValueError(
            f"{where}: box centre {box.center.tolist()} is more than {MAX_COORDINATE:g} file units from the origin; "
            "check the annotation's frame and units"
        )
    return box


def check_coordinates(where: str, key: str, points: np.ndarray) -> np.ndarray:
    """``points`` if every coordinate is within :data:`MAX_COORDINATE` of the origin (box corners
    before any arithmetic on them), else :class:`FileValueError`."""
    if (np.abs(points) > MAX_COORDINATE).any():
        raise FileValueError(
            f"{where}: '{key}' holds coordinates beyond {MAX_COORDINATE:g} file units (largest {float(np.abs(points).max()):.3g}); "
            "check the annotation's frame and units"
        )
    return points
