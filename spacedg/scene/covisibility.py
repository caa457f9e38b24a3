"""MapAnything-style covisibility of a scene's views from rendered depth, cached on disk per scene.

- :func:`covisibility_matrix`: ``M[i, j]`` = share of view i's valid depth pixels that, lifted to
  3D and projected into view j, land inside j, in front of it, and agree with j's rendered depth
  within a relative threshold (raw, asymmetric; diagonal 1).
- :func:`symmetrize`: ``min(M, Mᵀ)`` (default) or the mean.
- with ``cache_dir``, :func:`covisibility_matrix` (or its alias :func:`load_or_compute_covisibility`)
  caches the matrix as ``<cache_dir>/<scene id>.covisibility.npz``, reused only when its key
  (method version, parameters, Gaussian count, every view's intrinsics, lens and pose) matches.
"""

from __future__ import annotations

import json
import os
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.errors import ParameterError
from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians
from spacedg.render.renderer import render
from spacedg.scene.derived_cache import read_npz_entry, views_key, write_npz_entry
from spacedg.scene.model import Scene, ViewCovisibility
from spacedg.scene.visibility import check_size, reduced_camera, view_names

__all__ = [
    "COVISIBILITY_IMAGE_SIZE",
    "COVISIBILITY_VERSION",
    "covisibility_cache_path",
    "covisibility_key",
    "covisibility_matrix",
    "load_or_compute_covisibility",
    "symmetrize",
    "with_covisibility",
]

#: Default reduced render size (width, height) of :func:`covisibility_matrix`, pixels.
COVISIBILITY_IMAGE_SIZE = (80, 60)
#: Version of the covisibility computation; part of the cache key (bump on a change of method).
COVISIBILITY_VERSION = 2  # 2: reduced renders keep each view's aspect (visibility.reduced_camera)
#: Smallest ``cos θ`` of a fisheye ray that is lifted to 3D (rays near 90° are ill-conditioned).
_MIN_COS_THETA = 1e-3


# ----------------------------------------------------------------------- covisibility
@dataclass(frozen=True)
class _DepthView:
    """One view's reduced camera, rendered depth (0 = invalid) and world points of its valid pixels."""

    camera: Camera
    depth: np.ndarray  # (h, w) float64 metres, 0 where alpha <= 0.5
    points: np.ndarray  # (N, 3) world metres of the (strided) valid pixels


def _pixel_rays(camera: Camera, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera-space rays with z = 1 through pixel centres, and a validity mask.

    Pixel centres at ``(col + 0.5, row + 0.5)``, OpenCV axes. Pinhole: ``((u − cx)/fx, (v −
    cy)/fy, 1)``. Fisheye: θ from ``lens.undistort_theta`` of the normalised radius, ray
    ``(tan θ · x̂, tan θ · ŷ, 1)``; rays with ``cos θ < 1e-3`` (at or beyond 90°) are invalid.
    """
    x = (cols + 0.5 - camera.cx) / camera.fx
    y = (rows + 0.5 - camera.cy) / camera.fy
    if camera.fisheye is None:
        return np.stack([x, y, np.ones_like(x)], axis=1), np.ones(x.shape, dtype=bool)
    r = np.hypot(x, y)
    theta = camera.fisheye.undistort_theta(r)
    cos_t = np.cos(theta)
    valid = cos_t >= _MIN_COS_THETA
    scale = np.where(r > 1e-12, np.tan(np.where(valid, theta, 0.0)) / np.where(r > 1e-12, r, 1.0), 1.0)
    return np.stack([x * scale, y * scale, np.ones_like(x)], axis=1), valid


def _depth_view(gaussians: Gaussians, camera: Camera, stride: int, backend: str, device: str | None = None) -> _DepthView:
    """Render expected depth and lift the valid pixels (alpha > 0.5, every ``stride``-th row/column)."""

    frame = render(gaussians, camera, outputs="depth", backend=backend, device=device)
    assert frame.depth is not None
    depth = np.where((frame.alpha > 0.5) & (frame.depth > 0), frame.depth, 0.0).astype(np.float64)
    sub = depth[::stride, ::stride]
    rows, cols = np.nonzero(sub > 0)
    rows, cols = rows * stride, cols * stride
    rays, ok = _pixel_rays(camera, rows.astype(np.float64), cols.astype(np.float64))
    z = depth[rows, cols]
    cam_pts = rays[ok] * z[ok, None]
    world = cam_pts @ camera.rotation.T + camera.center
    return _DepthView(camera, depth, world)


def _agreeing(points: np.ndarray, target: _DepthView, rel_threshold: float) -> int:
    """How many world ``points`` land inside ``target``, in front, with depth agreeing (nearest pixel)."""
    cam = target.camera
    uv, z, valid = cam.project(points)
    inside = valid & (z > 0) & cam.in_image(uv)
    if not inside.any():
        return 0
    col = np.floor(uv[inside, 0]).astype(np.int64)
    row = np.floor(uv[inside, 1]).astype(np.int64)
    ref = target.depth[row, col]
    agree = (ref > 0) & (np.abs(z[inside] - ref) <= rel_threshold * ref)
    return int(np.count_nonzero(agree))


class _PinholeTargets:
    """Pinhole target views stacked once, for :meth:`count` of many point sets (all views per call)."""

    def __init__(self, targets: Sequence[_DepthView]) -> None:
        self.size = len(targets)
        if not targets:
            return
        self.rot = np.stack([t.camera.rotation for t in targets])  # (V, 3, 3) cam→world
        self.offset = np.einsum("vk,vkj->vj", np.stack([t.camera.center for t in targets]), self.rot)[:, None, :]
        self.fx = np.array([t.camera.fx for t in targets])[:, None]
        self.fy = np.array([t.camera.fy for t in targets])[:, None]
        self.cx = np.array([t.camera.cx for t in targets])[:, None]
        self.cy = np.array([t.camera.cy for t in targets])[:, None]
        self.heights = np.array([t.depth.shape[0] for t in targets])
        self.widths = np.array([t.depth.shape[1] for t in targets])
        sizes = self.heights * self.widths
        self.starts = np.concatenate([[0], np.cumsum(sizes)[:-1]])  # depth maps may differ in size
        self.flat = np.concatenate([t.depth.ravel() for t in targets])

    def count(self, points: np.ndarray, rel_threshold: float) -> np.ndarray:
        """(V,) int64: :func:`_agreeing` of ``points`` for every target, in one set of array operations."""
        if self.size == 0 or points.shape[0] == 0:
            return np.zeros(self.size, dtype=np.int64)
        cam = np.matmul(points[None], self.rot) - self.offset  # (V, N, 3): (p − c) R
        z = cam[..., 2]
        front = z > 0
        zs = np.where(front, z, 1.0)
        u = self.fx * cam[..., 0] / zs + self.cx
        v = self.fy * cam[..., 1] / zs + self.cy
        inside = front & (u >= 0) & (v >= 0) & (u < self.widths[:, None]) & (v < self.heights[:, None])
        vi, ni = np.nonzero(inside)
        col = u[vi, ni].astype(np.int64)  # >= 0 here, so truncation is floor
        row = v[vi, ni].astype(np.int64)
        ref = self.flat[self.starts[vi] + row * self.widths[vi] + col]
        agree = (ref > 0) & (np.abs(z[vi, ni] - ref) <= rel_threshold * ref)
        return np.bincount(vi[agree], minlength=self.size).astype(np.int64)


def covisibility_matrix(
    scene: Scene,
    views: Iterable[str] | None = None,
    *,
    image_size: tuple[int, int] = COVISIBILITY_IMAGE_SIZE,
    rel_threshold: float = 0.05,
    stride: int = 1,
    backend: str = "auto",
    progress: bool = True,
    timings: dict[str, float] | None = None,
    device: str | None = None,
    cache_dir: str | os.PathLike[str] | None = None,
) -> tuple[list[str], np.ndarray]:
    """MapAnything-style covisibility of views, from rendered depth, cached on disk with ``cache_dir``.

    For every view, expected depth is rendered at a reduced size (intrinsics scaled with
    :meth:`Camera.resized`); pixels with alpha > 0.5 are *valid*. The valid pixels of view i
    (pixel centres at +0.5, OpenCV axes; fisheye rays through ``undistort_theta``; every
    ``stride``-th row and column) are lifted to world points and projected into view j; a
    point counts if it lands inside j's image, in front of j, on a valid pixel of j (nearest
    pixel), and its depth in j agrees with j's rendered depth there:
    ``|z_j − D_j| <= rel_threshold · D_j``.

    ``M[i, j] = count / valid (strided) pixels of i``, in [0, 1]: the share of what i sees that
    j sees too. The matrix is **not symmetrised** (a wide view seeing a close-up view's
    surface has a low ``M[wide, close]`` but a high ``M[close, wide]``); use
    :func:`symmetrize` (``min`` by default: both views must see the shared surface) for pair
    selection. The diagonal is 1 by definition (also for a view with no valid pixel, whose
    off-diagonal row is 0).

    Args:
        scene: the scene.
        views: view names (default: all, in ``scene.views`` order).
        image_size: reduced render size ``(width, height)``, pixels: a bounding box, each view keeping
            its own aspect (:func:`~spacedg.scene.visibility.reduced_camera`).
        rel_threshold: relative depth tolerance, in (0, 1).
        stride: lift every ``stride``-th row and column of view i (targets keep full reduced
            resolution); 1 uses every pixel.
        backend: render backend.
        progress: tqdm progress bars.
        device: torch device of the renders (``"cuda"``: gsplat's CUDA compositor under ``auto``).
        timings: if given, receives ``render_s`` and ``matrix_s`` (wall-clock seconds) of a
            computation (untouched when the cache answers).
        cache_dir: folder of the cache file (:func:`covisibility_cache_path`), an ``.npz`` with
            ``names``, ``matrix`` (raw, asymmetric, float32), ``params`` (JSON) and ``key``
            (:func:`covisibility_key`). It is reused only when the key matches (same views, poses,
            intrinsics, Gaussian count and parameters); otherwise, or when unreadable, the matrix
            is computed and the file replaced atomically (temporary file + ``os.replace``). The
            backend is not part of the key (backends agree to float precision). None: no cache.

    Returns:
        ``(names, M)``: the view names (row/column order) and a float32 (V, V) matrix.
    """
    names = view_names(scene, views, "covisibility_matrix")
    size = check_size(image_size, "covisibility_matrix")
    if isinstance(rel_threshold, bool) or not isinstance(rel_threshold, (int, float)) or not 0.0 < rel_threshold < 1.0:
        raise ParameterError(f"covisibility_matrix: rel_threshold must be in (0, 1) (relative depth tolerance), got {rel_threshold!r}")
    if isinstance(stride, bool) or not isinstance(stride, (int, np.integer)) or stride < 1:
        raise ParameterError(f"covisibility_matrix: stride must be an integer >= 1 (pixels), got {stride!r}")
    if cache_dir is None:
        return names, _compute_matrix(scene, names, size, float(rel_threshold), int(stride), backend, device, progress, timings)
    key = covisibility_key(scene, names, image_size=size, rel_threshold=rel_threshold, stride=stride)
    path = covisibility_cache_path(scene, cache_dir)
    cached = read_npz_entry(path, key)
    if cached is not None and "names" in cached and "matrix" in cached:
        cached_names = [str(n) for n in cached["names"]]
        matrix = cached["matrix"].astype(np.float32)
        if matrix.shape == (len(cached_names), len(cached_names)):
            return cached_names, matrix
    matrix = _compute_matrix(scene, names, size, float(rel_threshold), int(stride), backend, device, progress, timings)
    params = {"image_size": list(size), "rel_threshold": float(rel_threshold), "stride": int(stride),
              "version": COVISIBILITY_VERSION, "symmetrised": False}
    write_npz_entry(path, key, {"names": np.array(names, dtype=str), "matrix": matrix, "params": np.array(json.dumps(params))})
    return names, matrix


def _compute_matrix(
    scene: Scene, names: list[str], size: tuple[int, int], rel_threshold: float, stride: int, backend: str,
    device: str | None, progress: bool, timings: dict[str, float] | None,
) -> np.ndarray:
    """The matrix of :func:`covisibility_matrix` over checked arguments (no cache)."""
    from tqdm import tqdm

    gaussians = scene.gaussians
    t0 = time.perf_counter()
    dviews = [
        _depth_view(gaussians, reduced_camera(scene.views[n], size), stride, backend, device)
        for n in tqdm(names, desc=f"covisibility depth {scene.id}", unit="view", disable=not progress)
    ]
    t1 = time.perf_counter()
    count = len(names)
    matrix = np.zeros((count, count), dtype=np.float32)
    pinhole = [k for k, d in enumerate(dviews) if d.camera.fisheye is None]
    fisheye = [k for k, d in enumerate(dviews) if d.camera.fisheye is not None]
    pin_targets = _PinholeTargets([dviews[k] for k in pinhole])
    for i in tqdm(range(count), desc=f"covisibility pairs {scene.id}", unit="view", disable=not progress):
        pts = dviews[i].points
        if pts.shape[0] == 0:
            continue
        hits = np.zeros(count, dtype=np.int64)
        hits[pinhole] = pin_targets.count(pts, rel_threshold)
        for k in fisheye:
            hits[k] = _agreeing(pts, dviews[k], rel_threshold)
        matrix[i] = hits / pts.shape[0]
    np.clip(matrix, 0.0, 1.0, out=matrix)
    np.fill_diagonal(matrix, 1.0)
    if timings is not None:
        timings["render_s"] = t1 - t0
        timings["matrix_s"] = time.perf_counter() - t1
    return matrix


def symmetrize(matrix: np.ndarray, mode: str = "min") -> np.ndarray:
    """Symmetric covisibility: ``min(M, Mᵀ)`` (default) or ``(M + Mᵀ)/2`` (``mode="mean"``).

    ``min`` is ≤ both directions: a pair passes a threshold only if each view sees that share
    of the other's surface.
    """
    m = np.asarray(matrix)
    if m.ndim != 2 or m.shape[0] != m.shape[1]:
        raise ParameterError(f"symmetrize: need a square matrix, got shape {m.shape}")
    if mode == "min":
        return np.minimum(m, m.T)
    if mode == "mean":
        return (0.5 * (m + m.T)).astype(m.dtype, copy=False)
    raise ParameterError(f"symmetrize: mode must be 'min' or 'mean', got {mode!r}")


# ------------------------------------------------------------------------------- cache
def covisibility_key(
    scene: Scene,
    names: Sequence[str],
    *,
    image_size: tuple[int, int],
    rel_threshold: float,
    stride: int,
) -> str:
    """Cache key: :func:`~spacedg.scene.derived_cache.views_key` over the method version,
    the parameters, the Gaussian count and every camera (moving one view changes it)."""
    params = {"version": COVISIBILITY_VERSION, "image_size": list(image_size), "rel_threshold": float(rel_threshold), "stride": int(stride)}
    return views_key(scene, names, params)


def covisibility_cache_path(scene: Scene, cache_dir: str | os.PathLike[str]) -> Path:
    """``<cache_dir>/<scene.id>.covisibility.npz``."""
    return Path(cache_dir) / f"{scene.id}.covisibility.npz"


def load_or_compute_covisibility(
    scene: Scene, cache_dir: str | os.PathLike[str], views: Iterable[str] | None = None, **options: Any,
) -> tuple[list[str], np.ndarray]:
    """:func:`covisibility_matrix` cached in ``cache_dir`` (its ``cache_dir`` argument); ``options``
    are its keyword arguments (``image_size``, ``rel_threshold``, ``stride``, ``backend``,
    ``progress``, ``device``, ``timings``)."""
    return covisibility_matrix(scene, views, cache_dir=cache_dir, **options)


def with_covisibility(
    scene: Scene,
    cache_dir: str | os.PathLike[str] | None = None,
    **kwargs: object,
) -> Scene:
    """``scene`` with :attr:`Scene.covisibility` attached (all views; raw asymmetric matrix).

    With ``cache_dir`` the matrix is cached there (:func:`covisibility_matrix`). ``kwargs`` go to
    the computation (``image_size``, ``rel_threshold``, ``stride``, ``backend``, ``device``, ``progress``).
    """
    names, matrix = covisibility_matrix(scene, cache_dir=cache_dir, **kwargs)  # type: ignore[arg-type]
    return scene.with_covisibility(ViewCovisibility(tuple(names), matrix))
