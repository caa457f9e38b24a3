"""Instance ids for Gaussians: by box containment, or by voting with annotation masks.

Question families read visibility from the rendered instance-id map, so every Gaussian of an
annotated object must carry that object's id (``Gaussians.instance_ids``, -1 = none). Real
captures arrive without them; :func:`assign_instances` gives them.

``method="boxes"`` (containment):

- A Gaussian belongs to a box when its centre lies inside the box grown by ``margin`` metres on
  every side (boundary Gaussians of a surface sit half their size outside a tight box).
- **Smallest box wins** on overlap (a cup on a table is the cup's); boxes of structural labels
  (:data:`STRUCTURAL_LABELS`: wall, floor, ceiling, ...) come after every other box whatever
  their volume, so they only take what no object took.
- **Floaters** stay -1: Gaussians with opacity below ``min_opacity``, and Gaussians too large for
  the box (standard deviation above half its longest side + margin: background splats crossing it).

``method="masks"`` (how SpaceDG lifts SAM masks to 3D): for every annotated view with a mask
file (``Instance.attributes["masks"]``, view → path), the Gaussians' centres are projected
into the view and kept where they are the visible surface (depth within 5 % + 2 cm of the
rendered depth at that pixel); each visible Gaussian inside an instance's mask votes for it.
A Gaussian takes the instance with the most votes when it holds at least ``min_votes`` (or every
view that saw it, if fewer) and at least half of the views that saw it; the opacity rule above applies too.

The :class:`AssignmentReport` gives per instance: Gaussians assigned, the share of its box's
volume they cover (occupied cells of an 8×8×8 grid in the box), and, where mask files exist,
the IoU of the rendered instance mask with the annotation mask (mean over up to ``iou_views``
views, rendered at most 160 px wide).
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

import numpy as np

from spacedg.errors import InvalidDataError, ParameterError
from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians
from spacedg.render.renderer import render
from spacedg.scene.box import OrientedBox
from spacedg.scene.model import Instance, Scene

__all__ = [
    "STRUCTURAL_LABELS", "InstanceCoverage", "AssignmentReport", "assign_instances", "assign_by_boxes",
    "ensure_instance_ids", "load_mask",
]

#: Labels of room structure, assigned after every object box (lower case, compared on label text).
STRUCTURAL_LABELS = frozenset({"wall", "floor", "ceiling", "room", "door frame", "window frame", "walls", "ground"})
#: Cells per axis of the grid that measures how much of a box its Gaussians cover.
COVERAGE_GRID = 8
#: Longest side of the renders used for mask IoU and mask voting, pixels.
MASK_RENDER_WIDTH = 160
#: ``(instance id, mask path as written) -> (H, W) bool mask or None``: where annotation masks come from.
MaskSource = Callable[[int, str], "np.ndarray | None"]


@dataclass(frozen=True)
class InstanceCoverage:
    """How well one instance's Gaussians match its annotation.

    Attributes:
        id, label: the instance.
        gaussians: Gaussians assigned to it.
        box_coverage: share of its box's 8×8×8 cells holding at least one of their centres, [0, 1].
        mask_iou: mean IoU of the rendered instance mask with the annotation masks, or ``None``
            when no mask file was found.
        structural: whether the label counts as room structure (assigned last).
    """

    id: int
    label: str
    gaussians: int
    box_coverage: float
    mask_iou: float | None
    structural: bool


@dataclass(frozen=True)
class AssignmentReport:
    """What :func:`assign_instances` did (``assigned`` of ``total`` Gaussians; ``floaters`` kept -1
    by the opacity rule; ``seconds`` of work)."""

    method: str
    total: int
    assigned: int
    floaters: int
    instances: tuple[InstanceCoverage, ...]
    seconds: float

    @property
    def empty_instances(self) -> list[int]:
        """Ids of instances that received no Gaussian (their questions will be skipped)."""
        return [c.id for c in self.instances if c.gaussians == 0]

    def mean_mask_iou(self) -> float | None:
        values = [c.mask_iou for c in self.instances if c.mask_iou is not None]
        return float(np.mean(values)) if values else None

    def to_dict(self) -> dict[str, object]:
        return {
            "method": self.method, "total": self.total, "assigned": self.assigned, "floaters": self.floaters,
            "seconds": round(self.seconds, 3),
            "instances": [
                {"id": c.id, "label": c.label, "gaussians": c.gaussians, "box_coverage": round(c.box_coverage, 4),
                 "mask_iou": None if c.mask_iou is None else round(c.mask_iou, 4), "structural": c.structural}
                for c in self.instances
            ],
        }

    def table(self, limit: int = 40) -> str:
        """A plain-text table, one row per instance (at most ``limit``)."""
        lines = [f"{'id':>5} {'label':<24} {'gaussians':>10} {'box cover':>9} {'mask IoU':>8}"]
        for c in self.instances[:limit]:
            iou = "-" if c.mask_iou is None else f"{c.mask_iou:.2f}"
            lines.append(f"{c.id:>5} {c.label[:24]:<24} {c.gaussians:>10,} {c.box_coverage:>9.0%} {iou:>8}")
        if len(self.instances) > limit:
            lines.append(f"... {len(self.instances) - limit} more")
        return "\n".join(lines)


def _is_structural(label: str) -> bool:
    return " ".join(label.replace("_", " ").lower().split()) in STRUCTURAL_LABELS


def assign_by_boxes(
    gaussians: Gaussians,
    instances: Iterable[Instance],
    *,
    margin: float = 0.02,
    min_opacity: float = 0.05,
) -> np.ndarray:
    """(N,) int32 instance ids by box containment (rules in the module docstring)."""
    if not (margin >= 0):
        raise ParameterError(f"assign_instances: margin must be >= 0 metres, got {margin}")
    means = gaussians.means.astype(np.float64)
    ids = np.full(len(gaussians), -1, dtype=np.int32)
    eligible = gaussians.opacities >= min_opacity
    sigma = gaussians.scales.max(axis=1).astype(np.float64)
    order = sorted(instances, key=lambda inst: (_is_structural(inst.label), inst.box.volume, inst.id))
    for inst in order:
        box = inst.box
        corners = box.corners()
        lo, hi = corners.min(axis=0) - margin, corners.max(axis=0) + margin
        cand = np.flatnonzero(((means >= lo) & (means <= hi)).all(axis=1) & (ids < 0) & eligible)
        if cand.size == 0:
            continue
        inside = box.contains(means[cand], tol=margin) & (sigma[cand] <= 0.5 * float(box.extents.max()) + margin)
        ids[cand[inside]] = inst.id
    return ids


def _coverage(box: OrientedBox, points: np.ndarray) -> float:
    if points.shape[0] == 0:
        return 0.0
    local = box.to_local(points) / np.maximum(box.extents, 1e-9) + 0.5
    cells = np.clip(np.floor(local * COVERAGE_GRID), 0, COVERAGE_GRID - 1).astype(np.int64)
    flat = (cells[:, 0] * COVERAGE_GRID + cells[:, 1]) * COVERAGE_GRID + cells[:, 2]
    return float(np.unique(flat).size) / COVERAGE_GRID**3


def load_mask(path: str | Path, masks_root: str | Path | None = None) -> np.ndarray | None:
    """A binary annotation mask (H, W) bool, or ``None`` if the file is not found.

    ``path`` is tried as written, then (Holi-Spatial writes absolute paths of the machine that
    made them) as ``masks_root / <parent folder> / <file name>`` and ``masks_root / <file name>``.
    """
    import cv2

    raw = Path(str(path).replace("\\", "/"))
    candidates = [raw]
    if masks_root is not None:
        root = Path(masks_root)
        candidates += [root / raw.parent.name / raw.name, root / raw.name]
    for candidate in candidates:
        if candidate.is_file():
            image = cv2.imread(str(candidate), cv2.IMREAD_GRAYSCALE)
            if image is None:
                raise InvalidDataError(f"{candidate}: cannot decode the mask image (PNG expected)")
            return image > 0
    return None


def _reduced(camera: Camera) -> Camera:
    if camera.width <= MASK_RENDER_WIDTH:
        return camera
    height = max(1, round(camera.height * MASK_RENDER_WIDTH / camera.width))
    return camera.resized(MASK_RENDER_WIDTH, height)


def _resize_mask(mask: np.ndarray, width: int, height: int) -> np.ndarray:
    import cv2

    if mask.shape == (height, width):
        return mask
    return cv2.resize(mask.astype(np.uint8), (width, height), interpolation=cv2.INTER_NEAREST) > 0


def _masks_of(instances: Iterable[Instance]) -> dict[str, list[tuple[int, str]]]:
    """view → [(instance id, mask path)]."""
    out: dict[str, list[tuple[int, str]]] = {}
    for inst in instances:
        masks = inst.attributes.get("masks") or {}
        if isinstance(masks, Mapping):
            for view, path in sorted(masks.items()):
                out.setdefault(str(view), []).append((inst.id, str(path)))
    return out


def _file_masks(masks_root: str | Path | None) -> MaskSource:
    return lambda _iid, path: load_mask(path, masks_root)


def _assign_by_masks(
    scene: Scene, gaussians: Gaussians, source: MaskSource, min_votes: int, min_opacity: float,
    backend: str, progress: bool,
) -> np.ndarray:
    from tqdm import tqdm


    by_view = {v: m for v, m in _masks_of(scene.instances).items() if v in scene.views}
    if not by_view:
        raise InvalidDataError(
            f"assign_instances(method='masks'): no instance of scene {scene.id} names a mask file "
            "(attributes['masks'], view → path, as read from Holi-Spatial's 'images'); use method='boxes'"
        )
    n = len(gaussians)
    means = gaussians.means.astype(np.float64)
    seen = np.zeros(n, dtype=np.int32)
    pairs: list[np.ndarray] = []
    found = 0
    for view, items in tqdm(sorted(by_view.items()), desc=f"mask votes {scene.id}", unit="view", disable=not progress):
        cam = _reduced(scene.views[view])
        loaded = [(iid, source(iid, path)) for iid, path in items]
        loaded = [(iid, _resize_mask(m, cam.width, cam.height)) for iid, m in loaded if m is not None]
        if not loaded:
            continue
        found += len(loaded)
        depth = render(gaussians, cam, outputs="depth", backend=backend).depth
        uv, z, valid = cam.project(means)
        valid &= cam.in_image(uv)
        idx = np.flatnonzero(valid)
        cols = np.clip(uv[idx, 0].astype(np.int64), 0, cam.width - 1)
        rows = np.clip(uv[idx, 1].astype(np.int64), 0, cam.height - 1)
        surface = depth[rows, cols]
        front = (surface > 0) & (z[idx] <= surface * 1.05 + 0.02)
        idx, rows, cols = idx[front], rows[front], cols[front]
        seen[idx] += 1
        for iid, mask in loaded:
            hit = idx[mask[rows, cols]]
            if hit.size:
                pairs.append(np.stack([hit.astype(np.int64), np.full(hit.size, iid, np.int64)], axis=1))
    if found == 0:
        raise InvalidDataError(
            f"assign_instances(method='masks'): none of the mask files named by scene {scene.id} was found; "
            "pass masks_root (the folder holding <image stem>/<label>.png) or use method='boxes'"
        )
    ids = np.full(n, -1, dtype=np.int32)
    if not pairs:
        return ids
    allpairs = np.concatenate(pairs)
    keys, counts = np.unique(allpairs, axis=0, return_counts=True)
    order = np.lexsort((-counts, keys[:, 0]))  # per Gaussian, the most votes first
    keys, counts = keys[order], counts[order]
    first = np.ones(len(keys), dtype=bool)
    first[1:] = keys[1:, 0] != keys[:-1, 0]
    g, inst, votes = keys[first, 0], keys[first, 1], counts[first]
    ok = (votes >= np.minimum(min_votes, seen[g])) & (votes * 2 >= seen[g]) & (gaussians.opacities[g] >= min_opacity)
    ids[g[ok]] = inst[ok].astype(np.int32)
    return ids


def _mask_ious(
    scene: Scene, gaussians: Gaussians, source: MaskSource, iou_views: int, backend: str
) -> dict[int, float]:

    by_view = _masks_of(scene.instances)
    wanted: dict[int, list[tuple[str, str]]] = {}
    for view, items in sorted(by_view.items()):
        if view not in scene.views:
            continue
        for iid, path in items:
            if len(wanted.setdefault(iid, [])) < iou_views:
                wanted[iid].append((view, path))
    renders: dict[str, np.ndarray] = {}
    out: dict[int, list[float]] = {}
    for iid, items in wanted.items():
        for view, path in items:
            mask = source(iid, path)
            if mask is None:
                continue
            cam = _reduced(scene.views[view])
            if view not in renders:
                frame = render(gaussians, cam, outputs="instance_ids", backend=backend)
                assert frame.instance_ids is not None
                renders[view] = frame.instance_ids
            rendered = renders[view] == iid
            mask = _resize_mask(mask, cam.width, cam.height)
            union = np.count_nonzero(rendered | mask)
            out.setdefault(iid, []).append(np.count_nonzero(rendered & mask) / union if union else 0.0)
    return {iid: float(np.mean(v)) for iid, v in out.items() if v}


def assign_instances(
    scene: Scene,
    method: Literal["boxes", "masks"] = "boxes",
    *,
    margin: float = 0.02,
    min_opacity: float = 0.05,
    min_votes: int = 2,
    masks_root: str | Path | None = None,
    iou_views: int = 3,
    backend: str = "auto",
    progress: bool = True,
    mask_source: MaskSource | None = None,
) -> tuple[Scene, AssignmentReport]:
    """Give every Gaussian of ``scene`` an instance id (see the module docstring for the rules).

    Args:
        scene: a scene with annotated instances (boxes; masks for ``method="masks"``).
        method: ``"boxes"`` (containment) or ``"masks"`` (voting with projected annotation masks).
        margin: growth of each box on every side, metres (``"boxes"``).
        min_opacity: Gaussians below this opacity stay -1 (floaters).
        min_votes: fewest mask votes for an id (``"masks"``).
        masks_root: folder where mask files are looked up when their recorded path does not exist.
        iou_views: masks per instance used for the rendered-mask IoU of the report.
        backend: renderer backend for the mask work.
        progress: progress bar over views.
        mask_source: where masks come from, ``(instance id, mask path) -> mask or None``
            (e.g. Holi-Spatial's RLE, :class:`~spacedg.scene.io.holispatial.RleMasks`); default:
            the mask files (:func:`load_mask` with ``masks_root``).

    Returns:
        ``(scene with Gaussians carrying instance_ids, report)``. Existing ids are replaced.

    Raises:
        InvalidDataError: no instances; ``"masks"`` without any readable mask file.
    """
    if method not in ("boxes", "masks"):
        raise ParameterError(f"assign_instances: method must be 'boxes' or 'masks', got {method!r}")
    if not scene.instances:
        raise InvalidDataError(f"assign_instances: scene {scene.id} has no annotated instances to assign Gaussians to")
    start = time.perf_counter()
    gaussians = scene.gaussians
    source = mask_source if mask_source is not None else _file_masks(masks_root)
    if method == "boxes":
        ids = assign_by_boxes(gaussians, scene.instances, margin=margin, min_opacity=min_opacity)
    else:
        ids = _assign_by_masks(scene, gaussians, source, int(min_votes), min_opacity, backend, progress)
    labelled = replace(gaussians, instance_ids=ids)
    out = Scene(scene.id, labelled, scene.views, scene.instances, scene.up, scene.vocabulary, scene.metadata, scene.covisibility)
    ious = _mask_ious(out, labelled, source, iou_views, backend) if _masks_of(scene.instances) else {}
    means = labelled.means.astype(np.float64)
    rows = []
    for inst in sorted(scene.instances, key=lambda i: i.id):
        members = ids == inst.id
        rows.append(InstanceCoverage(
            inst.id, inst.label, int(members.sum()), _coverage(inst.box, means[members]), ious.get(inst.id), _is_structural(inst.label)
        ))
    report = AssignmentReport(
        method, len(labelled), int((ids >= 0).sum()), int((gaussians.opacities < min_opacity).sum()), tuple(rows),
        time.perf_counter() - start,
    )
    return out, report


def ensure_instance_ids(scene: Scene) -> Scene:
    """``scene`` itself when its Gaussians carry instance ids (or it has no instances); otherwise
    the scene with ids assigned by boxes, with a warning saying how to keep them."""
    if not scene.instances or scene.gaussians.instance_ids is not None:
        return scene
    out, report = assign_instances(scene, "boxes", progress=False)
    warnings.warn(
        f"scene {scene.id}: its Gaussians carried no instance ids; assigned {report.assigned:,} of {report.total:,} by box "
        f"containment for this run ({len(report.empty_instances)} instance(s) got none). Save them with "
        "`spacedg scenes import` (or spacedg.assign_instances + save_scene) to skip this step",
        stacklevel=2,
    )
    return out
