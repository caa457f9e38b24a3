"""The fisheye lens's inverse on the CPU, compiled: ray angles from image-circle radii (not a plugin).

:meth:`spacedg.render.camera.FisheyeLens.undistort_theta` solves ``θ_d(θ) = r`` by bisection. Done with
numpy, each of its 60 halvings is a handful of array operations, which on the few thousand radii a
view asks for (:func:`spacedg.render.coverage.captured_share`'s grid of 64 samples on the longer side) took
3.8 ms a view of the dataset's distortion items (cProfile, 640 × 480), a fifth of the lens change's own
cost; compiled, with each halving run over every radius before the next, 0.13 ms. The same float64
operations in the same order (no fast-math: no fused multiply-add), so the same bits.

The lens polynomial's compiled form (:data:`theta_d`, :data:`theta_d_slope`) is defined here once, for
this kernel and the CPU projection (:mod:`spacedg.render.project_cpu`).
"""

from __future__ import annotations

import numba
import numpy as np

from spacedg.render import kernel_cache  # numba's cache entries checked before any kernel here compiles
from spacedg.render.lens_polynomial import equidistant_theta_d, equidistant_theta_d_slope

__all__ = ["HALVINGS", "theta_d", "theta_d_slope", "undistort_theta"]

#: Halvings of :func:`undistort_theta` (float64 resolution of a bracket under 2 rad).
HALVINGS = 60

#: :func:`~spacedg.render.lens_polynomial.equidistant_theta_d` and its slope, compiled and inlined into
#: the kernels that call them.
theta_d = numba.njit(cache=True, inline="always")(equidistant_theta_d)
theta_d_slope = numba.njit(cache=True, inline="always")(equidistant_theta_d_slope)


def undistort_theta(theta_d: np.ndarray, k1: float, k2: float, k3: float, k4: float, top: float) -> np.ndarray:
    """θ in ``[0, top]`` (radians, float64, ``theta_d``'s shape) with ``θ_d(θ) = theta_d`` for the lens
    polynomial ``k1 … k4`` (:func:`~spacedg.render.lens_polynomial.equidistant_theta_d`), by :data:`HALVINGS`
    halvings of ``[0, top]``: ``mid`` moves the lower end where ``θ_d(mid) < target``, else the upper;
    the result is the last bracket's middle (``top`` for a radius beyond ``θ_d(top)``, 0-ish for NaN);
    a numpy float64 scalar for a scalar ``theta_d``."""
    target = np.asarray(theta_d, dtype=np.float64)
    out = np.empty(target.shape, np.float64)
    flat = kernel_cache.read_only(np.ascontiguousarray(target.reshape(-1)))  # read-only: one compiled signature
    _bisect(flat, float(k1), float(k2), float(k3), float(k4), float(top), out.reshape(-1))
    return out if out.ndim else out[()]  # a scalar in, a numpy scalar out (as numpy's arithmetic gives)


@numba.njit(cache=True, fastmath=False)
def _bisect(target, k1, k2, k3, k4, top, out):  # pragma: no cover - compiled
    """:func:`undistort_theta` over flat float64 arrays (in place into ``out``): each halving over every
    value before the next (the values are independent, so their polynomials overlap and vectorise; one value
    at a time waited on each halving's polynomial before the next)."""
    n = target.shape[0]
    lo = np.zeros(n, np.float64)
    hi = np.full(n, top, np.float64)
    for _ in range(HALVINGS):
        for i in range(n):
            mid = 0.5 * (lo[i] + hi[i])
            below = theta_d(mid, k1, k2, k3, k4) < target[i]
            lo[i] = mid if below else lo[i]
            hi[i] = hi[i] if below else mid
    for i in range(n):
        out[i] = 0.5 * (lo[i] + hi[i])
