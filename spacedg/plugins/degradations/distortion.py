"""Distortion (optical-dynamic, raster stage): an equidistant fisheye lens inside the rasterizer.

Model: the paper's "Distortion". The view is rendered through the OpenCV equidistant fisheye
model ``θ_d = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)``, pixel ``= (fx θ_d x/r + cx, fy θ_d y/r +
cy)``, rays clamped at ``max_theta``; each Gaussian's covariance is projected with the exact
Jacobian of this map (:class:`spacedg.render.FisheyeLens`). Past the fold of a strong barrel
polynomial (the bench k1 = −0.24 folds at θ ≈ 1.18 rad) two rays would share a pixel, so the
renderer treats ``min(max_theta, fold)`` as the edge of the image circle; pixels outside it are
marked invalid and stay black.

Decisions the paper leaves open:

- **Field of view: the camera's own.** The paper modifies the projection, not the focal length:
  the lens replaces the pinhole on the view's own ``fx, fy, cx, cy`` and pose. Near the image
  centre ``θ_d ≈ θ ≈ tan θ``, so apparent sizes there are unchanged (a subject spanning ±0.1 rad
  keeps its size within 0.6 % at the bench k1; tested within 2 %); towards the border the barrel
  lens compresses the view and content the clean view did not show enters the frame. The share
  of the distorted frame that the clean view covers — the part the capture is known to hold —
  is :func:`spacedg.render.coverage.captured_share`; the degradation pipeline records it per
  chain (``DegradedViews.captured_share``, the smallest over the views): 0.64 for the
  bench lens on a 70° 4:3 view, 0.82 on a 50° 16:9 one (the corners gain the most). Rays the lens does not image (beyond ``max_theta`` or the fold)
  are invalid pixels (black).
- **The contained variant** (before issue 29 the only one), :func:`distort_contained`: the
  focal lengths scaled by the smallest factor ``s`` (:func:`containing_zoom`) for which every
  ray the distorted image shows is inside the clean view's frame, ``s = max_R R / θ_d(θ_src(R))``
  over the normalised distances ``R`` from the principal point to the frame boundary (for a
  pinhole view ``θ_src = atan R``; the maximum is at the corner). Nothing uncaptured enters, but
  the subject grows by ``s`` (≈ 1.2–1.4 with the bench lens): every apparent size changes. An
  API function for users who need it, not a registered degradation.
- **No identity value.** ``k1 = … = k4 = 0`` is the ideal f-θ lens, which already differs from
  a pinhole (θ instead of tan θ); the two agree as the field of view goes to 0 (tested).
- A view that already has a fisheye lens gets its lens replaced (the contained variant takes
  ``θ_src`` from the view's own lens).
- Deterministic: ``rng`` is not used.

Parameters (dimensionless coefficients for θ in radians): ``k1``–``k4`` in [−1, 1],
``max_theta`` (rad) in [0.05, 3.1]. Presets: ``bench`` = the paper's table (k1 ∈ [−0.24, −0.23],
k2 ∈ [1e-4, 3e-4], k3 ∈ [1e-4, 2e-4], k4 ∈ [0, 1e-4], max_theta = 1.5); severities ``1``–``5``:
k1 ∈ [−0.06, −0.04], [−0.10, −0.08], [−0.15, −0.13], [−0.20, −0.18], [−0.24, −0.23] with the
bench k2–k4 and max_theta.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any

import numpy as np

from spacedg.plugins.hookspecs import registering
from spacedg.plugins.specs import (
    Category,
    DegradationSpec,
    ParamRange,
    ParamSpec,
    Stage,
)
from spacedg.render.camera import Camera, FisheyeLens
from spacedg.render.request import RenderRequest

__all__ = ["SPEC", "containing_zoom", "distort", "distort_contained"]

_BOUNDARY_SAMPLES = 257


def _source_theta(camera: Camera, radius: np.ndarray) -> np.ndarray:
    """Ray angle (rad) of the clean camera at normalised image-plane distance ``radius``."""
    if camera.fisheye is None:
        return np.arctan(radius)
    return camera.fisheye.undistort_theta(radius)


def containing_zoom(camera: Camera, lens: FisheyeLens) -> float:
    """Focal-length factor ``s`` so that ``lens`` at ``s · (fx, fy)`` sees only rays ``camera`` sees.

    See the module docstring. ``radius`` runs over the normalised distances from the principal
    point to the frame boundary (nearest edge … farthest corner).
    """
    xs = np.array([-camera.cx / camera.fx, (camera.width - camera.cx) / camera.fx])
    ys = np.array([-camera.cy / camera.fy, (camera.height - camera.cy) / camera.fy])
    r_near = float(min(np.abs(xs).min(), np.abs(ys).min()))
    r_far = float(np.sqrt(np.max(xs**2) + np.max(ys**2)))
    radius = np.linspace(r_near, r_far, _BOUNDARY_SAMPLES)
    theta = _source_theta(camera, radius)
    edge = lens.effective_max_theta
    reachable = (theta <= edge) & (radius > 0.0)  # R = 0 (principal point on the frame's edge) bounds nothing
    if not reachable.any():  # even the nearest edge is beyond the fold: the image circle touches it
        return r_near / float(lens.distort_theta(np.float64(edge)))
    return float(np.max(radius[reachable] / lens.distort_theta(theta[reachable])))


def distort(request: RenderRequest, k1: float, k2: float, k3: float, k4: float, max_theta: float) -> RenderRequest:
    """``request`` rendered through the equidistant fisheye ``k1..k4, max_theta`` on the camera's own
    focal lengths, principal point and pose (the paper's model; see the module docstring)."""
    lens = FisheyeLens(k1=k1, k2=k2, k3=k3, k4=k4, max_theta=max_theta)
    return replace(request, camera=replace(request.camera, fisheye=lens))


def distort_contained(request: RenderRequest, k1: float, k2: float, k3: float, k4: float, max_theta: float) -> RenderRequest:
    """:func:`distort` with the focal lengths scaled by :func:`containing_zoom`, so that the view shows
    only rays the clean view shows (magnifies the subject; see the module docstring)."""
    camera = request.camera
    lens = FisheyeLens(k1=k1, k2=k2, k3=k3, k4=k4, max_theta=max_theta)
    zoom = containing_zoom(camera, lens)
    return replace(request, camera=replace(camera, fx=camera.fx * zoom, fy=camera.fy * zoom, fisheye=lens))


def apply(request: RenderRequest, params: Mapping[str, Any], rng: np.random.Generator) -> RenderRequest:
    """Raster-stage ``apply``: ``params = {"k1", "k2", "k3", "k4", "max_theta"}``; ``rng`` unused."""
    p = SPEC.validate_params(params)
    return distort(request, p["k1"], p["k2"], p["k3"], p["k4"], p["max_theta"])


def _preset(k1: tuple[float, float]) -> dict[str, ParamRange]:
    return {
        "k1": ParamRange(*k1),
        "k2": ParamRange(1e-4, 3e-4),
        "k3": ParamRange(1e-4, 2e-4),
        "k4": ParamRange(0.0, 1e-4),
        "max_theta": ParamRange(1.5, 1.5),
    }


def _coefficient(name: str, power: int, harsher: str | None) -> ParamSpec:
    return ParamSpec(name, "1", f"Coefficient of θ^{power} in θ_d / θ (θ in radians).", low=-1.0, high=1.0, harsher=harsher)  # type: ignore[arg-type]


SPEC = DegradationSpec(
    name="distortion", category=Category.OPTICAL_DYNAMIC, stage=Stage.RASTER,
    params=(
        _coefficient("k1", 2, "lower"),
        _coefficient("k2", 4, None),
        _coefficient("k3", 6, None),
        _coefficient("k4", 8, None),
        ParamSpec("max_theta", "rad", "Largest ray angle the lens images.", low=0.05, high=3.1),
    ),
    presets={
        "bench": _preset((-0.24, -0.23)),
        "1": _preset((-0.06, -0.04)),
        "2": _preset((-0.10, -0.08)),
        "3": _preset((-0.15, -0.13)),
        "4": _preset((-0.20, -0.18)),
        "5": _preset((-0.24, -0.23)),
    },
    apply=apply,
    description="Equidistant fisheye lens θ_d = θ(1 + k1θ² + k2θ⁴ + k3θ⁶ + k4θ⁸) in the rasterizer (exact Jacobian) on the camera's own focal lengths: sizes at the centre kept, new content at the border.",
    order=10.0,
)

spacedg_register_degradations = registering(SPEC)
