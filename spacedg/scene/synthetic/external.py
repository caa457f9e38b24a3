"""Objects from files (e.g. the ``.splat`` objects) placed into synthetic rooms as instances.

An :class:`ExternalObject` holds Gaussians in the object's own frame plus how to stand it
up: which of its axes points up, the real size it should have (the longest side, metres),
its label and description. :meth:`ExternalObject.model` normalises it (up axis → +z,
footprint centred on the origin, bottom on z = 0, scaled to ``size_m``) into an
``ObjectModel`` that the room layout places like any catalogue piece, on the floor or on a
top, without interpenetration.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import read_json
from spacedg.render.gaussians import Gaussians
from spacedg.scene.io.splat import read_splat
from spacedg.scene.synthetic.appearance import nearest_colour_name
from spacedg.scene.synthetic.catalogue import ObjectModel

_AXES = {"+x": (0, 1.0), "-x": (0, -1.0), "+y": (1, 1.0), "-y": (1, -1.0), "+z": (2, 1.0), "-z": (2, -1.0)}


def _up_to_z(up_axis: str) -> np.ndarray:
    """Rotation taking the object's ``up_axis`` (e.g. "-y") to +z."""
    if up_axis not in _AXES:
        raise InvalidDataError(f"ExternalObject: up_axis must be one of {sorted(_AXES)}, got {up_axis!r}")
    axis, sign = _AXES[up_axis]
    up = np.zeros(3)
    up[axis] = sign
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(up, z)
    c = float(up @ z)
    if np.linalg.norm(v) < 1e-12:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    vx = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + vx + vx @ vx / (1 + c)


@dataclass(frozen=True)
class ExternalObject:
    """Gaussians of one object with its label, description, up axis and target size.

    Attributes:
        gaussians: the object's Gaussians in its own (arbitrary, unit-less) frame.
        label: category word ("teapot").
        description: view-invariant description; ``None`` builds "<colour> <label>" from the
            dominant colour of the Gaussians.
        up_axis: which object axis points up ("+z", "-y", ...).
        size_m: longest side after scaling, metres.
        placement: "floor" or "support" (stands on a table, desk, cabinet or low shelf).
        attributes: extra facts kept on the instance (source file, licence, author).
    """

    gaussians: Gaussians
    label: str
    description: str | None = None
    up_axis: str = "+z"
    size_m: float = 0.3
    placement: str = "support"
    attributes: dict[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not (0.05 <= self.size_m <= 2.5):
            raise InvalidDataError(f"ExternalObject {self.label!r}: size_m must be in [0.05, 2.5] metres, got {self.size_m}")
        if self.placement not in ("floor", "support"):
            raise InvalidDataError(f"ExternalObject {self.label!r}: placement must be 'floor' or 'support', got {self.placement!r}")
        if len(self.gaussians) == 0:
            raise InvalidDataError(f"ExternalObject {self.label!r}: has no Gaussians")
        _up_to_z(self.up_axis)

    @classmethod
    def from_splat(cls, path: str | Path, *, label: str | None = None, description: str | None = None,
                   size_m: float = 0.3, placement: str = "support") -> ExternalObject:
        """Load a ``.splat`` object; label (meta ``id``), up axis and credits come from a ``meta.json`` beside it if present."""

        path = Path(path)
        meta: dict = {}
        meta_path = path.parent / "meta.json"
        if meta_path.is_file():
            meta = read_json(meta_path, "meta.json")
            if not isinstance(meta, dict):
                raise FileFormatError(f"{meta_path}: expected a JSON object (id, geometry.up_axis, license, ...), got {type(meta).__name__}")
        up_axis = str(meta.get("geometry", {}).get("up_axis", "+z"))
        attrs = {"source_file": path.name}
        for key in ("license", "author", "title"):
            if key in meta:
                attrs[key] = meta[key]
        name = label or str(meta.get("id", path.stem.split("_")[0])).lower()
        return cls(read_splat(path), name, description, up_axis, size_m, placement, attrs)

    def model(self) -> ObjectModel:
        """Normalised :class:`ObjectModel` (up = +z, bottom at z = 0, longest side ``size_m``)."""
        g = self.gaussians.transformed(_up_to_z(self.up_axis))
        lo, hi = g.bounds()
        longest = float((hi - lo).max())
        if longest <= 0:
            raise InvalidDataError(f"ExternalObject {self.label!r}: all Gaussians share one position; cannot scale it")
        scale = self.size_m / longest
        centre = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
        g = g.transformed(np.eye(3), -centre * scale, scale)
        desc = self.description or f"{nearest_colour_name(np.clip(np.median(g.base_colors(), axis=0), 0, 1))} {self.label}"
        return ObjectModel(self.label, [], {}, description_template=desc, prebuilt=g, attributes=dict(self.attributes))
