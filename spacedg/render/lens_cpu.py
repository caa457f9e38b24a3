"""The fisheye lens's inverse on the CPU, compiled: ray angles from image-circle radii (not a plugin).

:meth:`spacedg.render.camera.FisheyeLens.undistort_theta` solves ``θ_d(θ) = r`` by bisection. Done with
numpy, each of its 60 halvings is a handful of array operations, which on the few thousand radii a
view asks for (:func:`spacedg.render.coverage.captured_share`'s 64-px grid) cost ~5 ms a distortion
sample, more than the sample's lens change itself. This kernel runs the same bisection compiled: the
same float64 operations in the same order (no fast-math: no fused multiply-add), so the same bits.
"""

from __future__ import annotations

import numba
import numpy as np

from spacedg.render import kernel_cache  # noqa: F401 - numba's cache entries checked before any kernel here compiles
from spacedg.render.lens_polynomial import equidistant_theta_d

__all__ = ["undistort_theta"]

#: Halvings of :func:`undistort_theta` (float64 resolution of a bracket under 2 rad).
HALVINGS = 60

_theta_d = numba.njit(cache=True, inline="always")(equidistant_theta_d)


def undistort_theta(theta_d: np.ndarray, k1: float, k2: float, k3: float, k4: float, top: float) -> np.ndarray:
    """θ in ``[0, top]`` (radians, float64, ``theta_d``'s shape) with ``θ_d(θ) = theta_d`` for the lens
    polynomial ``k1 … k4`` (:func:`~spacedg.render.lens_polynomial.equidistant_theta_d`), by :data:`HALVINGS`
    halvings of ``[0, top]``: ``mid`` moves the lower end where ``θ_d(mid) < target``, else the upper;
    the result is the last bracket's middle (``top`` for a radius beyond ``θ_d(top)``, 0-ish for NaN);
    a numpy float64 scalar for a scalar ``theta_d``."""
    target = np.asarray(theta_d, dtype=np.float64)
    out = np.empty(target.shape, np.float64)
    _bisect(np.ascontiguousarray(target.reshape(-1)), float(k1), float(k2), float(k3), float(k4), float(top), out.reshape(-1))
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
            below = _theta_d(mid, k1, k2, k3, k4) < target[i]
            lo[i] = mid if below else lo[i]
            hi[i] = hi[i] if below else mid
    for i in range(n):
        out[i] = 0.5 * (lo[i] + hi[i])
