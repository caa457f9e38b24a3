"""Small deterministic factories shared by the I/O tests."""

from __future__ import annotations

import numpy as np

from spacedg.render.gaussians import SH_COEFFS, Gaussians

FIELDS = ("means", "quats", "scales", "opacities", "sh")


def random_gaussians(
    n: int = 50,
    sh_degree: int = 0,
    *,
    seed: int = 0,
    instance_ids: bool = False,
    include_extremes: bool = False,
) -> Gaussians:
    """Random valid Gaussians (unit quats, scales 1e-4..10 m, opacities in [0, 1]).

    ``include_extremes`` puts opacity 0 and 1, scale 0 and tiny/huge values in the first rows.
    """
    rng = np.random.default_rng(seed)
    means = rng.normal(0.0, 3.0, (n, 3))
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    scales = np.exp(rng.uniform(np.log(1e-4), np.log(10.0), (n, 3)))
    opacities = rng.uniform(0.0, 1.0, n)
    sh = rng.normal(0.0, 0.5, (n, SH_COEFFS[sh_degree], 3))
    if include_extremes and n >= 6:
        opacities[:6] = [0.0, 1.0, 1e-30, 1.0 - 2.0**-24, 0.5, 1e-45]
        scales[0] = [0.0, 1e-30, 1e30]
        scales[1] = [1.0, np.float32(1e-38), 2.0**-149]
    ids = rng.integers(-1, 5, n).astype(np.int32) if instance_ids else None
    return Gaussians(means, quats.astype(np.float32), scales, opacities, sh, ids)


def assert_gaussians_identical(a: Gaussians, b: Gaussians, fields: tuple[str, ...] = FIELDS) -> None:
    """Bit-identical arrays (same dtype, shape and bytes) for ``fields`` and instance ids."""
    for name in fields:
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.shape == y.shape, name
        assert x.tobytes() == y.tobytes(), f"{name} differs at {np.flatnonzero(x.reshape(-1) != y.reshape(-1))[:5]}"
    if a.instance_ids is None:
        assert b.instance_ids is None
    else:
        assert b.instance_ids is not None
        assert a.instance_ids.tobytes() == b.instance_ids.tobytes()
