"""A spacedg plugin registering a degradation called ``vignetting``, like ``spacedg-vignetting``.

Installed together with ``spacedg-vignetting``, loading must fail with a
``DuplicatePluginError`` naming both distributions.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np

from spacedg.plugins import Category, DegradationSpec, ParamSpec, Stage, hookimpl


def apply(rgb: np.ndarray, aux: Mapping[str, np.ndarray], params: Mapping[str, Any], rng: np.random.Generator) -> np.ndarray:
    """Uniform gain ``1 - amount`` (not a real vignetting; it exists to clash)."""
    return (rgb * np.float32(1.0 - params["amount"])).astype(np.float32)


SPEC = DegradationSpec(
    name="vignetting",
    category=Category.PHOTOMETRIC,
    stage=Stage.LINEAR,
    params=(ParamSpec("amount", "1", "Darkening, 0 = none.", low=0.0, high=1.0, harsher="higher"),),
    presets={
        "bench": {"amount": (0.5, 0.6)},
        "1": {"amount": (0.1, 0.1)},
        "2": {"amount": (0.2, 0.2)},
        "3": {"amount": (0.3, 0.3)},
        "4": {"amount": (0.4, 0.4)},
        "5": {"amount": (0.5, 0.5)},
    },
    apply=apply,
    description="Uniform darkening (example clash).",
    order=25.0,
)


@hookimpl
def spacedg_register_degradations(register):
    register(SPEC)
