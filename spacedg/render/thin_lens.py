"""The thin-lens reference for defocus: the average of pinhole renders over the lens.

:class:`~spacedg.render.settings.Defocus` blurs a Gaussian at camera depth ``d`` by adding ``r²·I``
to its 2D covariance, ``r = aperture·|d − focus|/d`` px: a Gaussian point-spread function of
standard deviation ``r``. This module computes what a real thin lens with a **Gaussian aperture**
images, independently of that model (only sharp renders are used), so the model can be held to it.

Derivation (pixels ``u = fx·x/z + cx``; lens in the camera's x-y plane through the centre).
A lens point ``b = (b_x, b_y)`` metres off the axis sees the scene from a pinhole at ``b``. All rays
through the lens that meet on the focus plane ``z = focus`` land on one sensor point, so the
pinhole's image is registered on the focus plane: its principal point moves by ``fx·b_x/focus``.
A point at camera ``(x, z)`` then lands at::

    u(b) = fx·(x − b_x)/z + cx + fx·b_x/focus = u(0) + fx·b_x·(1/focus − 1/z)
         = u(0) + (fx·b_x/focus)·(z − focus)/z.

A point on the focus plane does not move (the focus plane stays put); any other point moves
linearly in ``b``. With ``b_x ~ N(0, s_x²)`` its image is a Gaussian of standard deviation
``fx·s_x·|z − focus|/(focus·z)`` px, which is the model's ``r = aperture·|z − focus|/z`` at **every**
depth iff ``s_x = aperture·focus/fx`` (and ``s_y = aperture·focus/fy``: an isotropic blur in
pixels). So the lens density is a 2D Gaussian with those standard deviations (metres), and the
thin-lens image is ``E_b[pinhole render at b]`` in linear light: each render composites the scene
with exact occlusion from its own viewpoint, which the per-Gaussian model can only approximate.

Not reproduced: the model's clamp ``r ≤ max_radius`` (default ``3·aperture``, reached by points
nearer than ``focus/4``); choose views without such points when comparing.

Sampling: ``samples`` lens points on a golden-angle spiral, radius ``sqrt(−2 ln(1 − u))`` at
``u = (i + ½)/N`` (a deterministic quadrature of the 2D normal: equal-mass rings, low
discrepancy), optionally rotated by a seeded angle. The error of the average falls as the sample
spacing on screen (``≈ 2.5·r/√N`` px) drops below the Gaussians' own size: ``benchmarks/defocus_reference.py``
reports the convergence (PSNR of N against 2N samples).
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from spacedg.errors import ParameterError
from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians
from spacedg.render.renderer import render
from spacedg.render.settings import Defocus

__all__ = ["lens_offsets", "lens_camera", "thin_lens_render"]

_GOLDEN_ANGLE = math.pi * (3.0 - math.sqrt(5.0))


def lens_offsets(samples: int, seed: int = 0) -> np.ndarray:
    """(samples, 2) points of the unit 2D normal distribution (mean 0, identity covariance): a
    golden-angle spiral with equal-mass radii, rotated by an angle drawn from ``seed`` (0: none)."""
    if isinstance(samples, bool) or not isinstance(samples, (int, np.integer)) or not 1 <= samples <= 100_000:
        raise ParameterError(f"thin-lens samples must be an integer in [1, 100000], got {samples!r}")
    i = np.arange(samples, dtype=np.float64)
    radius = np.sqrt(-2.0 * np.log1p(-(i + 0.5) / samples))
    turn = 0.0 if seed == 0 else float(np.random.default_rng(seed).uniform(0.0, 2.0 * math.pi))
    angle = i * _GOLDEN_ANGLE + turn
    return np.stack([radius * np.cos(angle), radius * np.sin(angle)], axis=1)


def lens_camera(camera: Camera, defocus: Defocus, offset: np.ndarray) -> Camera:
    """The pinhole at lens point ``offset`` (unit-normal units; metres = ``offset ×
    aperture·focus/(fx, fy)``), its principal point shifted so the focus plane stays put."""
    bx = float(offset[0]) * defocus.aperture * defocus.focus / camera.fx
    by = float(offset[1]) * defocus.aperture * defocus.focus / camera.fy
    pose = np.array(camera.cam_to_world, dtype=np.float64)
    pose[:3, 3] = pose[:3, 3] + camera.rotation @ np.array([bx, by, 0.0])
    return replace(camera, cam_to_world=pose, cx=camera.cx + camera.fx * bx / defocus.focus, cy=camera.cy + camera.fy * by / defocus.focus)


def thin_lens_render(
    gaussians: Gaussians, camera: Camera, defocus: Defocus, samples: int = 96, seed: int = 0, backend: str = "cpu",
) -> dict[str, np.ndarray]:
    """The thin-lens image of ``defocus``: ``{"rgb": (H, W, 3) linear light, "alpha": (H, W)}``
    float64, the mean of ``samples`` pinhole renders over a Gaussian lens (see the module docstring)."""
    if camera.is_fisheye:
        raise ParameterError("thin_lens_render takes a pinhole camera, got a fisheye one")
    rgb = np.zeros((camera.height, camera.width, 3))
    alpha = np.zeros((camera.height, camera.width))
    for offset in lens_offsets(samples, seed):
        frame = render(gaussians, lens_camera(camera, defocus, offset), outputs="rgb,alpha", backend=backend)
        rgb += frame.rgb
        alpha += frame.alpha
    return {"rgb": rgb / samples, "alpha": alpha / samples}
