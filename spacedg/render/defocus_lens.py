"""Which part of each Gaussian the lens sees: its visibility averaged over the aperture.

The defocus model (:mod:`spacedg.render.defocus`) gives every blurred Gaussian the light the
sharp view shows of it, ``κ = W / mass`` (``W``: visible alpha, ``mass``: integrated alpha). A lens
is not a pinhole: seen from a point ``b`` of the aperture, Gaussians hidden from the centre can
appear beside an occluder's edge (the far side of a sharp foreground edge shows the background
behind it) while an object's back stays hidden from the whole lens. The thin lens images
``E_b[pinhole render at b]`` (:mod:`spacedg.render.thin_lens`), so each Gaussian's share of light
is ``E_b[W(b) / mass(b)]``. It is estimated with a degree-3 cubature of the lens's 2D normal:
the centre with weight ⅓ (the sharp pass the model measures anyway) and four points at
``√3`` standard deviations along ±x, ±y with weight ⅙ each (exact for the lens's mean and
covariance). Each point is a sharp measurement pass of its own pinhole, principal point shifted
so the focus plane stays put (:func:`spacedg.render.thin_lens.lens_camera`), at the measurement
pass's resolution.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from spacedg.render.camera import Camera
from spacedg.render.settings import Defocus

__all__ = ["CENTRE_WEIGHT", "LENS_POINTS", "PRIOR", "REACH", "LENS_MIN_COC", "lens_points", "lens_camera", "lens_defocus", "visibility"]

#: Weight (in units of the Gaussian's mass) of the frame's mean visible share in a Gaussian's estimate:
#: a Gaussian with 5 % of its mass inside the measured frame gets half its own share, half the mean.
PRIOR = 0.05

#: Largest visible circle of confusion (px) below which the lens points are not measured (the centre's
#: visibility stands for the lens's): what the lens sees around an occluder is a strip at most about that wide.
LENS_MIN_COC = 2.0

#: Weight of the lens centre in the cubature (the sharp measurement pass).
CENTRE_WEIGHT = 1.0 / 3.0
_R = math.sqrt(3.0)
#: The other cubature points (unit-normal units) and their weights.
LENS_POINTS: tuple[tuple[tuple[float, float], float], ...] = tuple(
    (p, 1.0 / 6.0) for p in ((_R, 0.0), (-_R, 0.0), (0.0, _R), (0.0, -_R))
)


#: Farthest a cubature point may lie from the lens centre, as a fraction of the focus distance. A lens
#: wider than that (aperture > REACH·fx/√3 px: 72 px at fx = 500) is no thin lens in a room: its points
#: would look at the scene from outside it. Beyond, the visibility is estimated at this reach.
REACH = 0.25


def lens_points(largest_coc: float) -> tuple[float, tuple[tuple[tuple[float, float], float], ...]]:
    """``(centre weight, other points)`` of the cubature for a view whose largest visible circle of
    confusion is ``largest_coc`` px: the centre alone (weight 1) below :data:`LENS_MIN_COC`."""
    return (CENTRE_WEIGHT, LENS_POINTS) if largest_coc >= LENS_MIN_COC else (1.0, ())


def lens_defocus(defocus: Defocus, scale: float, fx: float) -> Defocus:
    """``defocus`` for a camera of focal length ``fx`` px imaging at ``scale`` of the view's resolution
    (aperture × scale, at most ``REACH·fx/√3``), so that :func:`spacedg.render.thin_lens.lens_camera`
    moves the pinhole by the view's lens offsets (at most ``REACH·focus`` metres)."""
    return replace(defocus, aperture=min(defocus.aperture * scale, REACH * fx / _R), max_radius=None)


def visibility(w: np.ndarray, mass: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """(N,) float64 share of each Gaussian's alpha one pinhole shows: ``(W + p·mass·κ̄) / (mass·(inside + p))``,
    the share of its part inside the measured frame, pulled towards the frame's mean ``κ̄`` by the
    prior ``p`` = :data:`PRIOR`; clipped to [0, 1].
    ``w``: visible alpha summed over the pass's pixels; ``mass``: integrated alpha
    (:func:`spacedg.render.defocus.alpha_mass`, 0 = culled); ``inside``: mass share inside the frame."""
    w = np.asarray(w, dtype=np.float64)
    mass = np.asarray(mass, dtype=np.float64)
    share = np.clip(np.asarray(inside, dtype=np.float64), 0.0, 1.0)
    expected = float((mass * share).sum())
    mean = min(float(w.sum()) / expected, 1.0) if expected > 0 else 1.0
    with np.errstate(divide="ignore", invalid="ignore"):
        kappa = np.where(mass > 0, (w + PRIOR * mass * mean) / np.where(mass > 0, mass * (share + PRIOR), 1.0), mean)
    return np.clip(np.nan_to_num(kappa, nan=mean), 0.0, 1.0)


def lens_camera(camera: Camera, defocus: Defocus, offset: np.ndarray) -> Camera:
    """The pinhole at lens point ``offset`` (unit-normal units; metres = ``offset ×
    aperture·focus/(fx, fy)``), its principal point shifted so the focus plane stays put."""
    bx = float(offset[0]) * defocus.aperture * defocus.focus / camera.fx
    by = float(offset[1]) * defocus.aperture * defocus.focus / camera.fy
    pose = np.array(camera.cam_to_world, dtype=np.float64)
    pose[:3, 3] = pose[:3, 3] + camera.rotation @ np.array([bx, by, 0.0])
    return replace(camera, cam_to_world=pose, cx=camera.cx + camera.fx * bx / defocus.focus, cy=camera.cy + camera.fy * by / defocus.focus)
