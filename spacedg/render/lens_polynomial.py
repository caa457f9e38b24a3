"""The equidistant fisheye lens polynomial, one definition for every backend (numpy, torch, numba).

Kept apart from :mod:`spacedg.render.camera` so that the compiled lens kernels (:mod:`spacedg.render.lens_cpu`,
which compiles it once for the projection and the inverse) use it without importing the camera module that calls them.
"""

from __future__ import annotations

from typing import Any

__all__ = ["equidistant_theta_d", "equidistant_theta_d_slope"]


def equidistant_theta_d(theta: Any, k1: float, k2: float, k3: float, k4: float) -> Any:
    """``θ_d(θ) = θ (1 + k1 θ² + k2 θ⁴ + k3 θ⁶ + k4 θ⁸)``: the fisheye lens polynomial, once, for
    floats, numpy arrays and torch tensors alike (:class:`~spacedg.render.camera.FisheyeLens`, the torch projection) and
    compiled by numba once (:mod:`spacedg.render.lens_cpu`) for the CPU projection and the fisheye inverse."""
    t2 = theta * theta
    return theta * (1.0 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4))))


def equidistant_theta_d_slope(theta: Any, k1: float, k2: float, k3: float, k4: float) -> Any:
    """``dθ_d/dθ = 1 + 3 k1 θ² + 5 k2 θ⁴ + 7 k3 θ⁶ + 9 k4 θ⁸`` (as :func:`equidistant_theta_d`)."""
    t2 = theta * theta
    return 1.0 + t2 * (3.0 * k1 + t2 * (5.0 * k2 + t2 * (7.0 * k3 + t2 * 9.0 * k4)))
