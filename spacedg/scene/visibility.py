"""Instance visibility classes: when is an object *clearly visible*, *partly visible*, *hidden*.

- :func:`classify`: visibility class of one instance in one view (thresholds below).
- :func:`compute_visibility` / :func:`with_visibility`: :class:`~spacedg.scene.model.InstanceVisibility`
  of every instance in every view, from the rendered instance-id map.
- view covisibility from rendered depth lives in :mod:`spacedg.scene.covisibility`.

Classes (shared by every question family, e.g. counting and existence):

``HIDDEN``
    no record for the view, or 0 visible pixels: the image shows nothing of it.
``VISIBLE`` (clearly visible)
    ``visible_pixels >= min_pixels`` (scaled to the image, see below) **and**
    ``visible_fraction >= min_fraction``.
``PARTIAL``
    the grey zone in between: some pixels, but too few or too occluded/truncated to be sure a
    viewer counts it. Families that need certainty skip questions touching it.

Defaults (:data:`DEFAULT_THRESHOLDS`): ``min_pixels = 400`` at the reference image size
640×480 (0.13 % of the image, a 20×20 px patch), scaled linearly with the image area so a
view's classification does not change with its resolution; ``min_fraction = 0.5`` (at least
half of the object's unoccluded, untruncated projection is visible).
"""

from __future__ import annotations

import math
import os
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from enum import StrEnum
from typing import Any

import numpy as np

from spacedg.scene.model import InstanceVisibility, Scene
from spacedg.errors import InvalidDataError, ParameterError
from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians

__all__ = [
    "VisibilityClass", "VisibilityThresholds", "DEFAULT_THRESHOLDS", "REFERENCE_AREA", "classify",
    "compute_visibility", "with_visibility", "unbounded_canvas", "VISIBILITY_IMAGE_SIZE", "load_or_compute_visibility",
]

#: Pixels of the reference image size 640×480 at which ``min_pixels`` is stated.
REFERENCE_AREA = 640 * 480


class VisibilityClass(StrEnum):
    """How well a view shows an instance."""

    VISIBLE = "visible"
    PARTIAL = "partial"
    HIDDEN = "hidden"


@dataclass(frozen=True)
class VisibilityThresholds:
    """Thresholds of :func:`classify`.

    Attributes:
        min_pixels: visible pixels needed for "clearly visible" at :attr:`reference_area`
            (> 0); scaled linearly with the image area.
        min_fraction: visible fraction of the instance's own projection needed, in (0, 1].
        reference_area: image area in pixels at which ``min_pixels`` holds (default 640×480).
    """

    min_pixels: float = 400.0
    min_fraction: float = 0.5
    reference_area: int = REFERENCE_AREA

    def __post_init__(self) -> None:
        if isinstance(self.min_pixels, bool) or not isinstance(self.min_pixels, (int, float)) or not math.isfinite(self.min_pixels) or self.min_pixels <= 0:
            raise InvalidDataError(f"VisibilityThresholds: min_pixels must be a number > 0 (pixels at 640×480), got {self.min_pixels!r}")
        if isinstance(self.min_fraction, bool) or not isinstance(self.min_fraction, (int, float)) or not 0.0 < self.min_fraction <= 1.0:
            raise InvalidDataError(f"VisibilityThresholds: min_fraction must be in (0, 1], got {self.min_fraction!r}")
        if isinstance(self.reference_area, bool) or not isinstance(self.reference_area, int) or self.reference_area < 1:
            raise InvalidDataError(f"VisibilityThresholds: reference_area must be a positive integer number of pixels, got {self.reference_area!r}")

    def pixels_for(self, image_area: int | None) -> float:
        """``min_pixels`` scaled to an image of ``image_area`` pixels (unscaled if ``None``)."""
        if image_area is None:
            return float(self.min_pixels)
        if isinstance(image_area, bool) or int(image_area) != image_area or image_area < 1:
            raise InvalidDataError(f"visibility: image_area must be a positive integer number of pixels, got {image_area!r}")
        return float(self.min_pixels) * float(image_area) / float(self.reference_area)

    def to_dict(self) -> dict[str, float]:
        return {"min_pixels": float(self.min_pixels), "min_fraction": float(self.min_fraction), "reference_area": self.reference_area}


DEFAULT_THRESHOLDS = VisibilityThresholds()


def classify(
    vis: InstanceVisibility | None,
    thresholds: VisibilityThresholds = DEFAULT_THRESHOLDS,
    image_area: int | None = None,
) -> VisibilityClass:
    """Classify one instance in one view.

    Args:
        vis: the instance's visibility in the view (``None``: no record → hidden).
        thresholds: see :class:`VisibilityThresholds`.
        image_area: the view's ``width * height`` in pixels, to scale ``min_pixels``; ``None``
            uses ``min_pixels`` as is.
    """
    if vis is None or vis.visible_pixels == 0:
        return VisibilityClass.HIDDEN
    if vis.visible_pixels >= thresholds.pixels_for(image_area) and vis.visible_fraction >= thresholds.min_fraction:
        return VisibilityClass.VISIBLE
    return VisibilityClass.PARTIAL


# =========================================================================================
# Computing visibility from renders
# =========================================================================================
#: Default reduced render size (width, height) of :func:`compute_visibility`, pixels.
VISIBILITY_IMAGE_SIZE = (160, 120)


def _view_names(scene: Scene, views: Iterable[str] | None, caller: str) -> list[str]:
    """The requested view names (all of the scene's views if ``None``), checked to exist."""
    if views is None:
        names = list(scene.views)
    elif isinstance(views, str):
        names = [views]
    else:
        names = list(views)
    for name in names:
        try:
            scene.camera(name)
        except ParameterError as err:
            raise ParameterError(f"{caller}: {err}") from None
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ParameterError(f"{caller}: view name(s) {dup[:5]!r} are listed more than once; list each view once")
    return names


def _check_size(image_size: tuple[int, int], caller: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in image_size)
    except (TypeError, ValueError):
        raise ParameterError(f"{caller}: image_size must be (width, height) in pixels, got {image_size!r}") from None
    if w < 1 or h < 1 or (w, h) != tuple(image_size):
        raise ParameterError(f"{caller}: image_size must be two positive integers (width, height), got {image_size!r}")
    return w, h


def _reduced(camera: Camera, image_size: tuple[int, int]) -> Camera:
    """``camera`` resized to ``image_size`` (never enlarged beyond its own resolution, per axis)."""
    w = min(image_size[0], camera.width)
    h = min(image_size[1], camera.height)
    return camera if (w, h) == (camera.width, camera.height) else camera.resized(w, h)


def unbounded_canvas(camera: Camera, scale: int = 3) -> Camera:
    """The same camera with its image plane enlarged ``scale``× per axis, centred on the frame.

    Focal lengths, pose and lens are unchanged; the principal point moves by
    ``(scale − 1)/2`` frames so the original image is the centre tile of the canvas. Used as
    the "unbounded image" of :attr:`InstanceVisibility.visible_fraction` (anything beyond
    the canvas, i.e. more than one frame away from the image border for ``scale = 3``, is
    not counted).
    """
    if isinstance(scale, bool) or not isinstance(scale, int) or scale < 1 or scale % 2 == 0:
        raise ParameterError(f"unbounded_canvas: scale must be an odd integer >= 1 (3 = one frame of margin), got {scale!r}")
    pad = (scale - 1) // 2
    return replace(
        camera,
        cx=camera.cx + pad * camera.width,
        cy=camera.cy + pad * camera.height,
        width=camera.width * scale,
        height=camera.height * scale,
    )


def _instance_index(gaussians: Gaussians, scene_id: str) -> dict[int, np.ndarray]:
    """instance id → indices of its Gaussians (one sort, no per-instance scan)."""
    if gaussians.instance_ids is None:
        raise InvalidDataError(
            f"visibility: the Gaussians of scene {scene_id} carry no instance_ids; "
            "visibility is read from the rendered instance-id map, so give the Gaussians instance ids"
        )
    ids = gaussians.instance_ids
    order = np.argsort(ids, kind="stable")
    sorted_ids = ids[order]
    uniq, starts = np.unique(sorted_ids, return_index=True)
    ends = np.append(starts[1:], len(sorted_ids))
    return {int(i): order[s:e] for i, s, e in zip(uniq, starts, ends) if i >= 0}


def compute_visibility(
    scene: Scene,
    views: Iterable[str] | None = None,
    *,
    image_size: tuple[int, int] = VISIBILITY_IMAGE_SIZE,
    backend: str = "auto",
    canvas_scale: int = 3,
    progress: bool = True,
) -> dict[str, dict[int, InstanceVisibility]]:
    """Per-view, per-instance visibility read from rendered instance-id maps.

    For every view: one render of the whole scene (``instance_ids`` only) at a reduced size;
    an instance's *visible* pixels are those whose id is its id (the Gaussian where
    transmittance crosses ½). For every instance with at least one visible pixel, one more
    render of **only its Gaussians** on the same camera with the image plane enlarged
    ``canvas_scale``× (:func:`unbounded_canvas`) gives its *own projection* (pixels where it
    alone takes transmittance to ½ or below: nothing in front, no image border). Then

    ``visible_fraction = clip(visible / own, 0, 1)``,

    so both occlusion and truncation by the image border reduce it. An instance with no
    visible pixel gets ``InstanceVisibility(0, 0.0)`` without an own-projection render
    (its fraction is 0 whatever its own projection is); instances behind the camera or off
    screen land there.

    Units: ``visible_pixels`` are **full-resolution pixels** of the view (``camera.width ×
    camera.height``), estimated from the reduced render as ``round(count × full area /
    reduced area)``; the fraction is a ratio of counts at the same reduced size.

    Args:
        scene: the scene (its Gaussians must carry ``instance_ids``).
        views: view names (default: all of the scene's views).
        image_size: reduced render size ``(width, height)`` in pixels; intrinsics are scaled
            with :meth:`Camera.resized`; a view smaller than this renders at its own size.
        backend: render backend (``"auto"``, ``"cpu"``, ``"torch"``).
        canvas_scale: odd enlargement factor of the own-projection canvas (3: one frame of
            margin on every side).
        progress: show a tqdm progress bar over views.

    Returns:
        view name → instance id → :class:`InstanceVisibility`, for every instance of the scene.

    Raises:
        ParameterError: an unknown view name or a bad ``image_size``.
        InvalidDataError: Gaussians without instance ids.
    """
    from tqdm import tqdm

    from spacedg.render.renderer import render

    names = _view_names(scene, views, "compute_visibility")
    size = _check_size(image_size, "compute_visibility")
    gaussians = scene.gaussians
    members = _instance_index(gaussians, scene.id)
    instance_ids = [inst.id for inst in scene.instances]
    subsets: dict[int, Gaussians] = {}
    out: dict[str, dict[int, InstanceVisibility]] = {}
    for name in tqdm(names, desc=f"visibility {scene.id}", unit="view", disable=not progress):
        full = scene.views[name]
        cam = _reduced(full, size)
        ids = render(gaussians, cam, outputs="instance_ids", backend=backend).instance_ids
        assert ids is not None
        present = ids[ids >= 0]
        counts = np.bincount(present, minlength=1) if present.size else np.zeros(1, np.int64)
        area_ratio = (full.width * full.height) / (cam.width * cam.height)
        canvas = unbounded_canvas(cam, canvas_scale)
        row: dict[int, InstanceVisibility] = {}
        for iid in instance_ids:
            visible = int(counts[iid]) if iid < counts.size else 0
            if visible == 0 or iid not in members:
                row[iid] = InstanceVisibility(0, 0.0)
                continue
            if iid not in subsets:
                subsets[iid] = gaussians.subset(members[iid])
            own_ids = render(subsets[iid], canvas, outputs="instance_ids", backend=backend).instance_ids
            own = int(np.count_nonzero(own_ids == iid))
            fraction = min(1.0, visible / own) if own > 0 else 1.0
            row[iid] = InstanceVisibility(int(round(visible * area_ratio)), fraction)
        out[name] = row
    return out


def with_visibility(
    scene: Scene,
    visibility: Mapping[str, Mapping[int, InstanceVisibility]] | None = None,
    **kwargs: Any,
) -> Scene:
    """A new scene whose instances carry ``visibility`` (computed with :func:`compute_visibility` if ``None``).

    Records of views not in ``visibility`` are kept; records of the views in it are replaced.
    ``kwargs`` go to :func:`compute_visibility` (``views``, ``image_size``, ``backend``, ...).
    """
    if visibility is None:
        visibility = compute_visibility(scene, **kwargs)
    elif kwargs:
        raise ParameterError(f"with_visibility: {sorted(kwargs)} are compute_visibility options; pass them only without visibility")
    unknown = [v for v in visibility if v not in scene.views]
    if unknown:
        raise ParameterError(f"with_visibility: scene {scene.id} has no view(s) {unknown[:5]!r}")
    instances = []
    for inst in scene.instances:
        merged = dict(inst.visibility)
        for view, row in visibility.items():
            if inst.id in row:
                merged[view] = row[inst.id]
        instances.append(replace(inst, visibility=merged))
    return scene.with_instances(instances)


#: Version of the visibility computation; part of its cache key (bump on a change of method).
VISIBILITY_VERSION = 1


def load_or_compute_visibility(
    scene: Scene,
    cache_dir: str | os.PathLike[str],
    *,
    image_size: tuple[int, int] = VISIBILITY_IMAGE_SIZE,
    canvas_scale: int = 3,
    backend: str = "auto",
    progress: bool = True,
) -> dict[str, dict[int, InstanceVisibility]]:
    """:func:`compute_visibility` of every view, cached as ``<cache_dir>/<scene id>.visibility.npz``.

    The entry holds ``views``, ``ids``, ``pixels`` (V, I) and ``fractions`` (V, I); its key
    (:func:`~spacedg.scene.derived_cache.views_key`) covers the method version, parameters,
    cameras, Gaussian count and the instance ids, so it is reused only for the same scene.
    """
    from spacedg.scene.derived_cache import read_npz_entry, views_key, write_npz_entry

    names = list(scene.views)
    size = _check_size(image_size, "load_or_compute_visibility")
    ids = [inst.id for inst in scene.instances]
    params = {"version": VISIBILITY_VERSION, "image_size": list(size), "canvas_scale": int(canvas_scale), "instances": ids}
    key = views_key(scene, names, params)
    path = Path(cache_dir) / f"{scene.id}.visibility.npz"
    cached = read_npz_entry(path, key)
    if cached is not None and cached.get("pixels", np.zeros(0)).shape == (len(names), len(ids)):
        pixels, fractions = cached["pixels"], cached["fractions"]
        return {
            view: {iid: InstanceVisibility(int(pixels[v, k]), float(fractions[v, k])) for k, iid in enumerate(ids)}
            for v, view in enumerate(names)
        }
    table = compute_visibility(scene, names, image_size=size, canvas_scale=canvas_scale, backend=backend, progress=progress)
    pixels = np.array([[table[v][i].visible_pixels for i in ids] for v in names], dtype=np.int64).reshape(len(names), len(ids))
    fractions = np.array([[table[v][i].visible_fraction for i in ids] for v in names], dtype=np.float64).reshape(len(names), len(ids))
    write_npz_entry(path, key, {"views": np.array(names, dtype=str), "ids": np.array(ids, dtype=np.int64), "pixels": pixels, "fractions": fractions})
    return table
