"""Other Gaussian ``.ply`` layouts, decoded from their PLY records into activated :class:`Gaussians`.

:func:`~spacedg.scene.io.ply.read_ply` parses the PLY container and hands the records here
when the vertex element is not the INRIA layout:

- **PlayCanvas / SuperSplat compressed ply** (``*.compressed.ply``, written by SuperSplat and
  ``splat-transform``): a ``chunk`` element (one per 256 Gaussians) with float ``min_x..max_z``,
  ``min_scale_x..max_scale_z`` and optionally ``min_r..max_b``; a ``vertex`` element with four
  ``uint`` words ``packed_position`` (11-10-11 bit unorm, lerped between the chunk's min and
  max), ``packed_rotation`` (2 bits: index of the largest of ``(rot_0, rot_1, rot_2, rot_3)`` =
  ``(w, x, y, z)``, then the other three in order as 10-bit unorm ``v`` with component
  ``(v − ½)·√2``; the largest is ``√(1 − a² − b² − c²)``), ``packed_scale`` (11-10-11 unorm
  lerped between the chunk's log-scale bounds, then ``exp``) and ``packed_color`` (8-8-8-8:
  colour ``0.5 + SH_C0·f_dc`` (lerped between the chunk's colour bounds when present) and
  the **activated** opacity); an optional ``sh`` element of ``uchar f_rest_i`` decoded as
  ``v·8/255 − 4`` (channel-major like the INRIA layout).
- **Colour-only ply**: ``red green blue`` (``uchar`` 0–255 or float 0–1) instead of
  ``f_dc_*``. With the 3DGS properties (``opacity``, ``scale_*``, ``rot_*``) they are read as
  usual; without them (a coloured point cloud) every point becomes an isotropic, opaque
  Gaussian whose standard deviation is half the mean spacing of the points in its voxel.
- **Mip-Splatting's 3D filter** (``filter_3D``, a per-Gaussian standard deviation in scene
  units) is folded in as Mip-Splatting renders it: ``s' = √(s² + f²)`` per axis and
  ``o' = o · √(Π s² / Π s'²)``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import FileValueError
from spacedg.render.gaussians import SH_C0, SH_COEFFS, Gaussians

__all__ = ["CHUNK_SIZE", "is_compressed", "decode_compressed", "decode_colour_points", "apply_filter_3d"]

#: Gaussians per chunk of the compressed layout.
CHUNK_SIZE = 256
_CHUNK_REQUIRED = ("min_x", "min_y", "min_z", "max_x", "max_y", "max_z",
                   "min_scale_x", "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z")
_PACKED = ("packed_position", "packed_rotation", "packed_scale", "packed_color")
_SH_FOR_REST = {0: 0, 9: 1, 24: 2, 45: 3}


def is_compressed(vertex_names: set[str]) -> bool:
    """Whether a vertex element holds the PlayCanvas packed words."""
    return set(_PACKED) <= vertex_names


def _unorm(value: np.ndarray, shift: int, bits: int) -> np.ndarray:
    mask = (1 << bits) - 1
    return ((value >> np.uint32(shift)) & np.uint32(mask)).astype(np.float64) / mask


def _lerp(lo: np.ndarray, hi: np.ndarray, t: np.ndarray) -> np.ndarray:
    return lo * (1.0 - t) + hi * t


def decode_compressed(path: Path, elements: dict[str, np.ndarray]) -> Gaussians:
    """Gaussians from the ``chunk``, ``vertex`` and optional ``sh`` records (see the module docstring)."""
    if "chunk" not in elements:
        raise FileFormatError(f"{path}: packed vertices without a 'chunk' element; a compressed ply needs both")
    chunk, vertex = elements["chunk"], elements["vertex"]
    missing = [n for n in _CHUNK_REQUIRED if n not in (chunk.dtype.names or ())]
    if missing:
        raise FileFormatError(f"{path}: element 'chunk' lacks {missing}")
    n = vertex.shape[0]
    need = (n + CHUNK_SIZE - 1) // CHUNK_SIZE
    if chunk.shape[0] < need:
        raise FileFormatError(f"{path}: {n} packed vertices need {need} chunks of {CHUNK_SIZE}, the file has {chunk.shape[0]}")
    ci = np.arange(n) // CHUNK_SIZE

    def col(name: str) -> np.ndarray:
        return chunk[name].astype(np.float64)[ci]

    words = {k: vertex[k].astype(np.uint32) for k in _PACKED}
    def unpack_11_10_11(word: np.ndarray, field: str) -> np.ndarray:
        """x, y, z packed as 11, 10, 11 bits, each between the chunk's min_ and max_ of ``field``."""
        bits = ((21, 11), (11, 10), (0, 11))
        return np.stack([_lerp(col(f"min_{field}{axis}"), col(f"max_{field}{axis}"), _unorm(word, shift, width))
                         for axis, (shift, width) in zip("xyz", bits)], axis=1)

    means = unpack_11_10_11(words["packed_position"], "")
    log_scales = unpack_11_10_11(words["packed_scale"], "scale_")
    rot = words["packed_rotation"]
    norm = np.sqrt(2.0)  # 1 / (√2 / 2)
    abc = np.stack([(_unorm(rot, s, 10) - 0.5) * norm for s in (20, 10, 0)], axis=1)
    largest = (rot >> np.uint32(30)).astype(np.int64)
    m = np.sqrt(np.clip(1.0 - (abc**2).sum(axis=1), 0.0, None))
    quats = np.empty((n, 4))
    rows = np.arange(n)
    quats[rows, largest] = m
    slot = np.zeros(n, dtype=np.int64)
    for k in range(4):
        other = largest != k
        quats[rows[other], k] = abc[rows[other], slot[other]]
        slot[other] += 1
    colour = words["packed_color"]
    rgb = np.stack([_unorm(colour, s, 8) for s in (24, 16, 8)], axis=1)
    if {"min_r", "max_r", "min_g", "max_g", "min_b", "max_b"} <= set(chunk.dtype.names or ()):
        rgb = np.stack([_lerp(col(f"min_{c}"), col(f"max_{c}"), rgb[:, j]) for j, c in enumerate("rgb")], axis=1)
    opacities = _unorm(colour, 0, 8)
    degree = 0
    rest = None
    if "sh" in elements:
        sh_rec = elements["sh"]
        names = [name for name in (sh_rec.dtype.names or ()) if name.startswith("f_rest_")]
        if len(names) not in _SH_FOR_REST or sh_rec.shape[0] != n:
            raise FileFormatError(f"{path}: element 'sh' must hold 0/9/24/45 f_rest properties for each of the {n} vertices")
        degree = _SH_FOR_REST[len(names)]
        expected = {f"f_rest_{i}" for i in range(len(names))}
        if set(names) != expected:
            odd = sorted(set(names) - expected)[0]
            raise FileFormatError(f"{path}: element 'sh' property {odd[:40]!r} is not one of f_rest_0..f_rest_{len(names) - 1}")
        if degree:
            names = sorted(names, key=lambda s: int(s[len("f_rest_"):]))
            rest = np.stack([sh_rec[name].astype(np.float64) for name in names], axis=1) * (8.0 / 255.0) - 4.0
    k = SH_COEFFS[degree]
    sh = np.zeros((n, k, 3), dtype=np.float32)
    sh[:, 0, :] = (rgb - 0.5) / SH_C0
    if rest is not None:
        sh[:, 1:, :] = rest.reshape(n, 3, k - 1).transpose(0, 2, 1)
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    try:
        return Gaussians(means.astype(np.float32), quats.astype(np.float32), np.exp(log_scales).astype(np.float32),
                         opacities.astype(np.float32), sh, source=str(path))
    except InvalidDataError as err:
        raise FileValueError(f"{path}: {err}") from err


def _colours(path: Path, records: np.ndarray) -> np.ndarray:
    columns = []
    for name in ("red", "green", "blue"):
        values = records[name]
        if np.issubdtype(values.dtype, np.integer):
            top = np.iinfo(values.dtype).max
            columns.append(values.astype(np.float64) / (255.0 if top >= 255 else top))
        else:
            columns.append(values.astype(np.float64))
    rgb = np.stack(columns, axis=1)
    if not np.isfinite(rgb).all():
        raise FileValueError(f"{path}: red/green/blue hold NaN or Inf")
    return rgb


def point_spacing(means: np.ndarray, cells: int = 64) -> np.ndarray:
    """(N,) mean spacing of points near each point: the edge of its voxel over ∛(points in it).

    The bounding box is cut into at most ``cells`` voxels per axis (cubic voxels); a point alone
    in its voxel gets the voxel edge.
    """
    lo, hi = means.min(axis=0), means.max(axis=0)
    edge = max(float((hi - lo).max()) / cells, 1e-9)
    keys = np.floor((means - lo) / edge).astype(np.int64)
    _, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    return edge / np.cbrt(counts[inverse.reshape(-1)].astype(np.float64))


def decode_colour_points(path: Path, records: np.ndarray) -> Gaussians:
    """Gaussians from a ply whose colour is ``red green blue`` (see the module docstring)."""
    names = set(records.dtype.names or ())
    n = records.shape[0]
    means = np.stack([records[a].astype(np.float64) for a in "xyz"], axis=1)
    rgb = _colours(path, records)
    sh = np.zeros((n, 1, 3), dtype=np.float32)
    sh[:, 0, :] = (rgb - 0.5) / SH_C0
    full = {"opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"} <= names
    if full:
        with np.errstate(over="ignore", under="ignore"):
            opacities = 1.0 / (1.0 + np.exp(-records["opacity"].astype(np.float64)))
            scales = np.exp(np.stack([records[f"scale_{j}"].astype(np.float64) for j in range(3)], axis=1))
        quats = np.stack([records[f"rot_{j}"].astype(np.float64) for j in range(4)], axis=1)
        norms = np.linalg.norm(quats, axis=1, keepdims=True)
        if (norms == 0).any():
            raise FileValueError(f"{path}: {int((norms == 0).sum())} zero rotation quaternions (rot_0..3 all 0)")
        quats = quats / norms
    else:
        if n == 0:
            raise FileFormatError(f"{path}: a coloured point cloud without points")
        spacing = 0.5 * point_spacing(means)
        scales = np.repeat(spacing[:, None], 3, axis=1)
        opacities = np.full(n, 0.95)
        quats = np.zeros((n, 4))
        quats[:, 0] = 1.0
    try:
        return Gaussians(means.astype(np.float32), quats.astype(np.float32), scales.astype(np.float32),
                         opacities.astype(np.float32), sh, source=str(path))
    except InvalidDataError as err:
        raise FileValueError(f"{path}: {err}") from err


def apply_filter_3d(path: Path, gaussians: Gaussians, filter_3d: np.ndarray) -> Gaussians:
    """Fold Mip-Splatting's ``filter_3D`` (std, scene units) into scales and opacities."""
    from dataclasses import replace

    f = np.asarray(filter_3d, dtype=np.float64).reshape(-1)
    if f.shape[0] != len(gaussians) or not np.isfinite(f).all() or (f < 0).any():
        raise FileValueError(f"{path}: 'filter_3D' must be one finite value >= 0 per Gaussian")
    s2 = gaussians.scales.astype(np.float64) ** 2
    s2f = s2 + (f**2)[:, None]
    coef = np.sqrt(np.prod(s2, axis=1) / np.prod(s2f, axis=1))
    return replace(
        gaussians,
        scales=np.sqrt(s2f).astype(np.float32),
        opacities=(gaussians.opacities.astype(np.float64) * coef).astype(np.float32),
    )
