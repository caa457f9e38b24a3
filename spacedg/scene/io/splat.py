"""The ``.splat`` format (antimatter15's web viewer): 32 bytes per Gaussian, little endian.

Record layout:

- bytes 0–11: position, float32 × 3 (scene units).
- bytes 12–23: **linear** scale (standard deviations), float32 × 3.
- bytes 24–27: colour RGBA, uint8 × 4. ``A / 255`` is the opacity; ``c / 255`` is the
  base colour in [0, 1], stored in spacedg as the SH DC term ``(c/255 − 0.5) / SH_C0``.
- bytes 28–31: rotation quaternion w, x, y, z, uint8 × 4, decoded ``(q − 128) / 128`` and
  then normalised.

The format has no spherical harmonics beyond degree 0, no instance ids and no cameras.

Zero quaternions (all four bytes 128) have no rotation. None of the real files in
``shared/data/splats`` hold one; :func:`read_splat` refuses them unless called with
``zero_quaternions="identity"``, which maps them to (1, 0, 0, 0) — never silently.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import FileValueError, PathLike, as_path, atomic_write, require_file
from spacedg.render.gaussians import SH_C0, Gaussians

#: Bytes per Gaussian.
RECORD_BYTES = 32
_DTYPE = np.dtype([("position", "<f4", (3,)), ("scale", "<f4", (3,)), ("rgba", "u1", (4,)), ("rot", "u1", (4,))])
assert _DTYPE.itemsize == RECORD_BYTES


def _decode_quats(path: str, raw: np.ndarray, zero_quaternions: str) -> np.ndarray:
    q = (raw.astype(np.float64) - 128.0) / 128.0
    norms = np.linalg.norm(q, axis=1)
    zero = norms == 0.0
    if zero.any():
        rows = np.flatnonzero(zero)
        if zero_quaternions != "identity":
            raise FileValueError(
                f"{path}: {rows.size} of {len(q)} Gaussians have a zero rotation (bytes 28–31 all 128; first at record {rows[0]}); "
                "fix the file, or pass zero_quaternions='identity' to read them as unrotated"
            )
        q[zero] = (1.0, 0.0, 0.0, 0.0)
        norms[zero] = 1.0
    return (q / norms[:, None]).astype(np.float32)


def read_splat(path: PathLike, *, zero_quaternions: Literal["error", "identity"] = "error") -> Gaussians:
    """Read a ``.splat`` file into degree-0 :class:`Gaussians` (see the module docstring).

    Args:
        path: the ``.splat`` file.
        zero_quaternions: ``"error"`` (default) refuses records whose rotation decodes to
            zero; ``"identity"`` maps them to (1, 0, 0, 0).

    Raises:
        FileFormatError: missing file or a size that is not a multiple of 32 bytes.
        FileValueError: zero quaternions (with ``"error"``), NaN/Inf or negative values.
    """
    if zero_quaternions not in ("error", "identity"):
        raise InvalidDataError(f"read_splat: zero_quaternions must be 'error' or 'identity', got {zero_quaternions!r}")
    p = as_path(path, ".splat file")
    size = require_file(p, ".splat file")
    if size % RECORD_BYTES:
        raise _size_error(p, size)
    count = size // RECORD_BYTES
    records = np.fromfile(p, dtype=_DTYPE, count=count)
    if records.shape[0] != count:
        raise FileFormatError(f"{p}: file shrank while reading ({records.shape[0]} of {count} records); is another process writing it?")
    rgba = records["rgba"].astype(np.float64)
    sh = np.empty((count, 1, 3), dtype=np.float32)
    sh[:, 0, :] = (rgba[:, :3] / 255.0 - 0.5) / SH_C0
    opacities = (rgba[:, 3] / 255.0).astype(np.float32)
    quats = _decode_quats(str(p), records["rot"], zero_quaternions)
    try:
        return Gaussians(records["position"], quats, records["scale"], opacities, sh, source=str(p))
    except InvalidDataError as err:
        raise FileValueError(str(err)) from err


def _size_error(path: object, size: int) -> FileFormatError:
    return FileFormatError(
        f"{path}: size {size} bytes is not a multiple of {RECORD_BYTES} (the .splat record size); "
        f"the file is truncated or not a .splat file ({size % RECORD_BYTES} stray bytes)"
    )


def _encode_quats(quats: np.ndarray) -> np.ndarray:
    q = quats.astype(np.float64)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return np.clip(np.rint(q * 128.0 + 128.0), 0, 255).astype(np.uint8)


def write_splat(path: PathLike, gaussians: Gaussians, *, allow_lossy: bool = False) -> None:
    """Write degree-0 Gaussians as a ``.splat`` file, atomically.

    Quantisation is what the format defines: colour ``round(255 · (0.5 + SH_C0 · sh_dc))``,
    opacity ``round(255 · opacity)``, rotation ``round(128 · q + 128)`` clipped to [0, 255];
    positions and scales are stored as float32, unchanged. Losses beyond that quantisation
    need ``allow_lossy=True``: SH bands above 0 (view-dependent colour) are dropped, and
    base colours outside [0, 1] are clamped. Instance ids are never stored (the format has
    no field for them).

    Raises:
        InvalidDataError: SH degree > 0 or colours outside [0, 1] without ``allow_lossy``.
    """
    if not isinstance(gaussians, Gaussians):
        raise InvalidDataError(f"write_splat: expected Gaussians, got {type(gaussians).__name__}")
    if gaussians.sh_degree > 0 and not allow_lossy:
        raise InvalidDataError(
            f"write_splat {path}: the Gaussians have SH degree {gaussians.sh_degree}; .splat stores only the base colour, "
            "so view-dependent colour (SH bands 1+) would be lost. Pass allow_lossy=True to drop it, or write a .ply"
        )
    colour = 255.0 * (0.5 + SH_C0 * gaussians.sh[:, 0, :].astype(np.float64))
    outside = (colour < -0.5) | (colour >= 255.5)
    if outside.any() and not allow_lossy:
        rows = np.flatnonzero(outside.any(axis=1))
        raise InvalidDataError(
            f"write_splat {path}: {rows.size} of {len(gaussians)} base colours lie outside [0, 1] (first at index {rows[0]}: "
            f"{(colour[rows[0]] / 255.0).round(4).tolist()}); .splat stores 8-bit colour, so they would be clamped. "
            "Pass allow_lossy=True to clamp them"
        )
    records = np.zeros(len(gaussians), dtype=_DTYPE)
    records["position"] = gaussians.means
    records["scale"] = gaussians.scales
    records["rgba"][:, :3] = np.clip(np.rint(colour), 0, 255).astype(np.uint8)
    records["rgba"][:, 3] = np.clip(np.rint(gaussians.opacities.astype(np.float64) * 255.0), 0, 255).astype(np.uint8)
    records["rot"] = _encode_quats(gaussians.quats)
    with atomic_write(path, "wb") as handle:
        handle.write(records.view(np.uint8).data if records.size else b"")
