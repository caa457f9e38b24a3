"""Per-view instance visibility computed from rendered instance ids, cached per scene.

- :func:`compute_visibility` / :func:`with_visibility`: :class:`~spacedg.scene.model.InstanceVisibility`
  of every instance in every view, from the rendered instance-id map;
  :func:`load_or_compute_visibility` caches the table in ``<scene>/cache/``.
- The classes read from it (clearly visible / partly visible / hidden) and their thresholds are
  :mod:`spacedg.scene.visibility_classes`; view covisibility from rendered depth lives in
  :mod:`spacedg.scene.covisibility`.
"""


from __future__ import annotations

import os
from collections.abc import Iterable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians
from spacedg.render.renderer import render
from spacedg.scene.derived_cache import read_npz_entry, views_key, write_npz_entry
from spacedg.scene.model import InstanceVisibility, Scene

__all__ = [
    "compute_visibility", "with_visibility", "unbounded_canvas", "VISIBILITY_IMAGE_SIZE", "load_or_compute_visibility",
    "view_names", "check_size", "reduced_camera",
]

# =========================================================================================
# Computing visibility from renders
# =========================================================================================
#: Default reduced render size (width, height) of :func:`compute_visibility`, pixels.
VISIBILITY_IMAGE_SIZE = (160, 120)


def view_names(scene: Scene, views: Iterable[str] | None, caller: str) -> list[str]:
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


def check_size(image_size: tuple[int, int], caller: str) -> tuple[int, int]:
    try:
        w, h = (int(v) for v in image_size)
    except (TypeError, ValueError):
        raise ParameterError(f"{caller}: image_size must be (width, height) in pixels, got {image_size!r}") from None
    if w < 1 or h < 1 or (w, h) != tuple(image_size):
        raise ParameterError(f"{caller}: image_size must be two positive integers (width, height), got {image_size!r}")
    return w, h


def reduced_camera(camera: Camera, image_size: tuple[int, int]) -> Camera:
    """``camera`` at the largest image of its **own aspect ratio** inside ``image_size`` (a bounding box,
    pixels; never enlarged beyond its own resolution): :meth:`Camera.fitted`, the one image-size policy.
    A 4:3 view in the default 160×120 box renders at 160×120, a 16:9 one at 160×90, never squeezed."""
    return camera.fitted(min(image_size[0], camera.width), min(image_size[1], camera.height))


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
    device: str | None = None,
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
        image_size: reduced render size ``(width, height)`` in pixels, a bounding box: each view renders
            at the largest image of its own aspect inside it (:func:`reduced_camera`, intrinsics scaled
            with it); a view smaller than this renders at its own size.
        backend: render backend (``"auto"``, ``"cpu"``, ``"torch"``, ``"gsplat"``).
        device: torch device of the render (``"cuda"``: gsplat's CUDA compositor under ``auto``).
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


    names = view_names(scene, views, "compute_visibility")
    size = check_size(image_size, "compute_visibility")
    gaussians = scene.gaussians
    members = _instance_index(gaussians, scene.id)
    instance_ids = [inst.id for inst in scene.instances]
    subsets: dict[int, Gaussians] = {}
    out: dict[str, dict[int, InstanceVisibility]] = {}
    for name in tqdm(names, desc=f"visibility {scene.id}", unit="view", disable=not progress):
        full = scene.views[name]
        cam = reduced_camera(full, size)
        ids = render(gaussians, cam, outputs="instance_ids", backend=backend, device=device).instance_ids
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
            own_ids = render(subsets[iid], canvas, outputs="instance_ids", backend=backend, device=device).instance_ids
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
VISIBILITY_VERSION = 2  # 2: reduced renders keep each view's aspect (reduced_camera)


def load_or_compute_visibility(
    scene: Scene,
    cache_dir: str | os.PathLike[str],
    *,
    image_size: tuple[int, int] = VISIBILITY_IMAGE_SIZE,
    canvas_scale: int = 3,
    backend: str = "auto",
    progress: bool = True,
    device: str | None = None,
) -> dict[str, dict[int, InstanceVisibility]]:
    """:func:`compute_visibility` of every view, cached as ``<cache_dir>/<scene id>.visibility.npz``.

    The entry holds ``views``, ``ids``, ``pixels`` (V, I) and ``fractions`` (V, I); its key
    (:func:`~spacedg.scene.derived_cache.views_key`) covers the method version, parameters,
    cameras, Gaussian count and the instance ids, so it is reused only for the same scene.
    """

    names = list(scene.views)
    size = check_size(image_size, "load_or_compute_visibility")
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
    table = compute_visibility(scene, names, image_size=size, canvas_scale=canvas_scale, backend=backend, progress=progress, device=device)
    pixels = np.array([[table[v][i].visible_pixels for i in ids] for v in names], dtype=np.int64).reshape(len(names), len(ids))
    fractions = np.array([[table[v][i].visible_fraction for i in ids] for v in names], dtype=np.float64).reshape(len(names), len(ids))
    write_npz_entry(path, key, {"views": np.array(names, dtype=str), "ids": np.array(ids, dtype=np.int64), "pixels": pixels, "fractions": fractions})
    return table
