"""On-disk cache of values derived from a scene's views (visibility, covisibility).

Each entry is one ``.npz`` holding the arrays plus a ``key``: the SHA-256 of the method's
parameters (including its version), the scene id, the Gaussian count and every camera (name,
intrinsics, size, lens, cam-to-world as float64 bytes). An entry is reused only when its key
matches; an unreadable or foreign file is recomputed and replaced atomically.

Gaussian *values* are not hashed (only the count): rewriting a scene's splats in place with
the same count needs an explicit recompute (delete the cache file).
"""

from __future__ import annotations

import hashlib
import io
import json
import zipfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.files import atomic_write_bytes
from spacedg.scene.model import Scene

__all__ = ["views_key", "read_npz_entry", "write_npz_entry"]


def views_key(scene: Scene, names: Sequence[str], params: Mapping[str, Any]) -> str:
    """SHA-256 hex digest of ``params``, the scene id, its Gaussian count and the cameras ``names``
    (intrinsics, lens, pose and, when set, ``capture_focal``)."""
    digest = hashlib.sha256()
    head = {**params, "gaussians": len(scene.gaussians), "scene": scene.id}
    digest.update(json.dumps(head, sort_keys=True).encode())
    for name in names:
        cam = scene.views[name]
        lens = cam.fisheye.coeffs + (cam.fisheye.max_theta,) if cam.fisheye is not None else ()
        digest.update(name.encode() + b"\0")
        digest.update(np.array([cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height, *lens], np.float64).tobytes())
        digest.update(np.ascontiguousarray(cam.cam_to_world, np.float64).tobytes())
        if cam.capture_focal is not None:  # it changes renders at other sizes (footprint_dilation); absent: the old key
            digest.update(b"capture" + np.array(cam.capture_focal, np.float64).tobytes())
    return digest.hexdigest()


def read_npz_entry(path: Path, key: str) -> dict[str, np.ndarray] | None:
    """The arrays of ``path`` if it is a readable entry with ``key``, else ``None``."""
    if not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["key"]) != key:
                return None
            return {name: np.asarray(data[name]) for name in data.files if name != "key"}
    except (OSError, KeyError, ValueError, zipfile.BadZipFile):
        return None


def write_npz_entry(path: Path, key: str, arrays: Mapping[str, np.ndarray]) -> None:
    """Write ``arrays`` and ``key`` to ``path`` atomically (temporary file + rename)."""

    buffer = io.BytesIO()
    np.savez(buffer, key=np.array(key), **arrays)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, buffer.getvalue())
