"""Surface samplers that turn simple shapes into flat "surfel" Gaussians.

A shape's surface is sampled on a jittered grid with spacing ``h`` metres (one Gaussian per
cell), and each sample becomes a thin disk Gaussian: standard deviation ``0.6·h`` along the
surface, ``min(0.1·h, 2 mm)`` along the normal, its local z axis on the surface normal.
Every sampler returns :class:`Surfels` in the part's own frame; :func:`Surfels.transformed`
moves them, and :func:`surfels_to_arrays` makes Gaussian parameters.

Shapes: boxes (any subset of faces), conical frusta (cylinders, lamp shades, pots, vases)
with optional caps, and ellipsoids with optional noise displacement (foliage, cushions).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from spacedg.render.gaussians import quats_from_matrices
from spacedg.scene.synthetic.textures import fbm

TANGENT_SIGMA = 0.6  # × spacing
NORMAL_SIGMA = 0.1  # × spacing, capped at MAX_NORMAL_SIGMA
MAX_NORMAL_SIGMA = 0.002  # metres


@dataclass
class Surfels:
    """Surface samples: positions, unit normals, a unit tangent, uv (metres), spacing (metres)."""

    points: np.ndarray
    normals: np.ndarray
    tangents: np.ndarray
    uv: np.ndarray
    spacing: np.ndarray

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def transformed(self, rotation: np.ndarray, translation: np.ndarray) -> Surfels:
        rot = np.asarray(rotation, dtype=np.float64)
        return Surfels(
            self.points @ rot.T + translation, self.normals @ rot.T, self.tangents @ rot.T, self.uv, self.spacing
        )

    @staticmethod
    def concat(parts: list[Surfels]) -> Surfels:
        parts = [p for p in parts if len(p)]
        if not parts:
            z = np.zeros((0, 3))
            return Surfels(z, z, z, np.zeros((0, 2)), np.zeros(0))
        return Surfels(*(np.concatenate([getattr(p, f) for p in parts]) for f in ("points", "normals", "tangents", "uv", "spacing")))


def _jittered_grid(size_u: float, size_v: float, h: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    nu = max(1, math.ceil(size_u / h))
    nv = max(1, math.ceil(size_v / h))
    iu, iv = np.meshgrid(np.arange(nu), np.arange(nv), indexing="ij")
    u = (iu.ravel() + rng.uniform(0.15, 0.85, iu.size)) * (size_u / nu)
    v = (iv.ravel() + rng.uniform(0.15, 0.85, iv.size)) * (size_v / nv)
    return u, v


def rectangle(
    origin: np.ndarray, axis_u: np.ndarray, axis_v: np.ndarray, size_u: float, size_v: float, h: float, rng: np.random.Generator
) -> Surfels:
    """A planar rectangle ``origin + u·axis_u + v·axis_v``, u∈[0,size_u], v∈[0,size_v]; normal = u × v."""
    u, v = _jittered_grid(size_u, size_v, h, rng)
    axis_u, axis_v = np.asarray(axis_u, float), np.asarray(axis_v, float)
    normal = np.cross(axis_u, axis_v)
    pts = origin + u[:, None] * axis_u + v[:, None] * axis_v
    n = len(u)
    return Surfels(pts, np.tile(normal, (n, 1)), np.tile(axis_u, (n, 1)), np.stack([u, v], 1), np.full(n, h))


_FACES = {
    # name: (normal axis index, sign)
    "-x": (0, -1), "+x": (0, 1), "-y": (1, -1), "+y": (1, 1), "-z": (2, -1), "+z": (2, 1),
}


def box(size: np.ndarray, h: float, rng: np.random.Generator, faces: tuple[str, ...] = tuple(_FACES)) -> Surfels:
    """Faces of an axis-aligned box centred at the origin with full side lengths ``size``."""
    size = np.asarray(size, dtype=np.float64)
    half = size / 2
    out = []
    eye = np.eye(3)
    for name in faces:
        axis, sign = _FACES[name]
        a, b = (axis + 1) % 3, (axis + 2) % 3  # e_a × e_b = e_axis
        if sign < 0:
            a, b = b, a  # keep the normal (u × v) pointing outwards
        origin = -half.copy()
        origin[axis] = sign * half[axis]
        origin[a], origin[b] = -half[a], -half[b]
        out.append(rectangle(origin, eye[a], eye[b], size[a], size[b], h, rng))
    return Surfels.concat(out)


def frustum(
    radius_bottom: float,
    radius_top: float,
    height: float,
    h: float,
    rng: np.random.Generator,
    caps: tuple[bool, bool] = (True, True),
) -> Surfels:
    """Side (and optional bottom/top caps) of a conical frustum on the z axis, z ∈ [0, height]."""
    mean_r = 0.5 * (radius_bottom + radius_top)
    slant = math.hypot(height, radius_bottom - radius_top)
    circ = 2 * math.pi * max(mean_r, 1e-4)
    s, z_frac = _jittered_grid(circ, slant, h, rng)
    theta = s / circ * 2 * math.pi
    t = z_frac / slant
    r = radius_bottom + (radius_top - radius_bottom) * t
    z = t * height
    c, sn = np.cos(theta), np.sin(theta)
    pts = np.stack([r * c, r * sn, z], axis=1)
    slope = (radius_bottom - radius_top) / slant
    normal = np.stack([c * height / slant, sn * height / slant, np.full_like(c, slope)], axis=1)
    tangent = np.stack([-sn, c, np.zeros_like(c)], axis=1)
    parts = [Surfels(pts, normal, tangent, np.stack([s, z_frac], 1), np.full(len(s), h))]
    for is_top, (want, radius, zc) in enumerate(((caps[0], radius_bottom, 0.0), (caps[1], radius_top, height))):
        if not want or radius <= 0:
            continue
        u, v = _jittered_grid(2 * radius, 2 * radius, h, rng)
        u, v = u - radius, v - radius
        keep = u * u + v * v <= radius * radius
        u, v = u[keep], v[keep]
        n = len(u)
        nz = 1.0 if is_top else -1.0
        parts.append(
            Surfels(
                np.stack([u, v, np.full(n, zc)], 1),
                np.tile([0.0, 0.0, nz], (n, 1)),
                np.tile([1.0, 0.0, 0.0], (n, 1)),
                np.stack([u, v], 1),
                np.full(n, h),
            )
        )
    return Surfels.concat(parts)


def ellipsoid(
    radii: np.ndarray, h: float, rng: np.random.Generator, bumpiness: float = 0.0, z_min: float | None = None
) -> Surfels:
    """Ellipsoid centred at the origin; ``bumpiness`` displaces it radially by fractal noise
    (fraction of the radius); samples below ``z_min`` (local) are dropped."""
    radii = np.asarray(radii, dtype=np.float64)
    a, b, c = radii
    area = 4 * math.pi * ((a**1.6 * b**1.6 + a**1.6 * c**1.6 + b**1.6 * c**1.6) / 3) ** (1 / 1.6)
    n = max(8, int(area * (1 + bumpiness) / (h * h)))
    i = np.arange(n) + rng.uniform(0.1, 0.9, n)
    phi = np.arccos(np.clip(1 - 2 * i / n, -1, 1))
    theta = math.pi * (1 + 5**0.5) * i
    unit = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)
    radial = np.ones(n)
    if bumpiness > 0:
        seed = int(rng.integers(0, 2**31 - 1))
        radial = 1 + bumpiness * (fbm(theta * 1.3, phi * 4.0, seed, 3) - 0.5) * 2
    pts = unit * radii * radial[:, None]
    normals = unit / radii * radii.mean()
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    helper = np.where(np.abs(normals[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    tangent = np.cross(helper, normals)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    uv = np.stack([theta * radii.mean(), phi * radii.mean()], 1)
    s = Surfels(pts, normals, tangent, uv, np.full(n, h))
    if z_min is not None:
        keep = pts[:, 2] >= z_min
        s = Surfels(s.points[keep], s.normals[keep], s.tangents[keep], s.uv[keep], s.spacing[keep])
    return s


def frames_to_quats(tangents: np.ndarray, normals: np.ndarray) -> np.ndarray:
    """(N, 4) wxyz quaternions of rotations whose columns are (tangent, normal × tangent, normal)."""
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    t = tangents - (tangents * n).sum(1, keepdims=True) * n
    bad = np.linalg.norm(t, axis=1) < 1e-9
    if bad.any():
        alt = np.where(np.abs(n[bad, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
        t[bad] = np.cross(alt, n[bad])
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(n, t)
    return quats_from_matrices(np.stack([t, b, n], axis=2))  # columns = (t, b, n)


def surfel_scales(spacing: np.ndarray) -> np.ndarray:
    """(N, 3) standard deviations (tangent, bitangent, normal) for surfels of the given spacing."""
    t = TANGENT_SIGMA * spacing
    n = np.minimum(NORMAL_SIGMA * spacing, MAX_NORMAL_SIGMA)
    return np.stack([t, t, n], axis=1)
