"""Field checks shared by the JSON readers (instances, INRIA cameras, nerfstudio frames, EmbodiedScan).

Every check raises :class:`~spacedg.errors.FileFormatError` (a malformed field) or
:class:`~spacedg.errors.FileValueError` (numbers that break a convention), with ``where`` (the
file and the record) at the front of the message.
"""

from __future__ import annotations

from collections.abc import Container
from typing import Any

import numpy as np

from spacedg.errors import FileFormatError, FileValueError

__all__ = ["matrix_field", "named_record", "instance_list"]


def matrix_field(where: str, key: str, value: Any, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as a finite float64 array of ``shape`` (the JSON field ``key``)."""
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise FileFormatError(f"{where}: '{key}' must be numbers of shape {shape}") from None
    if array.shape != shape:
        raise FileFormatError(f"{where}: '{key}' must have shape {shape}, got {array.shape}")
    if not np.isfinite(array).all():
        raise FileValueError(f"{where}: '{key}' holds NaN or Inf")
    return array


def named_record(where: str, record: Any, name_key: str, required: tuple[str, ...], seen: Container[str], hint: str) -> tuple[str, str]:
    """Check one JSON record that a unique name identifies (a camera, a frame); returns
    ``(name, where with the name appended)``.

    ``record`` must be an object holding every key of ``required`` (``hint`` says what a record
    looks like), and ``record[name_key]`` a non-empty string not in ``seen``.
    """
    if not isinstance(record, dict):
        raise FileFormatError(f"{where}: expected an object, got {type(record).__name__}")
    missing = [k for k in required if k not in record]
    if missing:
        raise FileFormatError(f"{where}: missing {', '.join(repr(k) for k in missing)}; {hint}")
    name = record[name_key]
    if not isinstance(name, str) or not name:
        raise FileFormatError(f"{where}: '{name_key}' must be a non-empty string, got {name!r}")
    where = f"{where} ({name!r})"
    if name in seen:
        raise FileFormatError(f"{where}: {name_key} {name!r} appears twice; names must be unique")
    return name, where


def instance_list(path: object, data: Any, expected: str) -> list[Any]:
    """The instance list of a parsed instance file: ``data`` itself, or its ``"instances"`` list
    (``expected`` says which top-level forms the format has)."""
    if isinstance(data, dict):
        if "instances" not in data:
            raise FileFormatError(f"{path}: expected {expected} (keys: {sorted(data)[:10]})")
        data = data["instances"]
    if not isinstance(data, list):
        raise FileFormatError(f"{path}: 'instances' must be a list, got {type(data).__name__}")
    return data
