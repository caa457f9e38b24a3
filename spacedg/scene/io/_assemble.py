"""Assemble a :class:`Scene` from foreign files: Gaussians + cameras + optional instances."""

from __future__ import annotations

import functools
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, Literal

from spacedg.errors import FileFormatError
from spacedg.files import PathLike, as_path, require_file
from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians
from spacedg.scene import capture_checks as checks
from spacedg.scene.io.capture import find_cameras, read_cameras, scale_gaussians, scale_instances, scale_views
from spacedg.scene.io.instances import read_instances
from spacedg.scene.io.ply import read_ply
from spacedg.scene.io.splat import read_splat
from spacedg.scene.io.spz import read_spz
from spacedg.scene.model import Scene

#: Gaussian file suffixes :func:`read_gaussians` reads.
GAUSSIAN_SUFFIXES = (".ply", ".splat", ".spz")


def read_gaussians(path: PathLike) -> Gaussians:
    """Read Gaussians from a ``.ply`` (INRIA 3DGS, PlayCanvas compressed, colour-only), ``.splat``
    or ``.spz`` file, chosen by suffix. ``.ksplat`` is refused with a conversion hint."""
    p = as_path(path, "Gaussians file")
    suffix = p.suffix.lower()
    if suffix == ".ply":
        return read_ply(p)
    if suffix == ".splat":
        return read_splat(p)
    if suffix == ".spz":
        return read_spz(p)
    if suffix == ".ksplat":
        raise FileFormatError(
            f"{p}: .ksplat (GaussianSplats3D's viewer format) is not read: it has versioned, quantised sections with no "
            "published spec outside that viewer. Export the scene as .ply (or convert with that viewer's tools) and import the .ply"
        )
    raise FileFormatError(f"{p}: unknown Gaussians file type {p.suffix!r}; use a .ply (INRIA 3DGS / compressed), .splat or .spz file")


def load_scaled_gaussians(path: str, scale: float) -> Gaussians:
    """Read Gaussians and scale them to metres (module-level so a partial of it pickles)."""
    return scale_gaussians(read_gaussians(path), scale)


def read_views(source: PathLike | Mapping[str, Camera], opencv_distortion: Literal["error", "drop"] = "error") -> dict[str, Camera]:
    """Cameras from a COLMAP model folder (or a project with ``sparse/0``), a ``transforms.json``
    (or a folder holding one and no COLMAP model), an INRIA ``cameras.json``, or a ready mapping
    name → Camera. The format is told by :func:`~spacedg.scene.io.capture.find_cameras`."""
    if isinstance(source, Mapping):
        return dict(source)
    return read_cameras(find_cameras(as_path(source, "views")), opencv_distortion)


def scene_from_files(
    id: str,
    gaussians_path: PathLike,
    views: PathLike | Mapping[str, Camera],
    instances_path: PathLike | None = None,
    up: str | Iterable[float] | None = None,
    metres_per_unit: float | None = None,
    *,
    units: Literal["auto", "metric"] = "auto",
    trust_up: bool = False,
    frame_check: Literal["error", "warn"] = "error",
    opencv_distortion: Literal["error", "drop"] = "error",
    metadata: Mapping[str, Any] | None = None,
) -> Scene:
    """Build a :class:`Scene` from a Gaussians file, cameras and (optionally) instance boxes, with the
    checks of ``spacedg scenes import`` (:mod:`spacedg.scene.capture_checks`: the same functions, the
    same errors, the same override arguments).

    Args:
        id: scene id.
        gaussians_path: ``.ply`` (INRIA 3DGS), ``.splat`` or ``.spz``; loaded lazily on first use when
            there are no instances (the box checks need the Gaussians' centres).
        views: a COLMAP model folder, a ``transforms.json`` (or its folder), an INRIA
            ``cameras.json``, or a mapping name → Camera (see :func:`read_views`). Camera files are
            the capture's own (their ``capture_focal`` is set); a mapping's cameras are used as given
            (mark them with :meth:`Camera.as_captured` when the Gaussians were trained on them).
        instances_path: instance JSON (:func:`read_instances`, Holi-Spatial's layout included);
            image references must resolve to views.
        up: ``None``/``"auto"`` (estimated from the cameras, else the boxes), an axis (``"+z"``) or three
            numbers, in the **files'** world frame; verified against the capture's evidence either way.
        metres_per_unit: metres per file unit, applied once to Gaussians (positions and sizes), camera
            centres and boxes (up is a direction and is not scaled). ``None``: the files carry no metric
            scale, so 1 m per unit is taken **only when the labelled objects agree** (else refused).
        units: ``"metric"`` states the files are in metres (not checked).
        trust_up: keep an up the evidence contradicts (recorded as overridden).
        frame_check: ``"warn"`` writes boxes that do not hold their objects anyway (noted in metadata).
        opencv_distortion: passed to the camera reader.
        metadata: extra facts; ``source``, ``scale_to_metres``, ``up_source``, ``up_evidence``,
            ``units`` (and ``box_fill`` with instances) are added.

    Raises:
        ParameterError: a bad ``up``, ``metres_per_unit``, ``units`` or ``frame_check``.
        UpContradictedError / UpUndecidedError / UnitsImplausibleError / BoxFillError: as ``scenes import``.
    """
    checks.check_metres_per_unit(metres_per_unit)
    gpath = as_path(gaussians_path, "Gaussians file")
    require_file(gpath, "Gaussians file")
    if gpath.suffix.lower() not in GAUSSIAN_SUFFIXES:
        read_gaussians(gpath)  # raises the suffix's own message
    files = None if isinstance(views, Mapping) else find_cameras(as_path(views, "views"))
    cameras = dict(views) if files is None else read_cameras(files, opencv_distortion)
    instances = read_instances(instances_path, views=cameras.keys()) if instances_path is not None else []
    gauss = read_gaussians(gpath) if instances else None
    layout = "gaussians" if files is None else files.kind
    decided = checks.decide_frame(cameras, instances, where=str(gpath), layout=layout, up=up,
                                  means=None if gauss is None else gauss.means, units=units, metres_per_unit=metres_per_unit,
                                  trust_up=trust_up)
    scale = decided.metres_per_unit
    if scale != 1.0:
        cameras = scale_views(cameras, scale)
        instances = scale_instances(instances, scale)
    meta: dict[str, Any] = dict(metadata or {})
    meta.update(source={"gaussians": str(gpath), "views": "<memory>" if files is None else str(Path(views)),  # type: ignore[arg-type]
                        "instances": None if instances_path is None else str(Path(instances_path))}, **decided.metadata())
    if gauss is None:
        return Scene(id, functools.partial(load_scaled_gaussians, str(gpath), scale), cameras, instances, decided.up.tolist(), None, meta)
    gauss = scale_gaussians(gauss, scale)
    fill, note = checks.check_box_fill(gauss.means, instances, where=str(instances_path), layout=layout, frame_check=frame_check,
                                       instance_ids=gauss.instance_ids, metres_per_file_unit=scale)
    if fill is not None:
        meta["box_fill"] = fill.to_dict()
    if note:
        meta["notes"] = [*meta.get("notes", []), note]
    return Scene(id, gauss, cameras, instances, decided.up.tolist(), None, meta)
