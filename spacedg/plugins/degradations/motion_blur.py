"""Motion blur (optical-dynamic, raster stage): camera motion integrated over the exposure.

Model: the paper's "Motion Blur". The camera moves by ``trans`` metres along a direction and
turns by ``rot`` radians about an axis during the exposure; poses are interpolated (slerp of
the rotation, lerp of the centre) and ``sub_steps`` renders are averaged in linear light,
``I = 1/N Σ I_lin(T(t_i))`` (:class:`spacedg.render.MotionBlur`). The view's camera is the
**mid-exposure** pose, so every answer computed from the scene's camera stays exact.

Decisions the paper leaves open:

- Directions: the translation direction and the rotation axis are drawn independently and
  uniformly on the unit sphere, in the camera frame (x right, y down, z forward), from
  ``rng`` — two ``standard_normal(3)`` draws, normalised. So the same parameters give a
  different shake per view of a sample, as two exposures would.
- ``sub_steps`` is the reference count (the paper's N = 80). The pipeline renders with the
  renderer's fast path: 1–8 keyframes chosen from the on-screen path and the warp's predicted error
  (contrast × parallax across depth edges, :mod:`spacedg.render.motion_error`), each pixel's path
  integrated through them (no stroboscopic copies; PSNR against N = 80 and N = 256 per scene
  and severity in ``benchmarks/render.py --only severity``); it records the renders made.
- ``trans = rot = 0`` is the static render, bit for bit.

Parameters: ``trans`` (m, total path length, [0, 10]), ``rot`` (rad, total angle, [0, π]),
``sub_steps`` (integer, [1, 4096]). Presets: ``bench`` = the paper's table, trans ∈ [0.2, 0.35]
m, rot ∈ [0.06, 0.12] rad, sub_steps = 80; severities ``1``–``5``: trans [0.02, 0.04], [0.05,
0.08], [0.09, 0.14], [0.15, 0.22], [0.2, 0.35] m and rot [0.005, 0.01], [0.01, 0.02], [0.02,
0.04], [0.04, 0.07], [0.06, 0.12] rad, sub_steps = 80.

**Scale-aware** (decision): the ``trans`` ranges are stated for a scene of median depth
:data:`~spacedg.plugins.specs.REFERENCE_DEPTH_M` (2.5 m, a ScanNet++ room) and scale with the
sample's scene depth (``ParamRange(per_depth=True)``): a 0.3 m shake at 2.5 m moves the image as
much as a 6 cm shake at 0.5 m. ``rot`` (radians) moves the image the same at any depth and
is not scaled. The provenance records the resolved metres.
"""

from __future__ import annotations

import math
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
from spacedg.render.request import RenderRequest
from spacedg.render.settings import MotionBlur

__all__ = ["SPEC", "motion_blur", "random_unit_vector"]


def random_unit_vector(rng: np.random.Generator) -> np.ndarray:
    """A direction uniform on the unit sphere (one ``standard_normal(3)`` draw)."""
    v = rng.standard_normal(3)
    norm = float(np.linalg.norm(v))
    return v / norm if norm > 1e-12 else np.array([1.0, 0.0, 0.0])


def motion_blur(request: RenderRequest, trans: float, rot: float, sub_steps: int, rng: np.random.Generator) -> RenderRequest:
    """``request`` with camera motion: ``trans`` m along, and ``rot`` rad about, random camera-frame directions."""
    direction = random_unit_vector(rng)
    axis = random_unit_vector(rng)
    motion = MotionBlur(translation=tuple(trans * direction), rotation=tuple(rot * axis), sub_steps=int(sub_steps))
    return replace(request, motion=motion)


def apply(request: RenderRequest, params: Mapping[str, Any], rng: np.random.Generator) -> RenderRequest:
    """Raster-stage ``apply``: ``params = {"trans": m, "rot": rad, "sub_steps": int}``."""
    p = SPEC.validate_params(params)
    return motion_blur(request, p["trans"], p["rot"], p["sub_steps"], rng)


def _preset(trans: tuple[float, float], rot: tuple[float, float]) -> dict[str, ParamRange]:
    return {"trans": ParamRange(*trans, per_depth=True), "rot": ParamRange(*rot), "sub_steps": ParamRange(80, 80)}


SPEC = DegradationSpec(
    name="motion_blur", category=Category.OPTICAL_DYNAMIC, stage=Stage.RASTER,
    params=(
        ParamSpec("trans", "m", "Camera path length over the exposure (direction random per view).", low=0.0, high=10.0, harsher="higher"),
        ParamSpec("rot", "rad", "Camera rotation angle over the exposure (axis random per view).", low=0.0, high=math.pi, harsher="higher"),
        ParamSpec("sub_steps", "1", "Reference number of sub-exposure renders averaged in linear light.", low=1, high=4096, integer=True),
    ),
    presets={
        "bench": _preset((0.2, 0.35), (0.06, 0.12)),
        "1": _preset((0.02, 0.04), (0.005, 0.01)),
        "2": _preset((0.05, 0.08), (0.01, 0.02)),
        "3": _preset((0.09, 0.14), (0.02, 0.04)),
        "4": _preset((0.15, 0.22), (0.04, 0.07)),
        "5": _preset((0.2, 0.35), (0.06, 0.12)),
    },
    apply=apply,
    description="Camera shake over the exposure: slerp/lerp poses, sub-step renders averaged in linear light; mid-exposure pose = ground truth.",
    order=30.0,
)

spacedg_register_degradations = registering(SPEC)
