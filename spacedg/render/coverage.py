"""How much of a lensed view the capture covers (:func:`captured_share`), and blurred renders that
lost their coverage (:func:`coverage_problem`).

A raster-stage lens change (the ``distortion`` degradation) renders the scene through another
lens at the same pose: a fisheye on the camera's own focal lengths shows more than the captured
view near its border, where a reconstruction holds only what other views saw (or nothing).
:func:`captured_share` measures the share of the lensed image (inside its image circle) whose
rays the original camera's frame contains, i.e. the part of the new frame that the capture
covers.

A blurred render (defocus, motion blur) spreads each point's light; when the blur is large
against the frame (a 200-px circle of confusion on a 64×48 image, or a fisheye whose image
circle is a few pixels wide: a fisheye images no ray beyond its max θ, in focus or not, so no
blurred light enters its circle from outside) the light leaves the frame and the image goes
black. :func:`coverage_problem` names that cause; the degradation pipeline and ``spacedg
render`` raise :class:`CoverageLostError` with it instead of writing a black image.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from spacedg.errors import ParameterError
from spacedg.render.camera import Camera

if TYPE_CHECKING:
    from spacedg.render.gaussians import Gaussians
    from spacedg.render.settings import Defocus, MotionBlur, RasterSettings

__all__ = ["MIN_COVERED", "CoverageLostError", "captured_share", "coverage_problem", "covered_share", "pixel_rays"]

#: Longest side of the pixel grid :func:`captured_share` samples (pixel centres, evenly spread): 64 resolves
#: the share to ~1 % (chosen when the fisheye inverse on every sample was numpy's and 35 % of a 640×480
#: distortion sample at 160; compiled, :mod:`spacedg.render.lens_cpu`, it is 0.13 ms at 64).
SHARE_GRID = 64


def pixel_rays(camera: Camera, cols: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit camera-frame rays (N, 3) through pixel centres ``(col + 0.5, row + 0.5)`` and whether
    the lens images them (pinhole: always; fisheye: inside the image circle of its effective max θ).

    OpenCV axes. A fisheye ray at angle θ from the axis is ``(sin θ · x̂, sin θ · ŷ, cos θ)``
    (θ from :meth:`~spacedg.render.camera.FisheyeLens.undistort_theta`), so rays beyond 90° are
    represented too."""
    x = (np.asarray(cols, np.float64) + 0.5 - camera.cx) / camera.fx
    y = (np.asarray(rows, np.float64) + 0.5 - camera.cy) / camera.fy
    lens = camera.fisheye
    if lens is None:
        rays = np.stack([x, y, np.ones_like(x)], axis=1)
        return rays / np.linalg.norm(rays, axis=1, keepdims=True), np.ones(x.shape, bool)
    radius = np.hypot(x, y)
    valid = radius <= float(lens.distort_theta(np.float64(lens.effective_max_theta)))
    theta = lens.undistort_theta(radius)
    scale = np.where(radius > 1e-12, np.sin(theta) / np.where(radius > 1e-12, radius, 1.0), 0.0)
    return np.stack([x * scale, y * scale, np.cos(theta)], axis=1), valid


def captured_share(clean: Camera, lensed: Camera) -> float:
    """Share (in [0, 1]) of ``lensed``'s valid pixels whose ray falls inside ``clean``'s image.

    Both cameras are taken at the same pose (``lensed``'s rays are expressed in ``clean``'s
    frame through their rotations). Sampled on a grid of at most :data:`SHARE_GRID` pixel
    centres on the longer side; 1.0 when ``lensed`` images no pixel at all (nothing uncaptured)."""
    step = max(1, -(-max(lensed.width, lensed.height) // SHARE_GRID))
    rows, cols = np.meshgrid(np.arange(0, lensed.height, step), np.arange(0, lensed.width, step), indexing="ij")
    rays, valid = pixel_rays(lensed, cols.ravel(), rows.ravel())
    if not valid.any():
        return 1.0
    world = lensed.center + rays[valid] @ lensed.rotation.T
    uv, _, in_front = clean.project(world)
    return float(np.mean(in_front & clean.in_image(uv)))


# ------------------------------------------------------------------ renders that lost their coverage
#: Mean alpha over the pixels a lens images below which a render shows (almost) nothing.
MIN_COVERED = 0.02


class CoverageLostError(ParameterError):
    """A blurred render (defocus, motion) lost the coverage its sharp render has: its message
    names the blur and the frame that together caused it (never a black image written silently)."""


def covered_share(alpha: np.ndarray, valid: np.ndarray | None) -> float:
    """Mean alpha over the pixels the lens images (``valid``; all for a pinhole); 0 when there are none."""
    if valid is None:
        return float(np.mean(alpha, dtype=np.float64)) if alpha.size else 0.0
    return float(np.mean(alpha[valid], dtype=np.float64)) if valid.any() else 0.0


def _blur_causes(camera: Camera, defocus: Defocus | None, motion: MotionBlur | None) -> str:
    frame = f"{camera.width}×{camera.height}-px image"
    if camera.fisheye is not None:
        lens = camera.fisheye
        radius = float(lens.distort_theta(np.float64(lens.effective_max_theta))) * min(camera.fx, camera.fy)
        frame += f" whose fisheye image circle (max θ {lens.effective_max_theta:.3g} rad) is {radius:.3g} px in radius"
    causes = []
    if defocus is not None and defocus.aperture > 0:
        causes.append(f"defocus aperture {defocus.aperture:g} px spreads each point over a circle of confusion of up to "
                      f"{defocus.max_radius:g} px")
    if motion is not None and not motion.is_static:
        causes.append(f"motion blur (translation {tuple(round(v, 4) for v in motion.translation)} m, rotation "
                      f"{tuple(round(v, 4) for v in motion.rotation)} rad) sweeps the view")
    return f"{' and '.join(causes)} on a {frame}: the light leaves the frame and too little enters it"


def coverage_problem(
    gaussians: Gaussians, camera: Camera, alpha: np.ndarray, valid: np.ndarray | None, *,
    defocus: Defocus | None = None, motion: MotionBlur | None = None, backend: str = "auto",
    device: Any = None, settings: RasterSettings | None = None,
) -> str | None:
    """Why a blurred render of ``camera`` (its ``alpha`` and lens ``valid`` mask) shows (almost) nothing
    though the sharp render of the same camera and lens does, or ``None`` when it does not.

    Free unless the blurred render covers less than :data:`MIN_COVERED` of the pixels the lens
    images: then one sharp alpha render decides (a view that sees nothing sharp is not this
    check's business). A lens that images no pixel at all is always a problem."""
    if valid is not None and not valid.any():
        lens = camera.fisheye
        assert lens is not None
        return (f"the fisheye lens images none of the {camera.width}×{camera.height} pixels (max θ {lens.effective_max_theta:.3g} rad "
                f"at focal lengths {camera.fx:.4g}, {camera.fy:.4g} px): raise max_theta or render larger")
    blurred = (defocus is not None and defocus.aperture > 0) or (motion is not None and not motion.is_static)
    if not blurred:
        return None
    covered = covered_share(alpha, valid)
    if covered >= MIN_COVERED:
        return None
    from spacedg.render.renderer import render

    sharp = covered_share(render(gaussians, camera, outputs="alpha", backend=backend, device=device, settings=settings).alpha, valid)
    if sharp < MIN_COVERED:
        return None
    return (f"the blurred render lost its coverage: {covered:.2%} of the imaged pixels covered against {sharp:.1%} in the sharp "
            f"render of the same camera and lens, because {_blur_causes(camera, defocus, motion)}; lower the blur or render larger")
