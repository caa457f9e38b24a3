"""Do the Gaussians, the cameras and the boxes of a scene share one world frame?

Parts of a real capture come from different programs, each with its own frame (COLMAP's,
nerfstudio's ``transforms.json`` world = ``applied_transform · COLMAP``, splatfacto's normalised
frame, a scan's mesh frame, OpenGL vs OpenCV camera axes). Put together wrongly they render
black, and questions come out of black images. :func:`check_frame` measures, cheaply:

- ``gaussians_in_view``: share of (a sample of) the Gaussian centres inside at least one view's
  frustum (in front of the camera, inside the image);
- ``views_seeing``: share of views whose frustum holds at least 0.5 % of the sample;
- ``boxes_with_gaussians``: share of instance boxes (grown by 5 % of their size) holding at
  least one sampled Gaussian centre (``None`` without instances);
- ``render_coverage``: for a few views spread over the capture, the share of pixels with
  alpha > ½ in a small render.

Refused (``problems`` non-empty, :meth:`FrameReport.raise_if_bad` raises
:class:`FrameMismatchError`) when fewer than :data:`MIN_IN_VIEW` of the Gaussians are in any
view or fewer than :data:`MIN_VIEWS_SEEING` of the views see any ("Gaussians and cameras
disagree"), when the rendered views are all nearly empty
(< :data:`MIN_COVERAGE`), or when fewer than :data:`MIN_BOXES` of the boxes hold Gaussians
("boxes and Gaussians disagree"). :func:`diagnose` tries named corrections (the inverse of a
``dataparser_transforms.json``, nerfstudio's ``applied_transform``, OpenGL camera axes, a
y-up/z-up swap, ...) and names the one that passes as the probable cause.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace

import numpy as np

from spacedg.errors import InvalidDataError
from spacedg.render.renderer import render
from spacedg.scene.box import OrientedBox
from spacedg.scene.model import Scene

__all__ = [
    "FrameMismatchError", "FrameReport", "check_frame", "diagnose", "require_frame", "generic_corrections", "normalised_hint",
    "MIN_IN_VIEW", "BOX_PROBLEM", "PROBLEM_KINDS", "MIN_VIEWS_SEEING", "MIN_COVERAGE", "MIN_BOXES",
]

#: Fewest share of Gaussians inside some view's frustum.
MIN_IN_VIEW = 0.10
#: Fewest share of views that see Gaussians (every view of a capture looks at the scene).
MIN_VIEWS_SEEING = 0.5
#: Fewest mean share of covered pixels over the rendered check views.
MIN_COVERAGE = 0.02
#: Fewest share of boxes that hold Gaussians.
MIN_BOXES = 0.5
#: Start of the problem text about boxes.
BOX_PROBLEM = "the boxes and the Gaussians disagree"
#: The kinds of problem (:attr:`FrameReport.kinds`): Gaussians vs cameras, the check renders, the boxes.
PROBLEM_KINDS = ("cameras", "coverage", "boxes")
#: Gaussian centres sampled (evenly, deterministic) for the measures.
SAMPLE = 20_000
#: Views used for the frustum measures (evenly spread).
MAX_VIEWS = 48


class FrameMismatchError(InvalidDataError):
    """The parts of a scene are in different world frames (the message names which and why)."""


@dataclass(frozen=True)
class FrameReport:
    """Measures of :func:`check_frame` (module docstring) and the problems they show.

    ``kinds[i]`` is the kind (one of :data:`PROBLEM_KINDS`) of ``problems[i]`` (empty: all ``"cameras"``,
    for reports made by hand)."""

    gaussians_in_view: float
    views_seeing: float
    boxes_with_gaussians: float | None
    render_coverage: tuple[float, ...]
    problems: tuple[str, ...] = ()
    hints: tuple[str, ...] = field(default=())
    kinds: tuple[str, ...] = ()

    def problem_kinds(self) -> tuple[str, ...]:
        """The kind of each problem, in order."""
        return self.kinds if len(self.kinds) == len(self.problems) else ("cameras",) * len(self.problems)

    def without(self, kind: str) -> FrameReport:
        """This report less its problems of ``kind`` (the importer's box fill check names bad boxes itself)."""
        keep = [i for i, k in enumerate(self.problem_kinds()) if k != kind]
        return replace(self, problems=tuple(self.problems[i] for i in keep), kinds=tuple(self.problem_kinds()[i] for i in keep))

    @property
    def ok(self) -> bool:
        return not self.problems

    @property
    def mean_coverage(self) -> float:
        return float(np.mean(self.render_coverage)) if self.render_coverage else 0.0

    def summary(self) -> str:
        boxes = "-" if self.boxes_with_gaussians is None else f"{self.boxes_with_gaussians:.0%}"
        cover = ", ".join(f"{c:.0%}" for c in self.render_coverage) or "-"
        return (f"Gaussians in view {self.gaussians_in_view:.0%}, views seeing Gaussians {self.views_seeing:.0%}, "
                f"boxes holding Gaussians {boxes}, rendered coverage {cover}")

    def to_dict(self) -> dict[str, object]:
        return {"gaussians_in_view": round(self.gaussians_in_view, 4), "views_seeing": round(self.views_seeing, 4),
                "boxes_with_gaussians": None if self.boxes_with_gaussians is None else round(self.boxes_with_gaussians, 4),
                "render_coverage": [round(c, 4) for c in self.render_coverage], "ok": self.ok, "problems": list(self.problems)}

    def raise_if_bad(self, scene_id: str, where: str = "") -> None:
        """Raise :class:`FrameMismatchError` naming the disagreeing parts and the probable cause."""
        if self.ok:
            return
        cause = " ".join(self.hints) if self.hints else (
            "Check that the Gaussians, the cameras and the boxes come from the same reconstruction and frame "
            "(COLMAP vs nerfstudio transforms.json vs splatfacto's normalised frame; OpenGL vs OpenCV camera axes; units)"
        )
        raise FrameMismatchError(f"{where or 'scene ' + scene_id}: {'; '.join(self.problems)} ({self.summary()}). {cause}")


def _even(n: int, k: int) -> np.ndarray:
    """Up to ``k`` indices spread evenly over ``range(n)``: the rounded ``linspace``, sorted, repeats dropped
    (it is non-decreasing, so a neighbour comparison is ``np.unique`` without the sort)."""
    if not n or not k:
        return np.zeros(0, np.int64)
    picks = np.linspace(0, n - 1, num=min(n, k)).round().astype(np.int64)
    return picks[np.concatenate(([True], picks[1:] != picks[:-1]))]


def _holds_any(box: OrientedBox, points: np.ndarray, tol: float, every: int = 16) -> bool:
    """Whether ``box`` (grown by ``tol`` metres) holds any of ``points``: every ``every``-th point first (a
    subset, so a hit there is a hit), then all of them only when that finds none."""
    return bool(box.contains(points[::every], tol=tol).any()) or bool(box.contains(points, tol=tol).any())


def check_frame(
    scene: Scene, *, renders: int = 4, render_width: int = 64, backend: str = "auto", box_share: float | None = None
) -> FrameReport:
    """Measure whether ``scene``'s parts share a frame (see the module docstring); never raises on a mismatch.

    ``box_share``: the share of boxes holding Gaussians already measured (the importer passes
    :attr:`~spacedg.scene.box_fill.BoxFillReport.held_share`, so the summary and the fill table agree)."""
    gaussians = scene.gaussians
    names = list(scene.views)
    problems: list[str] = []
    if len(gaussians) == 0:
        return FrameReport(0.0, 0.0, None, (), ("the Gaussians file holds no Gaussians",))
    if not names:
        return FrameReport(0.0, 0.0, None, (), ("the scene has no views",))
    sample = gaussians.means[_even(len(gaussians), SAMPLE)].astype(np.float64)
    inside_any = np.zeros(len(sample), dtype=bool)
    seeing = 0
    chosen = [names[i] for i in _even(len(names), MAX_VIEWS)]
    for name in chosen:
        cam = scene.views[name]
        uv, z, valid = cam.project(sample)
        inside = valid & cam.in_image(uv) & (z > 1e-3)
        inside_any |= inside
        seeing += int(inside.mean() >= 0.005)
    in_view = float(inside_any.mean())
    views_seeing = seeing / len(chosen)
    boxes = None
    if scene.instances and box_share is not None:
        boxes = box_share
    elif scene.instances:
        big = gaussians.means[_even(len(gaussians), 10 * SAMPLE)].astype(np.float64)
        held = sum(_holds_any(inst.box, big, 0.05 * float(inst.box.extents.max()) + 1e-6) for inst in scene.instances)
        boxes = held / len(scene.instances)
    coverage: list[float] = []
    if renders > 0:

        for name in [names[i] for i in _even(len(names), renders)]:
            cam = scene.views[name]
            width = min(render_width, cam.width)
            small = cam.resized(width, max(1, round(cam.height * width / cam.width)))
            frame = render(gaussians, small, outputs="alpha", backend=backend)
            coverage.append(float((frame.alpha > 0.5).mean()))
    kinds: list[str] = []
    if in_view < MIN_IN_VIEW:
        problems.append(f"the Gaussians and the cameras disagree: only {in_view:.1%} of the Gaussians lie in any view")
        kinds.append("cameras")
    elif views_seeing < MIN_VIEWS_SEEING:
        problems.append(f"the Gaussians and the cameras disagree: only {views_seeing:.0%} of the views see any Gaussians")
        kinds.append("cameras")
    if coverage and max(coverage) < MIN_COVERAGE:
        problems.append(f"the cameras see (almost) nothing: the {len(coverage)} check renders cover at most {max(coverage):.1%} of their pixels")
        kinds.append("coverage")
    if boxes is not None and boxes < MIN_BOXES:
        problems.append(f"{BOX_PROBLEM}: only {boxes:.0%} of the {len(scene.instances)} boxes hold any Gaussian")
        kinds.append("boxes")
    return FrameReport(in_view, views_seeing, boxes, tuple(coverage), tuple(problems), kinds=tuple(kinds))


def diagnose(
    scene: Scene, report: FrameReport, corrections: Mapping[str, Callable[[Scene], Scene]], *, backend: str = "auto"
) -> FrameReport:
    """``report`` with hints: each named correction is applied to ``scene`` and checked; those that
    pass (best first) become the probable cause. Corrections that raise are skipped."""
    if report.ok:
        return report
    found: list[tuple[float, str]] = []
    for message, fix in corrections.items():
        try:
            trial = check_frame(fix(scene), renders=2, backend=backend)
        except Exception:  # noqa: BLE001 - a correction that cannot apply is simply not the cause
            continue
        if trial.ok:
            found.append((trial.gaussians_in_view + trial.mean_coverage, message))
    hints = tuple(f"Probable cause: {m}." for _, m in sorted(found, reverse=True)[:2])
    return replace(report, hints=hints or report.hints)


def generic_corrections(scene: Scene) -> dict[str, Callable[[Scene], Scene]]:
    """Corrections worth trying on any scene: OpenGL camera axes, y-up ↔ z-up Gaussians, RUB Gaussians."""
    flip = np.diag([1.0, -1.0, -1.0, 1.0])

    def gl_cameras(s: Scene) -> Scene:
        views = {n: c.with_pose(np.asarray(c.cam_to_world) @ flip) for n, c in s.views.items()}
        return Scene(s.id, s.gaussians, views, s.instances, s.up, s.vocabulary, s.metadata)

    def rotate_gaussians(rot: np.ndarray) -> Callable[[Scene], Scene]:
        def fix(s: Scene) -> Scene:
            return Scene(s.id, s.gaussians.transformed(rot), s.views, s.instances, s.up, s.vocabulary, s.metadata)
        return fix

    yz = np.array([[1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
    return {
        "the cameras use OpenGL axes (y up, z backwards) where OpenCV axes (y down, z forward) are expected; "
        "read them as nerfstudio transforms.json (which converts) or flip their y and z axes": gl_cameras,
        "the Gaussians are y-up where the cameras are z-up (or the reverse); export both from the same frame": rotate_gaussians(yz),
        "the Gaussians are z-up where the cameras are y-up; export both from the same frame": rotate_gaussians(yz.T),
        "the Gaussians are in RUB axes (an .spz or a viewer export) while the cameras are RDF (COLMAP)": rotate_gaussians(np.diag([1.0, -1.0, -1.0])),
    }


def normalised_hint(scene: Scene, *, layout: str | None = None, gaussians_given: bool = False) -> str | None:
    """A hint when the Gaussians look like splatfacto's normalised frame (all within a cube of side ~2
    while the cameras spread much wider), else ``None``.

    Only where a splatfacto export can be: a nerfstudio layout, a bare Gaussians file, or a
    Gaussians file given explicitly (``gaussians_given``); never for the Gaussians of an INRIA
    output, a COLMAP project or a ScanNet++ scene found by the layout (``layout`` ``None``: any)."""
    if layout in ("inria", "colmap", "scannetpp") and not gaussians_given:
        return None
    means = scene.gaussians.means.astype(np.float64)
    if len(means) == 0 or not scene.views:
        return None
    lo, hi = np.percentile(means, [2, 98], axis=0)
    centres = np.array([c.center for c in scene.views.values()])
    spread = float(np.linalg.norm(centres.max(axis=0) - centres.min(axis=0)))
    if float(np.abs(np.concatenate([lo, hi])).max()) <= 1.5 and spread > 2.0 * float(np.linalg.norm(hi - lo)):
        return ("Probable cause: the Gaussians are in nerfstudio's normalised frame (a splatfacto export: they fit in [-1, 1]³ "
                f"while the cameras span {spread:.2f} units): pass dataparser_transforms.json (--dataparser-transforms)")
    return None


def require_frame(scene: Scene, *, backend: str = "auto") -> FrameReport:
    """:func:`check_frame` + generic :func:`diagnose`; raises :class:`FrameMismatchError` on a mismatch."""
    report = check_frame(scene, backend=backend)
    if not report.ok:
        report = diagnose(scene, report, generic_corrections(scene), backend=backend)
        hint = normalised_hint(scene)
        if hint and not report.hints:
            report = replace(report, hints=(hint,))
        report.raise_if_bad(scene.id)
    return report
