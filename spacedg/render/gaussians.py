"""The Gaussians container and real spherical-harmonics (SH) evaluation.

Conventions (the whole engine uses these; readers convert file conventions once):

- ``means``      (N, 3) float32, metres, world frame.
- ``quats``      (N, 4) float32, rotation quaternion **w, x, y, z**, unit norm.
- ``scales``     (N, 3) float32, metres, standard deviations along the rotated axes
  (activated: ``exp`` already applied to the log-scales of 3DGS files).
- ``opacities``  (N,)   float32 in [0, 1] (activated: ``sigmoid`` already applied).
- ``sh``         (N, K, 3) float32 SH coefficients per colour channel, K = (degree+1)²,
  degree 0–3, ordered as in the original 3DGS code, each within ±:data:`SH_MAX`. The colour
  seen along unit direction ``d`` (from the camera centre to the Gaussian) is
  ``0.5 + Σ_k sh[:, k] · Y_k(d)``; the renderer clamps it at 0. For a degree-0 scene that is
  ``0.5 + SH_C0 · sh[:, 0]``.
- ``instance_ids`` (N,) int32, the :class:`~spacedg.scene.model.Instance` id a Gaussian
  belongs to, or -1 for none (walls, clutter). Optional.

Arrays are stored read-only so a ``Gaussians`` can be shared between views, caches and
threads without copies; derive new ones with :meth:`Gaussians.subset`,
:meth:`Gaussians.transformed` or :func:`dataclasses.replace`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from functools import lru_cache

import numpy as np

from spacedg._checks import (
    as_array,
    first_bad,
    require_finite,
    require_range,
    require_rotation,
    require_same_length,
    require_shape,
)
from spacedg.errors import InvalidDataError

SH_C0 = 0.28209479177387814
_SH_C1 = 0.4886025119029199
_SH_C2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792, 0.5462742152960396)
_SH_C3 = (
    -0.5900435899266435,
    2.890611442640554,
    -0.4570457994644658,
    0.3731763325901154,
    -0.4570457994644658,
    1.445305721320277,
    -0.5900435899266435,
)
#: Number of SH coefficients per channel for degrees 0..3.
SH_COEFFS = {0: 1, 1: 4, 2: 9, 3: 16}
#: Tolerance on | ||q|| - 1 | for a quaternion to count as unit (float32 data).
QUAT_UNIT_TOL = 1e-4
#: Largest |SH coefficient| accepted. The colour ``0.5 + Σ sh·Y`` then stays below ~10⁵
#: (sRGB-encoded; |Y_k| < 0.6 for the 16 basis functions), i.e. at most ~10¹² × diffuse white
#: in linear light (the sun's disc is ~10⁷ × white paper): every stage after the render
#: (exposure gains, noise, haze) stays finite in float32. A larger coefficient is a corrupt
#: file, not light, and is refused with the file and field named rather than rendered as NaN.
SH_MAX = 1e4


def sh_degree_of(num_coeffs: int) -> int:
    """Return the SH degree for ``num_coeffs`` coefficients per channel (1, 4, 9 or 16)."""
    for degree, count in SH_COEFFS.items():
        if count == num_coeffs:
            return degree
    raise InvalidDataError(f"{num_coeffs} SH coefficients per channel is not (degree+1)² for a degree 0–3")


def sh_basis(degree: int, dirs: np.ndarray) -> np.ndarray:
    """Real SH basis of the 3DGS convention evaluated at unit directions.

    Args:
        degree: highest band, 0–3; only the bands up to it are computed.
        dirs: (M, 3) unit vectors (x, y, z): a numpy array or a torch tensor (any device).

    Returns:
        (M, (degree+1)²) basis values, same float dtype (and array type) as ``dirs``.
    """
    xp = _array_namespace(dirs)
    x, y, z = dirs[:, 0], dirs[:, 1], dirs[:, 2]
    cols = [xp.full_like(x, SH_C0)]
    if degree >= 1:
        cols += [-_SH_C1 * y, _SH_C1 * z, -_SH_C1 * x]
    if degree >= 2:
        xx, yy, zz, xy, yz, xz = x * x, y * y, z * z, x * y, y * z, x * z
        cols += [
            _SH_C2[0] * xy,
            _SH_C2[1] * yz,
            _SH_C2[2] * (2.0 * zz - xx - yy),
            _SH_C2[3] * xz,
            _SH_C2[4] * (xx - yy),
        ]
    if degree >= 3:
        cols += [
            _SH_C3[0] * y * (3.0 * xx - yy),
            _SH_C3[1] * xy * z,
            _SH_C3[2] * y * (4.0 * zz - xx - yy),
            _SH_C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy),
            _SH_C3[4] * x * (4.0 * zz - xx - yy),
            _SH_C3[5] * z * (xx - yy),
            _SH_C3[6] * x * (xx - 3.0 * yy),
        ]
    return xp.stack(cols, -1)


def _array_namespace(array: object) -> object:
    """``numpy`` for arrays, ``torch`` for tensors (so one SH basis serves both paths)."""
    if type(array).__module__.startswith("torch"):
        import torch

        return torch
    return np


def eval_sh(sh: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """Colour of each Gaussian seen along ``dirs``: ``0.5 + Σ_k sh[:, k] Y_k(d)`` (unclamped).

    Only the bands present in ``sh`` are evaluated, so a degree-0 scene costs one multiply.

    Args:
        sh: (N, K, 3) coefficients.
        dirs: (N, 3) unit viewing directions (camera centre → Gaussian); ignored for K = 1.
    """
    degree = sh_degree_of(sh.shape[1])
    if degree == 0:
        return SH_C0 * sh[:, 0, :] + 0.5
    basis = sh_basis(degree, dirs.astype(sh.dtype, copy=False))
    return np.einsum("nk,nkc->nc", basis, sh) + 0.5


def _fibonacci_sphere(count: int) -> np.ndarray:
    i = np.arange(count, dtype=np.float64) + 0.5
    phi = np.arccos(1.0 - 2.0 * i / count)
    theta = math.pi * (1.0 + 5.0**0.5) * i
    return np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], axis=1)


@lru_cache(maxsize=1)
def _sample_dirs() -> np.ndarray:
    return _fibonacci_sphere(64)


def sh_rotation_matrix(rotation: np.ndarray, degree: int) -> np.ndarray:
    """Matrix ``M`` with ``sh_rotated[:, :, c] = M @ sh[:, :, c]`` for a world rotation ``R``.

    The rotated field satisfies ``f'(R d) = f(d)``. Each band is closed under rotation, so
    ``M`` is block diagonal; it is solved per band by least squares on 64 well-spread
    directions in float64 (residual ~1e-15), which avoids hand-written Wigner matrices.
    """
    dirs = _sample_dirs()
    basis = sh_basis(degree, dirs)  # Y(d)
    basis_rot = sh_basis(degree, dirs @ np.asarray(rotation, dtype=np.float64).T)  # Y(R d)
    # f'(R d) = Y(R d)·c' must equal f(d) = Y(d)·c for every d, so c' = M c with Y(R d) M = Y(d)
    matrix, *_ = np.linalg.lstsq(basis_rot, basis, rcond=None)
    matrix[0, :] = 0.0
    matrix[:, 0] = 0.0
    matrix[0, 0] = 1.0
    return matrix


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a ⊗ b`` of wxyz quaternions, broadcasting over leading axes."""
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quats_from_matrices(rotations: np.ndarray) -> np.ndarray:
    """(N, 3, 3) proper rotation matrices → (N, 4) wxyz unit quaternions, float64, w >= 0.

    Vectorised Shepperd's method: each row divides by the largest of 4w², 4x², 4y², 4z², so
    no branch loses precision.
    """
    m = np.asarray(rotations, dtype=np.float64).reshape(-1, 3, 3)
    trace = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    cand = np.stack([trace, m[:, 0, 0], m[:, 1, 1], m[:, 2, 2]], axis=1)
    k = cand.argmax(axis=1)
    s = np.sqrt(np.maximum(1.0 + 2.0 * cand[np.arange(len(m)), k] - trace, 1e-300)) * 2.0
    # 4·(wx, wy, wz, xy, xz, yz) products read off the matrix
    wx, wy, wz = m[:, 2, 1] - m[:, 1, 2], m[:, 0, 2] - m[:, 2, 0], m[:, 1, 0] - m[:, 0, 1]
    xy, xz, yz = m[:, 0, 1] + m[:, 1, 0], m[:, 0, 2] + m[:, 2, 0], m[:, 1, 2] + m[:, 2, 1]
    quarter = 0.25 * s
    q = np.select(
        [k[:, None] == 0, k[:, None] == 1, k[:, None] == 2, k[:, None] == 3],
        [
            np.stack([quarter, wx / s, wy / s, wz / s], 1),
            np.stack([wx / s, quarter, xy / s, xz / s], 1),
            np.stack([wy / s, xy / s, quarter, yz / s], 1),
            np.stack([wz / s, xz / s, yz / s, quarter], 1),
        ],
    )
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.where(q[:, :1] < 0, -q, q)


def quat_from_matrix(rotation: np.ndarray) -> np.ndarray:
    """wxyz unit quaternion (w >= 0) of one proper rotation matrix."""
    return quats_from_matrices(np.asarray(rotation)[None])[0]


def quat_to_matrix(quats: np.ndarray) -> np.ndarray:
    """(N, 4) wxyz unit quaternions → (N, 3, 3) rotation matrices (same dtype).

    Works on numpy arrays and torch tensors (any device) alike.
    """
    xp = _array_namespace(quats)
    w, x, y, z = quats[:, 0], quats[:, 1], quats[:, 2], quats[:, 3]
    rows = [
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
    ]
    return xp.stack(rows, -1).reshape(-1, 3, 3)


def _readonly(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


@dataclass(frozen=True, eq=False)
class Gaussians:
    """A set of 3D Gaussians in activated units (see the module docstring).

    Construction validates everything and raises :class:`InvalidDataError` naming the
    ``source`` (a file path or ``"<memory>"``), the field, the number of bad entries and the
    first bad index: NaN/Inf, zero or non-unit quaternions, negative scales, opacities outside
    [0, 1], SH coefficients beyond ±:data:`SH_MAX`, instance ids below -1, mismatched lengths,
    an SH count that is not a degree 0–3. Any finite non-negative scale is accepted: both
    render backends project covariances in float64, so a Gaussian metres or light-years wide
    covers the view the same way in both.
    """

    means: np.ndarray
    quats: np.ndarray
    scales: np.ndarray
    opacities: np.ndarray
    sh: np.ndarray
    instance_ids: np.ndarray | None = None
    source: str = field(default="<memory>", compare=False)

    def __post_init__(self) -> None:
        src = self.source
        conv = {
            "means": as_array(self.means, "means", src, np.float32),
            "quats": as_array(self.quats, "quats", src, np.float32),
            "scales": as_array(self.scales, "scales", src, np.float32),
            "opacities": as_array(self.opacities, "opacities", src, np.float32),
            "sh": as_array(self.sh, "sh", src, np.float32),
        }
        if self.instance_ids is not None:
            ids = np.asarray(self.instance_ids)
            if ids.size and not np.issubdtype(ids.dtype, np.integer):
                raise InvalidDataError(f"{src}: field 'instance_ids': expected integers, got {ids.dtype}")
            conv["instance_ids"] = as_array(ids, "instance_ids", src, np.int32)
        for name, array in conv.items():
            object.__setattr__(self, name, _readonly(array))
        self._validate()

    def _validate(self) -> None:
        src = self.source
        require_shape(self.means, (None, 3), "means", src)
        require_shape(self.quats, (None, 4), "quats", src)
        require_shape(self.scales, (None, 3), "scales", src)
        require_shape(self.opacities, (None,), "opacities", src)
        require_shape(self.sh, (None, None, 3), "sh", src)
        lengths = {
            "means": self.means.shape[0],
            "quats": self.quats.shape[0],
            "scales": self.scales.shape[0],
            "opacities": self.opacities.shape[0],
            "sh": self.sh.shape[0],
        }
        if self.instance_ids is not None:
            require_shape(self.instance_ids, (None,), "instance_ids", src)
            lengths["instance_ids"] = self.instance_ids.shape[0]
        require_same_length(lengths, src)
        try:
            sh_degree_of(self.sh.shape[1])
        except InvalidDataError as err:
            raise InvalidDataError(f"{src}: field 'sh': {err}") from err
        for name in ("means", "quats", "scales", "opacities", "sh"):
            require_finite(getattr(self, name), name, src)
        norms = np.linalg.norm(self.quats.astype(np.float64), axis=1)
        zero = norms < 1e-12
        if zero.any():
            count, row = first_bad(zero)
            raise InvalidDataError(
                f"{src}: field 'quats': {count} of {len(norms)} quaternions are zero (first at index {row}); "
                "a zero quaternion has no rotation: drop those Gaussians or set them to (1, 0, 0, 0)"
            )
        off = np.abs(norms - 1.0) > QUAT_UNIT_TOL
        if off.any():
            count, row = first_bad(off)
            raise InvalidDataError(
                f"{src}: field 'quats': {count} of {len(norms)} quaternions are not unit "
                f"(first at index {row}, norm {norms[row]:.6g}); normalise them (q / ||q||) before building Gaussians"
            )
        require_range(
            self.scales, 0.0, None, "scales", src,
            "Scales are activated standard deviations in metres; log-scales from a 3DGS file must be exponentiated (read_ply does this).",
        )
        require_range(
            self.sh, -SH_MAX, SH_MAX, "sh", src,
            f"SH coefficients (f_dc_*, f_rest_* in a 3DGS PLY) beyond ±{SH_MAX:g} would be light brighter than "
            "10¹² × diffuse white: the file is corrupt or not 3DGS data; repair or drop those Gaussians.",
        )
        require_range(
            self.opacities, 0.0, 1.0, "opacities", src,
            "Opacities are activated (sigmoid applied); logits from a 3DGS file must go through read_ply.",
        )
        if self.instance_ids is not None:
            require_range(self.instance_ids, -1, None, "instance_ids", src, "Use -1 for Gaussians that belong to no instance.")

    # ------------------------------------------------------------------ basics
    def __len__(self) -> int:
        return int(self.means.shape[0])

    @property
    def sh_degree(self) -> int:
        """Highest SH band stored (0–3)."""
        return sh_degree_of(self.sh.shape[1])

    @property
    def nbytes(self) -> int:
        """Memory held by the arrays, in bytes (used by byte-bounded caches)."""
        arrays = [self.means, self.quats, self.scales, self.opacities, self.sh]
        if self.instance_ids is not None:
            arrays.append(self.instance_ids)
        return int(sum(a.nbytes for a in arrays))

    def base_colors(self) -> np.ndarray:
        """(N, 3) view-independent colour ``0.5 + SH_C0 · sh[:, 0]`` (unclamped)."""
        return SH_C0 * self.sh[:, 0, :] + 0.5

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """Axis-aligned (min, max) of the centres, metres; zeros for an empty set."""
        if len(self) == 0:
            return np.zeros(3), np.zeros(3)
        return self.means.min(axis=0).astype(np.float64), self.means.max(axis=0).astype(np.float64)

    # ------------------------------------------------------------- factories
    @classmethod
    def from_colors(
        cls,
        means: np.ndarray,
        quats: np.ndarray,
        scales: np.ndarray,
        opacities: np.ndarray,
        colors: np.ndarray,
        *,
        sh_degree: int = 0,
        instance_ids: np.ndarray | None = None,
        source: str = "<memory>",
    ) -> Gaussians:
        """Build Gaussians whose view-independent colour is ``colors`` (N, 3), in [0, 1] by convention."""
        colors = np.asarray(colors, dtype=np.float32)
        sh = np.zeros((colors.shape[0], SH_COEFFS[sh_degree], 3), dtype=np.float32)
        sh[:, 0, :] = (colors - 0.5) / SH_C0
        return cls(means, quats, scales, opacities, sh, instance_ids, source)

    @classmethod
    def empty(cls, sh_degree: int = 0, with_instance_ids: bool = False) -> Gaussians:
        """A zero-length set (useful as a neutral element for :meth:`concat`)."""
        return cls(
            np.zeros((0, 3)), np.zeros((0, 4)), np.zeros((0, 3)), np.zeros((0,)),
            np.zeros((0, SH_COEFFS[sh_degree], 3)),
            np.zeros((0,), np.int32) if with_instance_ids else None,
        )

    # ------------------------------------------------------------ derivation
    def subset(self, index: np.ndarray | slice) -> Gaussians:
        """Gaussians selected by a boolean mask, integer index array or slice."""
        ids = None if self.instance_ids is None else self.instance_ids[index]
        return Gaussians(
            self.means[index], self.quats[index], self.scales[index], self.opacities[index], self.sh[index],
            ids, self.source,
        )

    def with_sh_degree(self, degree: int) -> Gaussians:
        """Same Gaussians with SH padded with zero bands up to ``degree`` (never truncates)."""
        if degree < self.sh_degree:
            raise InvalidDataError(
                f"{self.source}: cannot lower SH degree {self.sh_degree} to {degree} without losing colour; "
                "slice sh[:, :(degree+1)**2] yourself if that is intended"
            )
        if degree == self.sh_degree:
            return self
        sh = np.zeros((len(self), SH_COEFFS[degree], 3), dtype=np.float32)
        sh[:, : self.sh.shape[1]] = self.sh
        return replace(self, sh=sh)

    def with_instance_ids(self, ids: np.ndarray | int) -> Gaussians:
        """Same Gaussians with every (or each) Gaussian assigned to an instance id."""
        ids = np.broadcast_to(np.asarray(ids, dtype=np.int32), (len(self),)).copy()
        return replace(self, instance_ids=ids)

    @staticmethod
    def concat(parts: Sequence[Gaussians], source: str = "<memory>") -> Gaussians:
        """Concatenate sets; SH is padded to the highest degree, missing instance ids become -1."""
        if not parts:
            return Gaussians.empty()
        degree = max(p.sh_degree for p in parts)
        parts = [p.with_sh_degree(degree) for p in parts]
        any_ids = any(p.instance_ids is not None for p in parts)
        ids = (
            np.concatenate(
                [p.instance_ids if p.instance_ids is not None else np.full(len(p), -1, np.int32) for p in parts]
            )
            if any_ids
            else None
        )
        return Gaussians(
            np.concatenate([p.means for p in parts]),
            np.concatenate([p.quats for p in parts]),
            np.concatenate([p.scales for p in parts]),
            np.concatenate([p.opacities for p in parts]),
            np.concatenate([p.sh for p in parts]),
            ids,
            source,
        )

    def transformed(
        self,
        rotation: np.ndarray | None = None,
        translation: np.ndarray | None = None,
        scale: float = 1.0,
    ) -> Gaussians:
        """Apply the similarity ``x ↦ scale · R x + t`` to positions, orientations, sizes and SH.

        SH bands above 0 are rotated with :func:`sh_rotation_matrix`, so view-dependent colour
        follows the object. ``scale`` must be positive.
        """
        if not (scale > 0 and math.isfinite(scale)):
            raise InvalidDataError(f"{self.source}: transform scale must be a positive finite number, got {scale}")
        rot = np.eye(3) if rotation is None else np.asarray(rotation, dtype=np.float64)
        require_rotation(rot, "rotation", "Gaussians.transformed")
        t = np.zeros(3) if translation is None else np.asarray(translation, dtype=np.float64).reshape(3)
        means = (scale * (self.means.astype(np.float64) @ rot.T) + t).astype(np.float32)
        q_rot = quat_from_matrix(rot)
        quats = quat_multiply(q_rot[None, :], self.quats.astype(np.float64))
        quats /= np.linalg.norm(quats, axis=1, keepdims=True)
        sh = self.sh
        if self.sh_degree > 0:
            matrix = sh_rotation_matrix(rot, self.sh_degree)
            sh = np.einsum("kj,njc->nkc", matrix, self.sh.astype(np.float64)).astype(np.float32)
        return replace(
            self,
            means=means,
            quats=quats.astype(np.float32),
            scales=(self.scales.astype(np.float64) * scale).astype(np.float32),
            sh=sh,
        )
