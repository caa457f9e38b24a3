""".spz (Niantic's compressed Gaussian splats), versions 2 and 3, read from the published spec.

Why spacedg reads it itself: Niantic's reference library (C++, nianticlabs/spz) ships its Python
bindings only as a source build (nanobind + a C++ compiler + zlib), not on PyPI; the PyPI
``spz`` (0.0.1, one release) is an unrelated Rust port and ``gsply`` a young third-party
package. The format is small and documented, so it is decoded here with numpy and the
standard library's ``gzip``.

Layout: a gzip stream of a 16-byte header ``<magic u32 = 0x5053474e ("NGSP"), version u32,
numPoints u32, shDegree u8, fractionalBits u8, flags u8, reserved u8>`` followed by the
attributes, each for all points in turn:

- positions: 3 × 24-bit signed fixed point, ``value / 2**fractionalBits`` (scene units);
- alphas: u8, the **activated** opacity ``v / 255``;
- colours: 3 × u8, the SH DC coefficient ``(v / 255 − 0.5) / 0.15``;
- scales: 3 × u8, log of the standard deviation ``v / 16 − 10`` (then ``exp``);
- rotations: v2 3 × u8 ``(x, y, z) = v / 127.5 − 1``, ``w = √(1 − x² − y² − z²)``; v3 one u32
  "smallest three": the 2 top bits give the index of the largest of ``(x, y, z, w)``, then the
  other three from the highest index down, each 9 bits of magnitude ``m`` and a sign bit,
  value ``±m / 511 · √½``;
- SH: ``(K − 1) × 3`` u8 per point (coefficient-major, colour channel inner), ``(v − 128) / 128``.

Axes: spz stores RUB (x right, y up, z back, OpenGL/three.js); the INRIA ply and COLMAP use
RDF (y down, z forward). :func:`read_spz` converts RUB → RDF by default (a 180° rotation about
x, applied with SH rotation), so an spz converted from an INRIA ply lines up with its COLMAP
cameras again; ``axes="file"`` keeps the stored frame. Version 4 (zstd streams) is refused
with a conversion hint; flags (antialiasing) are ignored.
"""

from __future__ import annotations

import gzip
import struct
import zlib
from typing import Literal

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import FileValueError, PathLike, as_path, require_file
from spacedg.render.gaussians import SH_COEFFS, Gaussians

__all__ = ["read_spz", "SPZ_MAGIC"]

SPZ_MAGIC = 0x5053474E
_COLOR_SCALE = 0.15
#: Largest decompressed size accepted (a hostile header cannot make us allocate more).
MAX_BYTES = 8 << 30


#: deflate cannot compress better than ~1032:1, so a stream claiming more bytes than this many
#: times the file's size (plus slack) is corrupt or a decompression bomb.
_MAX_RATIO = 1100


def _read_gzip(path: object, handle: gzip.GzipFile, size: int, what: str) -> bytes:
    """At most ``size`` decompressed bytes of ``handle`` (never more: a bomb cannot fill memory)."""
    try:
        return handle.read(size)
    except (OSError, EOFError, zlib.error) as err:
        raise FileFormatError(f"{path}: not a valid gzip stream while reading {what} ({err}); .spz files are gzip-compressed") from None


def read_spz(path: PathLike, *, axes: Literal["rdf", "file"] = "rdf") -> Gaussians:
    """Read a ``.spz`` file into activated :class:`Gaussians` (see the module docstring).

    Raises:
        FileFormatError: not gzip, bad magic, unsupported version, truncated data.
    """
    if axes not in ("rdf", "file"):
        raise InvalidDataError(f"read_spz: axes must be 'rdf' or 'file', got {axes!r}")
    p = as_path(path, ".spz file")
    file_size = require_file(p, ".spz file")
    with open(p, "rb") as raw, gzip.GzipFile(fileobj=raw, mode="rb") as stream:
        head = _read_gzip(p, stream, 16, "the header")
        if len(head) < 16:
            raise FileFormatError(f"{p}: {len(head)} bytes after gzip; an spz header alone is 16 bytes")
        magic, version, count, degree, frac_bits, _flags, _reserved = struct.unpack_from("<IIIBBBB", head, 0)
        if magic == SPZ_MAGIC and version in (2, 3) and degree <= 3:
            per_point = 9 + 1 + 3 + 3 + (4 if version >= 3 else 3) + (SH_COEFFS[degree] - 1) * 3
            need = 16 + count * per_point
            if need > MAX_BYTES or need > _MAX_RATIO * file_size + 4096:
                raise FileFormatError(
                    f"{p}: header declares {count} points ({need} bytes) but the {file_size}-byte file cannot hold them "
                    "(deflate compresses at most ~1000:1); the file is truncated or corrupt"
                )
            body = _read_gzip(p, stream, need - 16, "the points")
        else:
            body = b""
    data = head + body
    if magic != SPZ_MAGIC:
        raise FileFormatError(f"{p}: magic 0x{magic:08x} is not 'NGSP' (0x{SPZ_MAGIC:08x}); not an spz file")
    if version not in (2, 3):
        raise FileFormatError(
            f"{p}: spz version {version} is not read (versions 2 and 3 are); convert it to a ply "
            "(e.g. `splat-transform in.spz out.ply`) and import that"
        )
    if degree > 3:
        raise FileFormatError(f"{p}: SH degree {degree}; spacedg renders degrees 0–3")
    k = SH_COEFFS[degree]
    rot_bytes = 4 if version >= 3 else 3
    per_point = 9 + 1 + 3 + 3 + rot_bytes + (k - 1) * 3
    need = 16 + count * per_point
    if need > MAX_BYTES or len(data) < need:
        raise FileFormatError(f"{p}: header declares {count} points ({need} bytes) but the stream holds {len(data)} bytes; truncated")
    buf = np.frombuffer(data, dtype=np.uint8, count=need - 16, offset=16)
    o = 0

    def take(size: int) -> np.ndarray:
        nonlocal o
        part = buf[o : o + count * size].reshape(count, size)
        o += count * size
        return part

    pos = take(9).reshape(count, 3, 3).astype(np.int32)
    fixed = pos[..., 0] | (pos[..., 1] << 8) | (pos[..., 2] << 16)
    fixed = np.where(fixed & 0x800000, fixed - (1 << 24), fixed)
    means = fixed.astype(np.float64) / float(1 << frac_bits)
    opacities = take(1)[:, 0].astype(np.float64) / 255.0
    dc = (take(3).astype(np.float64) / 255.0 - 0.5) / _COLOR_SCALE
    scales = np.exp(take(3).astype(np.float64) / 16.0 - 10.0)
    raw_rot = take(rot_bytes)
    xyzw = np.zeros((count, 4))
    if version >= 3:
        comp = raw_rot.astype(np.uint32)
        word = comp[:, 0] | (comp[:, 1] << 8) | (comp[:, 2] << 16) | (comp[:, 3] << 24)
        largest = (word >> 30).astype(np.int64)
        rows = np.arange(count)
        shift = word.copy()
        for i in range(3, -1, -1):
            active = largest != i
            mag = (shift & 0x1FF).astype(np.float64)
            neg = ((shift >> 9) & 1).astype(bool)
            value = np.sqrt(0.5) * mag / 511.0
            xyzw[rows[active], i] = np.where(neg, -value, value)[active]
            shift = np.where(active, shift >> 10, shift)
        xyzw[rows, largest] = np.sqrt(np.clip(1.0 - (xyzw**2).sum(axis=1), 0.0, None))
    else:
        xyzw[:, :3] = raw_rot.astype(np.float64) / 127.5 - 1.0
        xyzw[:, 3] = np.sqrt(np.clip(1.0 - (xyzw[:, :3] ** 2).sum(axis=1), 0.0, None))
    quats = xyzw[:, [3, 0, 1, 2]]
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    sh = np.zeros((count, k, 3), dtype=np.float32)
    sh[:, 0, :] = dc
    if k > 1:
        sh[:, 1:, :] = (take((k - 1) * 3).astype(np.float64).reshape(count, k - 1, 3) - 128.0) / 128.0
    try:
        gaussians = Gaussians(means.astype(np.float32), quats.astype(np.float32), scales.astype(np.float32),
                              opacities.astype(np.float32), sh, source=str(p))
    except InvalidDataError as err:
        raise FileValueError(f"{p}: {err}") from err
    if axes == "rdf":
        gaussians = gaussians.transformed(np.diag([1.0, -1.0, -1.0]))
    return gaussians
