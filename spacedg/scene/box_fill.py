"""Do the annotated boxes hold their objects? Per-box fill measures and the shift that fits a box best.

A box annotation that is off (another frame, a typo, a box drawn on another reconstruction)
silently turns every distance, size and direction question about its object wrong. For every
box :func:`measure_box_fill` measures, from the Gaussian **centres** (all of them, whatever their
opacity):

- ``inside``: centres inside the box (a centre inside a smaller box belongs to that one);
- ``fill``: share of the box's volume they fill: the share of the cells of a
  :data:`FILL_GRID`³ grid laid in the box that hold at least one centre, [0, 1];
- ``near``: centres just outside, in the shell of :data:`MARGIN_SHARE` of the box's **longest**
  side on every face (the box grown by 10 % of its longest side at each face, minus the box: a
  thin book's box gets a shell as thick as a cup's would);
- ``shift``: for a bad or loose box, the translation (scene units: metres once the import scaled
  the files) that fits it best, when one exists.

**Verdict** (``status``):

- ``"empty"``: no centre inside the box nor just outside;
- ``"shifted"``: the box is off its object, found by the per-axis **ends test** of
  :mod:`spacedg.scene.box_shift`: both ends of the object's centres moved past the box's faces
  the same way by at least 3 % of the side (neighbours' centres, claimed by their own boxes or
  by the Gaussians' instance ids, and planes lying across a face, a floor or a wall, left out);
  ``shift`` is the ends' move, which puts the box back;
- ``"outside"`` (mostly outside its object): shifted, and the box moved by ``shift`` holds at
  least :data:`MIN_GROWTH` × its count;
- ``"loose"``: no centre inside the box, some just outside, and no shift found (a small object
  whose few splats sit around a tight box): reported, not an error;
- ``"ok"``.

**Best placement** of an empty or loose box (its suggested ``shift``): translations ``t`` within
±1 longest side along the box's axes, among the centres no other box claims, scored
``inside(t) − near(t)`` (a box around a compact object holds it with little around; sliding a
box onto a wall or a table top gains as much in its shell as inside), exactly on a coarse grid
(steps of 1/10 of the longest side) then a fine one (1/50) by a summed-volume table of a histogram
of the box-local centres: a box costs a few milliseconds whatever the number of Gaussians. (A
count-based verdict from this search, "its best placement holds twice as many", was dropped: it
flagged correct small boxes beside larger objects in synthetic rooms 12, 13 and 15 and never a
large box moved by 7 cm.)

``benchmarks/box_fill.py`` prints the detections (box × shift direction) and the false alarms on
correct boxes (synthetic rooms, the tabletop, the Holi-Spatial fixture, the shared plant).

An empty, outside or shifted box is an error (:meth:`BoxFillReport.raise_if_bad`,
:class:`BoxFillError`) naming each such box (id, label), what is wrong and its suggested shift
(scene units, and file units where the import scaled them), with the causes that fit the capture
layout actually imported (:func:`layout_causes`). The import summary's "boxes holding Gaussians"
and the fill table both come from the same :class:`BoxFillReport`.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from spacedg.errors import InvalidDataError
from spacedg.scene.box import OrientedBox
from spacedg.scene.box_shift import estimate_shift, foreign_points
from spacedg.scene.model import Instance

__all__ = [
    "BoxFill", "BoxFillReport", "BoxFillError", "measure_box_fill", "layout_causes",
    "MARGIN_SHARE", "FILL_GRID", "MIN_GROWTH", "STATUSES", "BAD",
]

#: Thickness of the "just outside" shell, share of the box's longest side, on every face.
MARGIN_SHARE = 0.10
#: Thinnest side a box is measured with, share of its longest side (flat boxes are allowed).
MIN_THICKNESS = 0.02
#: Cells per axis of the grid measuring how much of a box's volume its Gaussians fill.
FILL_GRID = 8
#: Verdicts of a box, worst first (``BAD``: an error at import).
STATUSES = ("empty", "outside", "shifted", "loose", "ok")
BAD = ("empty", "outside", "shifted")
#: What each bad verdict means, for messages.
_WHAT = {"empty": "empty (no Gaussian inside it or just outside)", "outside": "mostly outside its object",
         "shifted": "shifted off its object"}
#: A shifted box is *mostly outside* its object when, moved by its shift, it holds at least this many times its count.
MIN_GROWTH = 2.0
#: Weight of the shell's centres in the best-fit score ``inside − weight · near``.
SHELL_WEIGHT = 1.0
#: Search steps per longest side: coarse then fine.
_COARSE, _FINE = 10, 50


class BoxFillError(InvalidDataError):
    """Boxes that do not hold their objects (the message names each box, its shift and the causes)."""


@dataclass(frozen=True)
class BoxFill:
    """Fill measures of one box (see the module docstring).

    Attributes:
        id, label: the instance.
        inside: Gaussian centres inside the box.
        fill: share of the box's :data:`FILL_GRID`³ cells holding a centre, [0, 1].
        near: centres in the shell just outside (:data:`MARGIN_SHARE` of the longest side per face).
        status: one of :data:`STATUSES`.
        shift: world translation fitting the box best (scene units), or ``None`` when the box is ok
            or no placement within ±1 extent holds Gaussians.
        shifted_inside, shifted_near: centres inside / just outside the box moved by ``shift`` (0 without a shift).
    """

    id: int
    label: str
    inside: int
    fill: float
    near: int
    status: str
    shift: tuple[float, float, float] | None = None
    shifted_inside: int = 0
    shifted_near: int = 0

    @property
    def bad(self) -> bool:
        """Empty, mostly outside or shifted: an error at import."""
        return self.status in BAD

    def shift_text(self, metres_per_file_unit: float = 1.0) -> str:
        """``"(dx, dy, dz) = |d|"`` in scene units, followed by the same in file units when the import
        scaled them (``metres_per_file_unit`` ≠ 1); ``"-"`` without a shift."""
        if self.shift is None:
            return "-"
        d = np.asarray(self.shift)
        text = f"({d[0]:+.3f}, {d[1]:+.3f}, {d[2]:+.3f}) = {np.linalg.norm(d):.3f}"
        if metres_per_file_unit != 1.0:
            f = d / metres_per_file_unit
            text += f" m = ({f[0]:+.3f}, {f[1]:+.3f}, {f[2]:+.3f}) = {np.linalg.norm(f):.3f} file units"
        return text

    def to_dict(self) -> dict[str, object]:
        return {"id": self.id, "label": self.label, "inside": self.inside, "fill": round(self.fill, 4), "near": self.near,
                "status": self.status, "shift": None if self.shift is None else [round(v, 5) for v in self.shift],
                "shifted_inside": self.shifted_inside, "shifted_near": self.shifted_near}


@dataclass(frozen=True)
class BoxFillReport:
    """Fill of every box of a scene (:func:`measure_box_fill`); rows sorted by instance id.

    ``metres_per_file_unit``: the import's scale (the rows are in scene units, metres once scaled);
    messages give shifts in both."""

    rows: tuple[BoxFill, ...]
    total_gaussians: int
    metres_per_file_unit: float = 1.0

    @property
    def holding(self) -> int:
        """Boxes holding at least one Gaussian centre (the same ``inside`` the table prints)."""
        return sum(r.inside > 0 for r in self.rows)

    @property
    def held_share(self) -> float | None:
        """Share of boxes holding at least one Gaussian; ``None`` without boxes."""
        return self.holding / len(self.rows) if self.rows else None

    @property
    def bad(self) -> list[BoxFill]:
        return [r for r in self.rows if r.bad]

    def counts(self) -> dict[str, int]:
        """Boxes per status (every one of :data:`STATUSES`)."""
        return {s: sum(r.status == s for r in self.rows) for s in STATUSES}

    def summary(self) -> str:
        """One line, computed from the same rows as :meth:`table`."""
        if not self.rows:
            return "no boxes"
        c = self.counts()
        return (f"boxes holding Gaussians {self.holding} of {len(self.rows)} ({self.held_share:.0%}), "
                f"{c['empty']} empty, {c['outside']} mostly outside, {c['shifted']} shifted, "
                f"{c['loose']} loose (Gaussians only just outside), mean fill {np.mean([r.fill for r in self.rows]):.0%}")

    def table(self, limit: int = 40) -> str:
        """A plain-text table, one row per box (at most ``limit``; bad boxes first)."""
        lines = [f"{'id':>5} {'label':<20} {'inside':>8} {'fill':>5} {'near':>7} {'status':<9} best shift (scene units)"]
        rows = sorted(self.rows, key=lambda r: (STATUSES.index(r.status), r.id))
        for r in rows[:limit]:
            lines.append(f"{r.id:>5} {r.label[:20]:<20} {r.inside:>8,} {r.fill:>5.0%} {r.near:>7,} {r.status:<9} {r.shift_text()}")
        if len(rows) > limit:
            lines.append(f"... {len(rows) - limit} more")
        return "\n".join(lines)

    def text(self, limit: int = 40) -> str:
        """The summary line and the table (what a benchmark prints), from the same rows."""
        return self.summary() + "\n" + self.table(limit)

    def to_dict(self) -> dict[str, object]:
        return {"held_share": None if self.held_share is None else round(self.held_share, 4), "holding": self.holding,
                "boxes": len(self.rows), "counts": self.counts(), "rows": [r.to_dict() for r in self.rows]}

    def _describe(self, r: BoxFill) -> str:
        """One bad box: what is wrong, its counts and the shift that fits it."""
        shift = r.shift_text(self.metres_per_file_unit)
        if r.status == "shifted":
            fix = f"moving it by {shift} fits it"
        elif r.shift is not None:
            fix = f"moving it by {shift} would hold {r.shifted_inside:,}"
        else:
            fix = "no placement within one box size holds any Gaussian"
        return f"box {r.id} '{r.label}' is {_WHAT[r.status]} ({r.inside:,} Gaussians inside, {r.near:,} just outside; {fix})"

    def message(self, where: str, layout: str) -> str:
        """The error text for the bad boxes: each box, its shift, the causes fitting ``layout``."""
        bad = self.bad
        parts = [self._describe(r) for r in bad[:8]]
        if len(bad) > 8:
            parts.append(f"... and {len(bad) - 8} more")
        common = _common_shift(bad)
        far = any(r.status == "empty" and r.shift is None for r in bad)  # more than a box size from any Gaussian
        frame_wide = len(bad) == len(self.rows) or len(bad) >= max(2, len(self.rows) / 2) or common is not None or far
        causes = layout_causes(layout, frame_wide=frame_wide, common=common)
        return (f"{where}: {len(bad)} of {len(self.rows)} boxes do not hold their objects: " + "; ".join(parts)
                + f". {causes} To write the scene anyway, pass --allow-frame-mismatch (questions about these boxes will be wrong).")

    def raise_if_bad(self, where: str, layout: str, *, misplaced: bool = True) -> None:
        """Raise :class:`BoxFillError` when a box is empty or, with ``misplaced``, mostly outside or shifted
        (a ``"loose"`` box is not an error)."""
        if any(r.status == "empty" or (misplaced and r.bad) for r in self.rows):
            raise BoxFillError(self.message(where, layout))


def _common_shift(bad: Sequence[BoxFill]) -> np.ndarray | None:
    """The shared world shift of several bad boxes, when they agree within 20 % (a frame offset)."""
    shifts = np.array([r.shift for r in bad if r.shift is not None], dtype=np.float64)
    if len(shifts) < 2:
        return None
    mean = shifts.mean(axis=0)
    spread = float(np.linalg.norm(shifts - mean, axis=1).max())
    return mean if spread <= 0.2 * float(np.linalg.norm(mean)) else None


_LAYOUT_CAUSES = {
    "inria": "the boxes were annotated on another reconstruction of these images (every COLMAP / INRIA run has its own "
             "origin, rotation and scale: annotate the point_cloud.ply you import), or the box file is in other units than the capture",
    "colmap": "the boxes were annotated on another reconstruction of these images (every COLMAP run has its own origin, "
              "rotation and scale: annotate the Gaussians trained on this model), or the box file is in other units than the capture",
    "nerfstudio": "the boxes are in the COLMAP frame while the Gaussians are in transforms.json's frame (its applied_transform) "
                  "or in splatfacto's normalised frame (pass --dataparser-transforms), or the reverse",
    "scannetpp": "the boxes are in the ScanNet++ scan (mesh) frame while the Gaussians were trained in another frame "
                 "(train them on the poses of the scene's nerfstudio/transforms_undistorted.json)",
    "gaussians": "the boxes, the Gaussians and the cameras come from different reconstructions or frames",
}


def layout_causes(layout: str, *, frame_wide: bool, common: np.ndarray | None = None) -> str:
    """Probable causes of bad boxes that fit ``layout`` (one of the importer's layouts).

    ``frame_wide``: many boxes (or several with one shared shift) are off, which points at the
    frame of the whole annotation rather than at single boxes.
    """
    single = "the annotation of these boxes is off: correct their position (obb_transform translation / corners; by the shift given where there is one), or drop them"
    if not frame_wide:
        return f"Probable cause: {single}."
    offset = "" if common is None else f"they are all off by about ({common[0]:+.3f}, {common[1]:+.3f}, {common[2]:+.3f}): "
    return f"Probable cause: {offset}{_LAYOUT_CAUSES.get(layout, _LAYOUT_CAUSES['gaussians'])}; or {single}."


# --------------------------------------------------------------------------- measures
def _scale(box: OrientedBox) -> float:
    """The box's longest side (at least 1e-6): the unit of the box-local coordinates, of the shell and of the search."""
    return max(float(box.extents.max()), 1e-6)


def _half(box: OrientedBox) -> np.ndarray:
    """Half side lengths in units of the longest side (the longest is ½); a flat or nearly flat box
    (a poster, a rug) counts as :data:`MIN_THICKNESS` of its longest side thick."""
    return np.maximum(box.extents.astype(np.float64) / (2.0 * _scale(box)), MIN_THICKNESS / 2.0)


def _candidates(sorted_means: np.ndarray, box: OrientedBox, reach: float) -> np.ndarray:
    """Indices into ``sorted_means`` (sorted by x) of the centres within ``reach`` longest sides of the box (a superset)."""
    half = np.abs(box.rotation) @ (box.extents * 0.5 + reach * _scale(box))
    lo, hi = box.center - half, box.center + half
    a = int(np.searchsorted(sorted_means[:, 0], lo[0], side="left"))
    b = int(np.searchsorted(sorted_means[:, 0], hi[0], side="right"))
    chunk = sorted_means[a:b]
    keep = ((chunk[:, 1:] >= lo[1:]) & (chunk[:, 1:] <= hi[1:])).all(axis=1)
    return a + np.flatnonzero(keep)


def _local(points: np.ndarray, box: OrientedBox) -> np.ndarray:
    """Box-local coordinates in units of the box's longest side (the box is ``|u_i| ≤ _half(box)_i``)."""
    d = points - box.center
    rot = box.rotation / _scale(box)
    return d[:, 0:1] * rot[0] + d[:, 1:2] * rot[1] + d[:, 2:3] * rot[2]  # (d @ R) / scale, without a BLAS call per box


def _counts(u: np.ndarray, t: np.ndarray, half: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(inside mask, shell mask) of the box moved by ``t`` (longest-side units)."""
    d = (np.abs(u - t) - half).max(axis=1)
    return d <= 0.0, (d > 0.0) & (d <= MARGIN_SHARE)


def _fill(u_inside: np.ndarray, half: np.ndarray) -> float:
    if u_inside.shape[0] == 0:
        return 0.0
    rel = u_inside / np.maximum(2.0 * half, 1e-9) + 0.5
    cells = np.clip(np.floor(rel * FILL_GRID), 0, FILL_GRID - 1).astype(np.int64)
    flat = (cells[:, 0] * FILL_GRID + cells[:, 1]) * FILL_GRID + cells[:, 2]
    return float(np.unique(flat).size) / FILL_GRID**3


def _window_sums(sat: np.ndarray, lo: list[np.ndarray], size: np.ndarray) -> np.ndarray:
    """Sums of the histogram over the windows ``[lo, lo + size)`` (per axis) from its summed-volume table."""
    total = np.zeros(lo[0].shape, dtype=np.int64)
    for corner in range(8):
        pick = [lo[ax] + size[ax] if corner >> ax & 1 else lo[ax] for ax in range(3)]
        sign = (-1) ** (3 - bin(corner).count("1"))
        total += sign * sat[pick[0], pick[1], pick[2]]
    return total


def _grid_search(u: np.ndarray, half: np.ndarray, centre: np.ndarray, steps: int, reach_cells: int) -> np.ndarray:
    """Best shift (longest-side units) of the box around ``centre`` ± ``reach_cells`` cells of size 1/``steps``,
    scored ``inside − SHELL_WEIGHT · shell`` on the grid (box sides rounded to whole cells) through a
    summed-volume table; ties go to the smallest shift."""
    h = 1.0 / steps
    shell = max(1, round(MARGIN_SHARE * steps))
    box = np.maximum(1, np.round(2.0 * half * steps)).astype(np.int64)
    n = 2 * (reach_cells + shell) + box
    origin = centre - (reach_cells + shell) * h - box * h / 2.0
    idx = np.floor((u - origin) / h).astype(np.int64)
    idx = idx[((idx >= 0) & (idx < n)).all(axis=1)]
    hist = np.bincount((idx[:, 0] * n[1] + idx[:, 1]) * n[2] + idx[:, 2], minlength=int(np.prod(n))).reshape(tuple(n))
    sat = np.zeros(tuple(n + 1), dtype=np.int64)
    sat[1:, 1:, 1:] = hist.cumsum(0).cumsum(1).cumsum(2)
    k = np.arange(-reach_cells, reach_cells + 1)
    grid = np.meshgrid(k, k, k, indexing="ij")
    inner = _window_sums(sat, [g + reach_cells + shell for g in grid], box)
    outer = _window_sums(sat, [g + reach_cells for g in grid], box + 2 * shell)
    score = ((1 + SHELL_WEIGHT) * inner - SHELL_WEIGHT * outer).astype(np.float64) - 1e-6 * sum(g**2 for g in grid)
    best = np.unravel_index(int(np.argmax(score)), score.shape)
    return centre + np.array([k[best[0]], k[best[1]], k[best[2]]], dtype=np.float64) * h


def _best_placement(inst: Instance, u: np.ndarray) -> np.ndarray:
    """The translation (local, longest-side units) of the best placement among the unclaimed centres ``u``
    (0 when none holds any centre): the suggestion for an empty or loose box."""
    half = _half(inst.box)
    coarse = _grid_search(u, half, np.zeros(3), _COARSE, _COARSE)
    t = _grid_search(u, half, coarse, _FINE, _FINE // _COARSE)
    return t if _counts(u, t, half)[0].any() else np.zeros(3)


def _one_box(
    inst: Instance, near_u: np.ndarray, free: Callable[[], np.ndarray], unclaimed: Callable[[], np.ndarray],
    object_local: Callable[[], tuple[np.ndarray, bool]],
) -> BoxFill:
    """Measures and verdict of one box from the free centres around it: ``near_u`` (box and shell, local
    coordinates), ``free()`` / ``unclaimed()`` (the free centres within the search reach / those no other box
    claims, fetched only when needed) and
    ``object_local()`` (its object's centres for the ends test, box frame in scene units, and whether
    they are labelled)."""
    half = _half(inst.box)
    inside0, shell0 = _counts(near_u, np.zeros(3), half)
    n_in, n_near = int(inside0.sum()), int(shell0.sum())
    fill = _fill(near_u[inside0], half)
    local, labelled = object_local()
    ends = estimate_shift(local, inst.box.extents, labelled=labelled)
    status = "empty" if n_in == 0 and n_near == 0 else "shifted" if ends.any else "loose" if n_in == 0 else "ok"
    t = ends.local / _scale(inst.box) if ends.any else np.zeros(3)
    if status in ("empty", "loose") and not ends.any:
        t = _best_placement(inst, unclaimed())
    if not np.any(t != 0):
        return BoxFill(inst.id, inst.label, n_in, fill, n_near, status)
    inside_t, shell_t = _counts(free(), t, half)  # counted as ``inside`` is
    best_in = int(inside_t.sum())
    if status == "shifted" and best_in >= max(MIN_GROWTH * n_in, 1):
        status = "outside"  # the box holds less than half of what it holds once moved
    shift = tuple(float(v) for v in inst.box.rotation @ (t * _scale(inst.box)))
    return BoxFill(inst.id, inst.label, n_in, fill, n_near, status, shift, best_in, int(shell_t.sum()))  # type: ignore[arg-type]


def measure_box_fill(
    means: np.ndarray, instances: Sequence[Instance], *, instance_ids: np.ndarray | None = None, metres_per_file_unit: float = 1.0,
) -> BoxFillReport:
    """Fill measures of every instance box against the Gaussian centres ``means`` (N, 3), same units as the boxes.

    A centre inside a smaller box belongs to that box's object (smallest box wins, as in
    :func:`~spacedg.scene.labelling.assign_by_boxes`): it is not counted for larger boxes, nor
    sought by their best fit. The ends test (:mod:`spacedg.scene.box_shift`) reads the object's
    centres: those carrying the box's id where ``instance_ids`` (N,) labels the Gaussians, else those
    no other box claims. Vectorised: the centres are sorted by x once; each box reads the centres
    within about one longest side of it. ``metres_per_file_unit``: the import's scale, for messages.
    See the module docstring for the measures and the verdict.
    """
    pts = np.asarray(means, dtype=np.float64).reshape(-1, 3)
    order = np.argsort(pts[:, 0], kind="stable")
    sorted_means = pts[order]
    sorted_ids = None if instance_ids is None else np.asarray(instance_ids).reshape(-1)[order]
    owned = np.zeros(len(pts), dtype=bool)
    boxes = _BoxIndex([i.box for i in instances])
    rows = {}
    reach = 1.0 + 1.0 / _COARSE + 2 * MARGIN_SHARE

    def free_local(box: OrientedBox, within: float) -> tuple[np.ndarray, np.ndarray]:
        idx = _candidates(sorted_means, box, within)
        idx = idx[~owned[idx]]
        return idx, _local(sorted_means[idx], box)

    def unclaimed_local(k: int, box: OrientedBox) -> np.ndarray:
        """The free centres within the search reach that no other box claims (the best placement is sought among them)."""
        idx = _candidates(sorted_means, box, reach)
        near = sorted_means[idx[~owned[idx]]]
        return _local(near[~foreign_points(near, box, boxes.overlapping(k, near))], box)

    def object_local(k: int, inst: Instance) -> tuple[np.ndarray, bool]:
        idx = _candidates(sorted_means, inst.box, 1.0)
        own = idx[sorted_ids[idx] == inst.id] if sorted_ids is not None else idx[:0]
        if len(own) > 0:
            return inst.box.to_local(sorted_means[own]), True
        near = sorted_means[idx]  # unlabelled (or none of its labelled centres near): the centres no other box claims
        return inst.box.to_local(near[~foreign_points(near, inst.box, boxes.overlapping(k, near))]), False

    for k, inst in sorted(enumerate(instances), key=lambda ki: (ki[1].box.volume, ki[1].id)):
        idx, near_u = free_local(inst.box, MARGIN_SHARE)
        rows[inst.id] = _one_box(inst, near_u, lambda box=inst.box: free_local(box, reach)[1], lambda k=k, box=inst.box: unclaimed_local(k, box),
                                 lambda k=k, inst=inst: object_local(k, inst))
        owned[idx[(np.abs(near_u) - _half(inst.box)).max(axis=1) <= 0.0]] = True
    return BoxFillReport(tuple(rows[k] for k in sorted(rows)), len(pts), metres_per_file_unit)


class _BoxIndex:
    """World axis-aligned bounds of a scene's boxes, to find those overlapping a set of points cheaply."""

    def __init__(self, boxes: Sequence[OrientedBox]) -> None:
        self.boxes = list(boxes)
        reach = np.array([np.abs(b.rotation) @ (b.extents / 2.0) for b in self.boxes]).reshape(-1, 3)
        centres = np.array([b.center for b in self.boxes]).reshape(-1, 3)
        self.lo, self.hi = centres - reach, centres + reach

    def overlapping(self, k: int, points: np.ndarray) -> list[OrientedBox]:
        """The boxes other than the ``k``-th whose bounds meet the bounds of ``points``."""
        if len(points) == 0:
            return []
        lo, hi = points.min(axis=0), points.max(axis=0)
        hit = np.flatnonzero(((self.lo <= hi) & (self.hi >= lo)).all(axis=1))
        return [self.boxes[j] for j in hit if j != k]
