"""Top-down pictures of scenes: the floor plan a user checks before anything is rendered.

:func:`floorplan` draws one scene seen from above (along ``-Scene.up``): the Gaussians below
the ceiling, coloured, higher ones over lower ones; each instance's box outline with its id
and label; and the camera path with a tick in each view's heading. :func:`contact_sheet`
tiles several of them into one PNG-ready image.
"""

from __future__ import annotations

from collections.abc import Sequence

import cv2
import numpy as np

from spacedg.scene.model import Scene


def plane_basis(up: np.ndarray) -> np.ndarray:
    """(2, 3) orthonormal axes spanning the plane perpendicular to ``up`` (right-handed with up)."""
    up = np.asarray(up, dtype=np.float64)
    helper = np.eye(3)[int(np.argmin(np.abs(up)))]
    e1 = np.cross(helper, up)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(up, e1)
    return np.stack([e1, e2])


def floorplan(scene: Scene, pixels_per_metre: float = 70.0, max_points: int = 400_000) -> np.ndarray:
    """(H, W, 3) uint8 RGB top view of ``scene`` (see module docstring)."""
    g = scene.gaussians
    basis = plane_basis(scene.up)
    heights = g.means.astype(np.float64) @ scene.up
    keep = heights < heights.max() - 0.08  # drop the ceiling
    if keep.sum() > max_points:
        keep &= np.random.default_rng(0).uniform(size=len(keep)) < max_points / keep.sum()
    pts = g.means[keep].astype(np.float64) @ basis.T
    order = np.argsort(heights[keep], kind="stable")
    pts, colors = pts[order], np.clip(g.base_colors()[keep][order], 0, 1)
    cams = np.array([c.center for c in scene.views.values()]) @ basis.T if scene.views else np.zeros((0, 2))
    allpts = np.concatenate([pts, cams]) if len(cams) else pts
    lo, hi = allpts.min(0) - 0.3, allpts.max(0) + 0.3
    size = np.ceil((hi - lo) * pixels_per_metre).astype(int)
    width, height = int(size[0]), int(size[1])
    header = 28
    image = np.full((height + header, width, 3), 255, dtype=np.uint8)

    def to_px(xy: np.ndarray) -> np.ndarray:
        px = (xy - lo) * pixels_per_metre
        return np.stack([px[:, 0], height - px[:, 1] + header], axis=1)

    # each Gaussian as a square about two standard deviations wide (1–7 px)
    radius = np.clip(np.round(g.scales[keep][order].max(axis=1) * pixels_per_metre), 0, 3).astype(int)
    p = np.round(to_px(pts)).astype(int)
    rgb = (colors * 255).astype(np.uint8)
    for r in range(int(radius.max(initial=0)), -1, -1):  # outer rings first, centres win
        sel = radius >= r
        for dx in range(-r, r + 1):
            for dy in (-r, r) if r else (0,):
                for ox, oy in ((dx, dy), (dy, dx)):
                    q = p[sel] + (ox, oy)
                    ok = (q[:, 0] >= 0) & (q[:, 0] < width) & (q[:, 1] >= header) & (q[:, 1] < height + header)
                    image[q[ok, 1], q[ok, 0]] = rgb[sel][ok]
    for inst in scene.instances:
        hull = cv2.convexHull(np.round(to_px(inst.box.corners() @ basis.T)).astype(np.int32))
        cv2.polylines(image, [hull], True, (220, 30, 30), 1, cv2.LINE_AA)
        c = to_px((inst.box.center @ basis.T)[None])[0]
        cv2.putText(image, f"{inst.id}:{inst.label}", (int(c[0]) - 20, int(c[1])), cv2.FONT_HERSHEY_SIMPLEX, 0.33, (150, 0, 0), 1, cv2.LINE_AA)
    if len(cams):
        cp = to_px(cams)
        cv2.polylines(image, [np.round(cp).astype(np.int32)], False, (30, 90, 220), 1, cv2.LINE_AA)
        for cam, xy in zip(scene.views.values(), cp):
            f = cam.forward @ basis.T
            n = np.linalg.norm(f)
            if n > 1e-6:
                tip = xy + np.array([f[0], -f[1]]) / n * 0.25 * pixels_per_metre
                cv2.line(image, tuple(np.round(xy).astype(int)), tuple(np.round(tip).astype(int)), (30, 90, 220), 1, cv2.LINE_AA)
    title = f"{scene.id}: {len(g):,} Gaussians, {len(scene.instances)} instances, {len(scene.views)} views"
    cv2.putText(image, title, (6, 19), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    return image


def contact_sheet(images: Sequence[np.ndarray], columns: int = 2, pad: int = 8) -> np.ndarray:
    """Tile RGB images into a grid on a white background (rows as tall as their tallest image)."""
    if not images:
        raise ValueError("contact_sheet needs at least one image")
    rows = [images[i : i + columns] for i in range(0, len(images), columns)]
    col_w = max(im.shape[1] for im in images)
    out_rows = []
    for row in rows:
        h = max(im.shape[0] for im in row)
        canvas = np.full((h + pad, columns * (col_w + pad) + pad, 3), 255, dtype=np.uint8)
        for k, im in enumerate(row):
            x = pad + k * (col_w + pad)
            canvas[: im.shape[0], x : x + im.shape[1]] = im
        out_rows.append(canvas)
    return np.concatenate(out_rows, axis=0)
