"""Oriented 3D bounding boxes.

An :class:`OrientedBox` is ``center`` (3,) metres, ``extents`` (3,) **full** side lengths in
metres (not half sizes), and ``rotation`` (3, 3) whose **columns** are the box's local axes
in world coordinates (a proper rotation). A world point ``p`` has box-local coordinates
``rotation.T @ (p - center)``, inside the box when each is within ±extents/2.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from spacedg._checks import require_rotation
from spacedg.errors import InvalidDataError

_SOURCE = "OrientedBox"
# Sign pattern of the 8 corners, in box-local half-extent units (x fastest).
_CORNER_SIGNS = np.array(list(itertools.product((-1, 1), repeat=3)), dtype=np.float64)[:, ::-1]


def cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``np.cross(a, b)`` of two float64 3-vectors, bit for bit (the same three products and
    differences in float64), without ``np.cross``'s axis handling (the cost of a candidate's
    geometry). Anything else goes to ``np.cross``."""
    if (
        type(a) is np.ndarray and type(b) is np.ndarray and a.shape == (3,) and b.shape == (3,)
        and a.dtype == np.float64 and b.dtype == np.float64
    ):
        a0, a1, a2 = a.tolist()
        b0, b1, b2 = b.tolist()
        return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])
    return np.cross(a, b)


@dataclass(frozen=True, eq=False)
class OrientedBox:
    """A box with a centre, full side lengths and an orientation (see module docstring)."""

    center: np.ndarray
    extents: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))

    def __post_init__(self) -> None:
        center = np.array(self.center, dtype=np.float64).reshape(-1)
        extents = np.array(self.extents, dtype=np.float64).reshape(-1)
        rotation = np.array(self.rotation, dtype=np.float64)
        if center.shape != (3,) or not np.isfinite(center).all():
            raise InvalidDataError(f"{_SOURCE}: center must be 3 finite numbers, got {center.tolist()}")
        if extents.shape != (3,) or not np.isfinite(extents).all() or (extents < 0).any():
            raise InvalidDataError(
                f"{_SOURCE}: extents must be 3 finite full side lengths >= 0 metres, got {extents.tolist()}"
            )
        require_rotation(rotation, "rotation", _SOURCE, tol=1e-5)
        for name, arr in (("center", center), ("extents", extents), ("rotation", rotation)):
            arr.flags.writeable = False
            object.__setattr__(self, name, arr)

    def __eq__(self, other: object) -> bool:
        """Exact equality of centre, extents and rotation."""
        if not isinstance(other, OrientedBox):
            return NotImplemented
        return all(np.array_equal(getattr(self, f), getattr(other, f)) for f in ("center", "extents", "rotation"))

    __hash__ = None  # type: ignore[assignment]  # mutable-looking arrays: not hashable

    # ------------------------------------------------------------- factories
    @classmethod
    def from_transform(cls, transform: np.ndarray, extents: np.ndarray) -> OrientedBox:
        """Box from a (4, 4) local-to-world transform (rotation + translation) and full extents.

        A reflection (det = -1) is turned into a rotation by flipping the third axis, which
        describes the same set of points.
        """
        t = np.asarray(transform, dtype=np.float64)
        if t.shape != (4, 4):
            raise InvalidDataError(f"{_SOURCE}: transform must be 4×4, got shape {t.shape}")
        rot = t[:3, :3].copy()
        if np.isfinite(rot).all() and np.linalg.det(rot) < 0:
            rot[:, 2] *= -1.0
        return cls(t[:3, 3], extents, rot)

    @classmethod
    def from_corners(cls, corners: np.ndarray, rel_tol: float = 1e-3) -> OrientedBox:
        """Recover a box from its 8 corners given in **any order**.

        Three mutually orthogonal edges are found among the vectors from one corner to the
        others; every corner must then be the centre ± half of a combination of those edges,
        within ``rel_tol`` of the box diagonal. Raises :class:`InvalidDataError` otherwise.
        One zero extent (a flat box) is allowed.
        """
        pts = np.asarray(corners, dtype=np.float64)
        if pts.shape != (8, 3) or not np.isfinite(pts).all():
            raise InvalidDataError(f"{_SOURCE}: corners must be 8 finite 3D points, got shape {pts.shape}")
        center = pts.mean(axis=0)
        diag = float(np.linalg.norm(pts - center, axis=1).max()) * 2.0
        if diag == 0.0:
            return cls(center, np.zeros(3))
        tol = rel_tol * diag
        vecs = pts[1:] - pts[0]
        lengths = np.linalg.norm(vecs, axis=1)
        best: tuple[float, np.ndarray, np.ndarray] | None = None
        for i, j in itertools.combinations(range(7), 2):
            a, b = vecs[i], vecs[j]
            if lengths[i] <= tol or lengths[j] <= tol:
                continue
            if abs(a @ b) > tol * (lengths[i] + lengths[j]):
                continue
            # third edge: another vector orthogonal to both, or zero length (flat box)
            for k in range(7):
                if k in (i, j):
                    continue
                c = vecs[k]
                if lengths[k] > tol and (abs(a @ c) > tol * (lengths[i] + lengths[k]) or abs(b @ c) > tol * (lengths[j] + lengths[k])):
                    continue
                edges = np.stack([a, b, c], axis=1) if lengths[k] > tol else np.stack([a, b, np.zeros(3)], axis=1)
                err = cls._fit_error(pts, pts[0], edges)
                if best is None or err < best[0]:
                    best = (err, edges, pts[0])
                if lengths[k] > tol:
                    break
        if best is None or best[0] > tol:
            worst = "n/a" if best is None else f"{best[0]:.3g} m"
            raise InvalidDataError(
                f"{_SOURCE}: the 8 corners do not form a box (best fit deviation {worst}, tolerance {tol:.3g} m); "
                "give corners of a rectangular cuboid, in any order"
            )
        _, edges, _ = best
        ext = np.linalg.norm(edges, axis=0)
        axes = np.zeros((3, 3))
        for col in range(3):
            if ext[col] > tol:
                axes[:, col] = edges[:, col] / ext[col]
        flat = [c for c in range(3) if ext[c] <= tol]
        if flat:
            c = flat[0]
            o1, o2 = [x for x in range(3) if x != c]
            axes[:, c] = np.cross(axes[:, o1], axes[:, o2])
            ext[c] = 0.0
        # orthonormalise (noise) and make right-handed
        u, _, vt = np.linalg.svd(axes)
        axes = u @ vt
        if np.linalg.det(axes) < 0:
            axes[:, 2] *= -1.0
        return cls(center, ext, axes)

    @staticmethod
    def _fit_error(pts: np.ndarray, origin: np.ndarray, edges: np.ndarray) -> float:
        signs01 = (_CORNER_SIGNS + 1.0) / 2.0  # 0/1 combinations
        model = origin + signs01 @ edges.T
        # match each model corner to its nearest given corner (boxes have distinct corners)
        dist = np.linalg.norm(model[:, None, :] - pts[None, :, :], axis=2)
        return float(dist.min(axis=1).max())

    @classmethod
    def fit_points(cls, points: np.ndarray, rotation: np.ndarray | None = None) -> OrientedBox:
        """Tightest box with the given axes (default: world axes) that contains ``points``."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if pts.shape[0] == 0:
            raise InvalidDataError(f"{_SOURCE}: cannot fit a box to zero points")
        rot = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
        local = pts @ rot
        lo, hi = local.min(axis=0), local.max(axis=0)
        return cls(rot @ ((lo + hi) / 2.0), hi - lo, rot)

    # ------------------------------------------------------------- geometry
    @property
    def half_extents(self) -> np.ndarray:
        return self.extents / 2.0

    @property
    def volume(self) -> float:
        """Volume in cubic metres."""
        return float(np.prod(self.extents))

    def corners(self) -> np.ndarray:
        """(8, 3) world-space corners (local sign order x fastest, then y, then z)."""
        return self.center + (_CORNER_SIGNS * self.half_extents) @ self.rotation.T

    def to_local(self, points: np.ndarray) -> np.ndarray:
        """(N, 3) world points → box-local coordinates (metres, origin at the centre)."""
        return (np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.center) @ self.rotation

    def contains(self, points: np.ndarray, tol: float = 0.0) -> np.ndarray:
        """(N,) bool: points inside the box grown by ``tol`` metres on every side."""
        return (np.abs(self.to_local(points)) <= self.half_extents + tol).all(axis=1)

    def extent_along(self, direction: np.ndarray) -> tuple[float, float]:
        """(min, max) of the box projected on a unit ``direction`` (e.g. ``Scene.up``)."""
        d = np.asarray(direction, dtype=np.float64)
        c = float(self.center @ d)
        r = float(np.abs(self.rotation.T @ d) @ self.half_extents)
        return c - r, c + r

    def intersects(self, other: OrientedBox, tol: float = 0.0) -> bool:
        """True when the boxes overlap by more than ``tol`` metres along every separating axis.

        Separating-axis test over the 15 candidate axes. Boxes that merely touch (a cup
        standing on a table) do not intersect for any ``tol >= 0``.
        """
        axes = [self.rotation[:, i] for i in range(3)] + [other.rotation[:, i] for i in range(3)]
        for i in range(3):
            for j in range(3):
                cross = cross3(self.rotation[:, i], other.rotation[:, j])
                n = np.linalg.norm(cross)
                if n > 1e-9:
                    axes.append(cross / n)
        delta = other.center - self.center
        for axis in axes:
            ra = float(np.abs(self.rotation.T @ axis) @ self.half_extents)
            rb = float(np.abs(other.rotation.T @ axis) @ other.half_extents)
            if abs(float(delta @ axis)) >= ra + rb - tol:
                return False
        return True

    def transformed(self, rotation: np.ndarray, translation: np.ndarray, scale: float = 1.0) -> OrientedBox:
        """Box under the similarity ``x ↦ scale · R x + t``."""
        rot = np.asarray(rotation, dtype=np.float64)
        return OrientedBox(scale * rot @ self.center + np.asarray(translation, dtype=np.float64), self.extents * scale, rot @ self.rotation)

    # ----------------------------------------------------------- (de)serialise
    def to_dict(self) -> dict[str, Any]:
        return {"center": self.center.tolist(), "extents": self.extents.tolist(), "rotation": self.rotation.tolist()}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> OrientedBox:
        missing = [k for k in ("center", "extents", "rotation") if k not in data]
        if missing:
            raise InvalidDataError(f"{_SOURCE}: missing key(s) {missing}")
        return cls(data["center"], data["extents"], data["rotation"])
