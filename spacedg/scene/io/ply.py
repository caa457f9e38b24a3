"""INRIA 3D Gaussian Splatting ``.ply`` files (the layout of the original 3DGS code).

File layout (one ``vertex`` element, one record per Gaussian):

- ``x y z``: centre, scene units (metres for spacedg scenes).
- ``nx ny nz``: unused normals (written as zeros, ignored on read).
- ``f_dc_0..2``: SH band 0 per channel (R, G, B).
- ``f_rest_0..f_rest_{3(K-1)-1}``: higher SH bands, **channel-major**: ``f_rest_{c·(K−1)+k−1}``
  is coefficient ``k`` (1 ≤ k < K) of channel ``c``, with K = (degree+1)². 0, 9, 24 or 45 of
  them mean SH degree 0, 1, 2 or 3.
- ``opacity``: logit of the opacity (``sigmoid`` gives [0, 1]).
- ``scale_0..2``: natural log of the standard deviations (``exp`` gives metres).
- ``rot_0..3``: rotation quaternion **w, x, y, z**, not necessarily normalised.
- ``instance_id`` (optional, any integer type): the spacedg instance id of each Gaussian, -1
  for none. Our native scene format writes it; other 3DGS tools ignore unknown properties.
- ``filter_3D`` (optional, Mip-Splatting): folded into scales and opacities on read.

Other layouts are recognised from the header and decoded by
:mod:`spacedg.scene.io.ply_variants`: PlayCanvas / SuperSplat compressed plys (``chunk`` +
packed ``vertex`` words) and colour-only plys (``red green blue`` instead of ``f_dc_*``).

Reading converts once, at the boundary: ``scales = exp(scale_i)`` and ``opacities =
sigmoid(opacity)`` are computed in float64 and rounded to float32; quaternions are normalised
in float64 (those already unit within :data:`~spacedg.render.gaussians.QUAT_UNIT_TOL`, the
tolerance :class:`Gaussians` accepts, are kept bit-for-bit). Other scalar properties are
ignored. ``ascii``, ``binary_little_endian`` and ``binary_big_endian`` files are read;
required properties may be ``float`` or ``double``.

Exactness contract of :func:`write_ply` → :func:`read_ply`:

- ``means``, ``quats``, ``sh`` and ``instance_ids`` come back bit-identical, always.
- ``scales`` and ``opacities`` come back bit-identical whenever the float32 value is
  reachable through the float32 activation, i.e. it equals ``float32(exp(x))`` /
  ``float32(sigmoid(x))`` for some float32 ``x``. Everything read from a float32 PLY is, so
  file → memory → file → memory is exact. :func:`quantize_for_ply` snaps arbitrary values to
  exactly what a float32 round trip yields (use it to make generated scenes reproducible from
  disk); other values move by at most a few float32 ulps.
- ``precision="float64"`` writes ``double`` properties and round-trips any float32 values
  bit-exactly.

Opacity 0 and 1 (logit ±∞) and scale 0 (log −∞) are written as the finite bound
±:data:`ACTIVATION_BOUND` (= 120), which decodes back to exactly 0.0 / 1.0 / 0.0 in float32.

Hostile input (truncated data, a header claiming 10¹² vertices, a missing ``end_header``,
garbage) raises :class:`~spacedg.errors.FileFormatError` before any allocation larger than
the header (:data:`MAX_HEADER_BYTES`) and the data the file actually holds.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import numpy as np

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import FileValueError, PathLike, as_path, atomic_write, require_file
from spacedg.render.gaussians import QUAT_UNIT_TOL, SH_COEFFS, Gaussians
from spacedg.scene.io.ply_variants import (
    apply_filter_3d,
    decode_colour_points,
    decode_compressed,
    is_compressed,
)

#: The header (from ``ply`` to ``end_header``) must fit in this many bytes.
MAX_HEADER_BYTES = 64 * 1024
#: Finite stand-in for ±∞ logits and −∞ log-scales. float32(sigmoid(−120)) = float32(exp(−120))
#: = 0.0 and float32(sigmoid(120)) = 1.0 exactly (any |x| > 104 would do).
ACTIVATION_BOUND = 120.0
#: Neighbouring float32 codes tried when snapping an activated value to an exact preimage.
_MAX_FIX_STEPS = 64

_FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}
_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_F_REST_COUNTS = {0: 0, 9: 1, 24: 2, 45: 3}
_F_REST = re.compile(r"^f_rest_(\d+)$")
_COUNT = re.compile(r"^[0-9]+$")
#: Longest element count (digits) read from a header: 10¹⁸ records exceed any file already.
_MAX_COUNT_DIGITS = 18
_REQUIRED = ("x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2", "opacity", "scale_0", "scale_1", "scale_2",
             "rot_0", "rot_1", "rot_2", "rot_3")


@dataclass(frozen=True)
class _Property:
    name: str
    type: str  # PLY type name as written
    code: str  # numpy type code without byte order ("f4"); "" for list properties
    is_list: bool
    line: int


@dataclass(frozen=True)
class _Element:
    name: str
    count: int
    properties: tuple[_Property, ...]
    line: int

    def record_dtype(self, order: str) -> np.dtype:
        return np.dtype([(p.name, order + p.code) for p in self.properties])

    @property
    def is_fixed_size(self) -> bool:
        return not any(p.is_list for p in self.properties)


@dataclass(frozen=True)
class _Header:
    format: str
    elements: tuple[_Element, ...]
    data_offset: int


# ----------------------------------------------------------------------------- header
def _fail(path: Path, message: str) -> FileFormatError:
    return FileFormatError(f"{path}: {message}")


def _split_header(path: Path, head: bytes, file_size: int) -> tuple[list[str], int]:
    """Header lines (decoded) and the byte offset where the data starts."""
    if not (head.startswith(b"ply\n") or head.startswith(b"ply\r\n")):
        raise _fail(path, "not a PLY file (the first line must be 'ply'); is it a .splat or another format?")
    lines: list[str] = []
    offset = 0
    while True:
        end = head.find(b"\n", offset)
        if end < 0:
            if file_size > MAX_HEADER_BYTES and len(head) >= MAX_HEADER_BYTES:
                raise _fail(path, f"no 'end_header' line within the first {MAX_HEADER_BYTES} bytes; the header is garbled or this is not a PLY file")
            raise _fail(path, "the header has no 'end_header' line; the file is truncated or not a PLY file")
        raw = head[offset:end].rstrip(b"\r")
        try:
            line = raw.decode("ascii")
        except UnicodeDecodeError:
            raise _fail(path, f"header line {len(lines) + 1} is not ASCII text; the header is garbled") from None
        lines.append(line)
        offset = end + 1
        if line.strip() == "end_header":
            return lines, offset


def _parse_property(path: Path, tokens: list[str], lineno: int) -> _Property:
    if len(tokens) >= 2 and tokens[1] == "list":
        if len(tokens) != 5:
            raise _fail(path, f"header line {lineno}: expected 'property list <count type> <item type> <name>', got {' '.join(tokens)!r}")
        for t in tokens[2:4]:
            if t not in _TYPES:
                raise _fail(path, f"header line {lineno}: unknown PLY type {t!r} (known: {sorted(set(_TYPES))})")
        return _Property(tokens[4], "list", "", True, lineno)
    if len(tokens) != 3:
        raise _fail(path, f"header line {lineno}: expected 'property <type> <name>', got {' '.join(tokens)!r}")
    if tokens[1] not in _TYPES:
        raise _fail(path, f"header line {lineno}: unknown PLY type {tokens[1]!r} for property {tokens[2]!r} (known: {sorted(set(_TYPES))})")
    return _Property(tokens[2], tokens[1], _TYPES[tokens[1]], False, lineno)


def _parse_header(path: Path, head: bytes, file_size: int) -> _Header:
    lines, data_offset = _split_header(path, head, file_size)
    fmt: str | None = None
    elements: list[tuple[str, int, list[_Property], int]] = []
    for lineno, line in enumerate(lines[1:-1], start=2):
        tokens = line.split()
        if not tokens or tokens[0] in ("comment", "obj_info"):
            continue
        key = tokens[0]
        if key == "format":
            if fmt is not None:
                raise _fail(path, f"header line {lineno}: a second 'format' line")
            if len(tokens) != 3 or tokens[1] not in _FORMATS:
                raise _fail(path, f"header line {lineno}: expected 'format <ascii|binary_little_endian|binary_big_endian> 1.0', got {line!r}")
            fmt = tokens[1]
        elif key == "element":
            if len(tokens) != 3 or not _COUNT.match(tokens[2]):
                raise _fail(path, f"header line {lineno}: expected 'element <name> <count>' with a non-negative integer count, got {line[:120]!r}")
            if len(tokens[2]) > _MAX_COUNT_DIGITS:
                raise _fail(
                    path,
                    f"header line {lineno}: element {tokens[1][:60]!r} declares a count of {len(tokens[2]):,} digits; "
                    f"no file holds more than 10^{_MAX_COUNT_DIGITS} records: the header is corrupt or hostile",
                )
            if any(e[0] == tokens[1] for e in elements):
                raise _fail(path, f"header line {lineno}: element {tokens[1]!r} is declared twice")
            elements.append((tokens[1], int(tokens[2]), [], lineno))
        elif key == "property":
            if not elements:
                raise _fail(path, f"header line {lineno}: 'property' before any 'element'")
            prop = _parse_property(path, tokens, lineno)
            props = elements[-1][2]
            if any(p.name == prop.name for p in props):
                raise _fail(path, f"header line {lineno}: property {prop.name!r} is declared twice in element {elements[-1][0]!r}")
            props.append(prop)
        else:
            raise _fail(path, f"header line {lineno}: unknown header keyword {key!r} (line {line!r})")
    if fmt is None:
        raise _fail(path, "the header has no 'format' line")
    return _Header(fmt, tuple(_Element(n, c, tuple(p), ln) for n, c, p, ln in elements), data_offset)


# ------------------------------------------------------------------ vertex layout checks
@dataclass(frozen=True)
class _Layout:
    sh_degree: int
    rest_names: tuple[str, ...]
    has_instance_ids: bool


def _vertex_layout(path: Path, vertex: _Element) -> _Layout:
    props = {p.name: p for p in vertex.properties}
    lists = [p.name for p in vertex.properties if p.is_list]
    if lists:
        raise _fail(path, f"element 'vertex' has list properties {lists}; a 3DGS vertex holds scalar properties only")
    missing = [name for name in _REQUIRED if name not in props]
    if missing:
        raise _fail(path, f"element 'vertex' lacks the 3DGS properties {missing}; is this a mesh or point cloud rather than a 3DGS file?")
    rest_names = [name for name in props if _F_REST.match(name)]
    long_index = [name for name in rest_names if len(name) > len("f_rest_") + 4]
    if long_index:
        raise _fail(path, f"property {long_index[0][:40]!r}… ({len(long_index[0]):,} characters) is not an f_rest_<0..44> name; the header is corrupt")
    rest = sorted((int(name[len("f_rest_"):]), name) for name in rest_names)
    if [i for i, _ in rest] != list(range(len(rest))):
        raise _fail(path, f"f_rest properties are not numbered 0..{len(rest) - 1} without gaps (found {[n for _, n in rest][:8]}...)")
    if len(rest) not in _F_REST_COUNTS:
        raise _fail(path, f"{len(rest)} f_rest properties do not match an SH degree 0–3 (expected 0, 9, 24 or 45)")
    float_names = [*_REQUIRED, *(n for _, n in rest)]
    for name in float_names:
        if props[name].code not in ("f4", "f8"):
            raise _fail(path, f"property {name!r} has type {props[name].type!r}; 3DGS properties must be 'float' or 'double'")
    ids = props.get("instance_id")
    if ids is not None and ids.code[0] not in "iu":
        raise _fail(path, f"property 'instance_id' has type {ids.type!r}; it must be an integer type (int, uint, short, ...)")
    return _Layout(_F_REST_COUNTS[len(rest)], tuple(n for _, n in rest), ids is not None)


def _find_vertex(path: Path, header: _Header) -> tuple[int, _Element]:
    for index, element in enumerate(header.elements):
        if element.name == "vertex":
            return index, element
    raise _fail(path, f"no 'vertex' element (elements: {[e.name for e in header.elements]}); a 3DGS file stores Gaussians as vertices")


def _check_fixed_before(path: Path, header: _Header, vertex_index: int) -> None:
    for element in header.elements[:vertex_index]:
        if not element.is_fixed_size:
            raise _fail(
                path,
                f"element {element.name!r} (header line {element.line}) comes before 'vertex' and has list properties; "
                "spacedg can only skip fixed-size elements before the Gaussians",
            )


# ------------------------------------------------------------------------ data reading
def _read_binary(path: Path, header: _Header, vertex_index: int, file_size: int) -> np.ndarray:
    order = _FORMATS[header.format]
    skip = sum(e.count * e.record_dtype(order).itemsize for e in header.elements[:vertex_index])
    vertex = header.elements[vertex_index]
    dtype = vertex.record_dtype(order)
    need = skip + vertex.count * dtype.itemsize
    have = file_size - header.data_offset
    if need > have:
        raise _fail(
            path,
            f"truncated or corrupt: the header declares {vertex.count} vertices of {dtype.itemsize} bytes"
            + (f" after {skip} bytes of other elements" if skip else "")
            + f" ({need} bytes) but only {have} bytes follow the header",
        )
    with open(path, "rb") as handle:
        handle.seek(header.data_offset + skip)
        records = np.fromfile(handle, dtype=dtype, count=vertex.count)
    if records.shape[0] != vertex.count:
        raise _fail(path, f"truncated while reading: got {records.shape[0]} of {vertex.count} vertices")
    return records


def _read_ascii(path: Path, header: _Header, vertex_index: int, file_size: int) -> np.ndarray:
    before = header.elements[:vertex_index]
    vertex = header.elements[vertex_index]
    nprops = len(vertex.properties)
    # every value takes at least one character plus a separator or newline
    min_bytes = sum(e.count * 2 * len(e.properties) for e in (*before, vertex)) - 1
    have = file_size - header.data_offset
    if min_bytes > have:
        raise _fail(
            path,
            f"truncated or corrupt: the header declares {vertex.count} ASCII vertices of {nprops} values, "
            f"which need at least {min_bytes} bytes, but only {have} bytes follow the header",
        )
    with open(path, "rb") as handle:
        handle.seek(header.data_offset)
        body = handle.read()
    rows = [row for row in body.split(b"\n") if row.strip()]
    skip = sum(e.count for e in before)
    if len(rows) < skip + vertex.count:
        raise _fail(path, f"truncated: the header declares {vertex.count} vertices but the file holds {max(0, len(rows) - skip)} vertex lines")
    vrows = rows[skip : skip + vertex.count]
    for i, row in enumerate(vrows):
        if len(row.split()) != nprops:
            raise _fail(path, f"vertex {i}: expected {nprops} values, found {len(row.split())}; the ASCII data does not match the header")
    try:
        values = np.array(b" ".join(vrows).split(), dtype=np.float64)
    except ValueError as err:
        raise _fail(path, f"ASCII vertex data holds a value that is not a number ({err})") from None
    values = values.reshape(vertex.count, nprops)
    dtype = vertex.record_dtype("=")
    records = np.empty(vertex.count, dtype=dtype)
    for j, prop in enumerate(vertex.properties):
        column = values[:, j]
        if prop.code[0] in "iu":
            info = np.iinfo(np.dtype(prop.code))
            bad = ~np.isfinite(column) | (column != np.round(column)) | (column < info.min) | (column > info.max)
            if bad.any():
                row = int(np.flatnonzero(bad)[0])
                raise _fail(path, f"vertex {row}: property {prop.name!r} ({prop.type}) holds {column[row]!r}, not a {prop.type}")
        with np.errstate(over="ignore", invalid="ignore"):
            records[prop.name] = column
    return records


# ------------------------------------------------------------------------ activations
def _sigmoid32(x: np.ndarray) -> np.ndarray:
    """float32(sigmoid(x)) computed in float64 (the reader's opacity activation)."""
    with np.errstate(over="ignore", under="ignore"):
        return (1.0 / (1.0 + np.exp(-np.asarray(x, dtype=np.float64)))).astype(np.float32)


def _exp32(x: np.ndarray) -> np.ndarray:
    """float32(exp(x)) computed in float64 (the reader's scale activation)."""
    with np.errstate(over="ignore", under="ignore"):
        return np.exp(np.asarray(x, dtype=np.float64)).astype(np.float32)


def _logit64(v: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        return np.log(v) - np.log1p(-v)


def _log64(v: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore"):
        return np.log(v)


def _encode(
    target: np.ndarray,
    inverse: Callable[[np.ndarray], np.ndarray],
    decode: Callable[[np.ndarray], np.ndarray],
    file_dtype: np.dtype,
) -> np.ndarray:
    """File codes ``x`` (of ``file_dtype``) whose ``decode(x)`` is as close as possible to ``target``.

    Starts from the float64 inverse, clamped to ±:data:`ACTIVATION_BOUND` and rounded to the
    file type, then walks neighbouring codes (monotone ``decode``) until the decoded value
    equals ``target`` or the next step would move away from it.
    """
    target = np.asarray(target, dtype=np.float32).reshape(-1)
    x = np.clip(inverse(target.astype(np.float64)), -ACTIVATION_BOUND, ACTIVATION_BOUND).astype(file_dtype)
    decoded = decode(x)
    todo = decoded != target
    bound = np.asarray(ACTIVATION_BOUND, dtype=file_dtype)
    for _ in range(_MAX_FIX_STEPS):
        idx = np.flatnonzero(todo)
        if idx.size == 0:
            break
        xi, di, ti = x[idx], decoded[idx], target[idx]
        up = di < ti
        xn = np.clip(np.nextafter(xi, np.where(up, bound, -bound)), -bound, bound)
        dn = decode(xn)
        no_cross = np.where(up, dn <= ti, dn >= ti)
        closer = np.abs(dn.astype(np.float64) - ti) < np.abs(di.astype(np.float64) - ti)
        accept = (no_cross | closer) & (xn != xi)
        x[idx[accept]] = xn[accept]
        decoded[idx[accept]] = dn[accept]
        todo[idx] = accept & no_cross & (dn != ti)
    return x


def _encode_opacities(opacities: np.ndarray, file_dtype: np.dtype) -> np.ndarray:
    return _encode(opacities, _logit64, _sigmoid32, file_dtype)


def _encode_scales(scales: np.ndarray, file_dtype: np.dtype) -> np.ndarray:
    return _encode(scales, _log64, _exp32, file_dtype).reshape(-1, 3)


# ------------------------------------------------------------------------ conversion
def _normalise_quats(path: Path, raw: np.ndarray) -> np.ndarray:
    """(N, 4) float32 unit quaternions; near-unit rows kept bit-for-bit (see module docs)."""
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):  # huge doubles become inf, rejected later
        q32 = raw.astype(np.float32)
        peak = np.abs(raw).max(axis=1)
        q64 = raw / np.where(peak > 0, peak, 1.0)[:, None]  # scaled so the norm cannot overflow
        norms = np.linalg.norm(q64, axis=1)
    zero = peak * norms < 1e-12
    if zero.any():
        rows = np.flatnonzero(zero)
        raise FileValueError(
            f"{path}: {rows.size} of {len(norms)} Gaussians have a zero rotation quaternion (rot_0..3 all 0; first at vertex {rows[0]}); "
            "a zero quaternion has no rotation: remove those Gaussians or set rot_0 to 1 in the source file"
        )
    with np.errstate(over="ignore", invalid="ignore"):
        unit = np.abs(np.linalg.norm(q32.astype(np.float64), axis=1) - 1.0) <= QUAT_UNIT_TOL
    if unit.all():
        return q32
    with np.errstate(over="ignore", invalid="ignore"):
        normalised = (q64 / norms[:, None]).astype(np.float32)
    return np.where(unit[:, None], q32, normalised)


def _stack(records: np.ndarray, names: tuple[str, ...] | list[str], dtype: type) -> np.ndarray:
    out = np.empty((records.shape[0], len(names)), dtype=dtype)
    with np.errstate(over="ignore", invalid="ignore"):  # out-of-range doubles become inf, rejected later
        for j, name in enumerate(names):
            out[:, j] = records[name]
    return out


def _to_gaussians(path: Path, records: np.ndarray, layout: _Layout) -> Gaussians:
    n = records.shape[0]
    means = _stack(records, ("x", "y", "z"), np.float32)
    k = SH_COEFFS[layout.sh_degree]
    sh = np.empty((n, k, 3), dtype=np.float32)
    sh[:, 0, :] = _stack(records, ("f_dc_0", "f_dc_1", "f_dc_2"), np.float32)
    if k > 1:
        rest = _stack(records, layout.rest_names, np.float32)  # (n, 3(K-1)), channel-major
        sh[:, 1:, :] = rest.reshape(n, 3, k - 1).transpose(0, 2, 1)
    opacities = _sigmoid32(records["opacity"])
    scales = _exp32(_stack(records, ("scale_0", "scale_1", "scale_2"), np.float64))
    quats = _normalise_quats(path, _stack(records, ("rot_0", "rot_1", "rot_2", "rot_3"), np.float64))
    ids = None
    if layout.has_instance_ids:
        raw_ids = records["instance_id"]
        bad = (raw_ids < -1) | (raw_ids > np.iinfo(np.int32).max)
        if bad.any():
            rows = np.flatnonzero(bad)
            raise FileValueError(
                f"{path}: property 'instance_id': {rows.size} of {n} values outside [-1, 2147483647] "
                f"(first at vertex {rows[0]}: {raw_ids[rows[0]]}); use -1 for Gaussians without an instance"
            )
        ids = raw_ids.astype(np.int32)
    try:
        return Gaussians(means, quats, scales, opacities, sh, ids, source=str(path))
    except InvalidDataError as err:
        raise FileValueError(str(err)) from err


# ----------------------------------------------------------------------------- public
def read_ply(path: PathLike) -> Gaussians:
    """Read an INRIA 3DGS ``.ply`` file into activated :class:`Gaussians` (see module docs).

    Args:
        path: the ``.ply`` file.

    Returns:
        Gaussians with scales in scene units (``exp`` of the file's log-scales), opacities in
        [0, 1] (``sigmoid`` of the logits), unit wxyz quaternions, SH of degree 0–3 and
        ``instance_ids`` when the file has an ``instance_id`` property.

    Raises:
        FileFormatError: not a PLY, garbled or truncated header/data, missing or mistyped 3DGS
            properties, an ``f_rest`` count that is not a degree 0–3, list properties in
            ``vertex``. Values that parse but break a convention (NaN, zero quaternions)
            raise :class:`FileValueError`, which is also an ``InvalidDataError``.
    """
    p = as_path(path, "PLY file")
    file_size = require_file(p, "PLY file")
    with open(p, "rb") as handle:
        head = handle.read(MAX_HEADER_BYTES)
    header = _parse_header(p, head, file_size)
    vertex_index, vertex = _find_vertex(p, header)
    names = {prop.name for prop in vertex.properties}
    if is_compressed(names):
        return decode_compressed(p, _read_fixed_elements(p, header, file_size))
    if "f_dc_0" not in names and {"red", "green", "blue"} <= names and {"x", "y", "z"} <= names:
        _check_fixed_before(p, header, vertex_index)
        reader = _read_ascii if header.format == "ascii" else _read_binary
        return decode_colour_points(p, reader(p, header, vertex_index, file_size))
    layout = _vertex_layout(p, vertex)
    _check_fixed_before(p, header, vertex_index)
    if header.format == "ascii":
        records = _read_ascii(p, header, vertex_index, file_size)
    else:
        records = _read_binary(p, header, vertex_index, file_size)
    gaussians = _to_gaussians(p, records, layout)
    if "filter_3D" in names:
        gaussians = apply_filter_3d(p, gaussians, records["filter_3D"])
    return gaussians


def _read_fixed_elements(path: Path, header: _Header, file_size: int) -> dict[str, np.ndarray]:
    """Every element of a binary file whose elements are all fixed-size (the compressed layout)."""
    if header.format == "ascii":
        raise _fail(path, "a compressed (packed) ply must be binary")
    order = _FORMATS[header.format]
    out: dict[str, np.ndarray] = {}
    offset = header.data_offset
    for element in header.elements:
        if not element.is_fixed_size:
            raise _fail(path, f"element {element.name!r} has list properties; a compressed ply holds fixed-size elements only")
        dtype = element.record_dtype(order)
        need = element.count * dtype.itemsize
        if offset + need > file_size:
            raise _fail(path, f"truncated: element {element.name!r} declares {element.count} records ({need} bytes) past the end of the file")
        with open(path, "rb") as handle:
            handle.seek(offset)
            out[element.name] = np.fromfile(handle, dtype=dtype, count=element.count)
        offset += need
    return out


def _file_dtype(precision: str) -> np.dtype:
    if precision not in ("float32", "float64"):
        raise InvalidDataError(f"write_ply: precision must be 'float32' or 'float64', got {precision!r}")
    return np.dtype("<f4" if precision == "float32" else "<f8")


def _property_names(sh_degree: int) -> list[str]:
    k = SH_COEFFS[sh_degree]
    return [
        "x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2",
        *(f"f_rest_{i}" for i in range(3 * (k - 1))),
        "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
    ]


def _records_for(gaussians: Gaussians, fdt: np.dtype) -> np.ndarray:
    names = _property_names(gaussians.sh_degree)
    fields = [(name, fdt) for name in names]
    if gaussians.instance_ids is not None:
        fields.append(("instance_id", np.dtype("<i4")))
    n = len(gaussians)
    rec = np.zeros(n, dtype=np.dtype(fields))
    for j, axis in enumerate("xyz"):
        rec[axis] = gaussians.means[:, j]
    for c in range(3):
        rec[f"f_dc_{c}"] = gaussians.sh[:, 0, c]
    k = gaussians.sh.shape[1]
    for c in range(3):
        for i in range(1, k):
            rec[f"f_rest_{c * (k - 1) + i - 1}"] = gaussians.sh[:, i, c]
    rec["opacity"] = _encode_opacities(gaussians.opacities, fdt)
    scales = _encode_scales(gaussians.scales, fdt)
    for j in range(3):
        rec[f"scale_{j}"] = scales[:, j]
    for j in range(4):
        rec[f"rot_{j}"] = gaussians.quats[:, j]
    if gaussians.instance_ids is not None:
        rec["instance_id"] = gaussians.instance_ids
    return rec


def _header_for(rec: np.ndarray, precision: str) -> bytes:
    type_name = "float" if precision == "float32" else "double"
    lines = [
        "ply",
        "format binary_little_endian 1.0",
        "comment written by spacedg: INRIA 3DGS layout, opacity = logit, scale = log, rot = wxyz",
        f"element vertex {rec.shape[0]}",
    ]
    for name in rec.dtype.names or ():
        lines.append(f"property {'int' if name == 'instance_id' else type_name} {name}")
    lines.append("end_header")
    return ("\n".join(lines) + "\n").encode("ascii")


def write_ply(path: PathLike, gaussians: Gaussians, *, precision: Literal["float32", "float64"] = "float32") -> None:
    """Write Gaussians as an INRIA 3DGS ``.ply`` (binary little endian), atomically.

    Scales and opacities are encoded in float64 as log / logit (±∞ clamped to
    ±:data:`ACTIVATION_BOUND`) and snapped so the reader's activation gives back the stored
    float32 value whenever one exists (see the module's exactness contract). ``instance_id``
    (int32) is written when the Gaussians carry instance ids. The file appears under its name
    only when complete (temporary file + ``os.replace``).

    Args:
        path: destination file.
        gaussians: what to write.
        precision: ``"float32"`` (the usual INRIA layout) or ``"float64"`` (``double``
            properties; round-trips any float32 values bit-exactly).
    """
    if not isinstance(gaussians, Gaussians):
        raise InvalidDataError(f"write_ply: expected Gaussians, got {type(gaussians).__name__}")
    fdt = _file_dtype(precision)
    rec = _records_for(gaussians, fdt)
    header = _header_for(rec, precision)
    with atomic_write(path, "wb") as handle:
        handle.write(header)
        handle.write(rec.view(np.uint8).data if rec.size else b"")


def quantize_for_ply(gaussians: Gaussians, *, precision: Literal["float32", "float64"] = "float32") -> Gaussians:
    """Gaussians exactly as ``read_ply(write_ply(gaussians, precision=...))`` would return them.

    Only scales and opacities change (snapped to values reachable through the float32
    activation); means, quaternions, SH and instance ids are untouched. With
    ``precision="float64"`` nothing changes. Idempotent.
    """
    fdt = _file_dtype(precision)
    opacities = _sigmoid32(_encode_opacities(gaussians.opacities, fdt))
    scales = _exp32(_encode_scales(gaussians.scales, fdt))
    return replace(gaussians, scales=scales, opacities=opacities)
