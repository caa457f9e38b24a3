"""How many keyframes a motion-blurred view needs: the keyframe warp's error, predicted from a coarse render.

The keyframe warp (:mod:`spacedg.render.motion_warp`) takes what a pixel sees during an interval
from the keyframe at that pixel. Where neighbouring pixels move alike (a rotation, a smooth
surface) that is nearly exact; its error lives at depth edges, in a band as wide as the
interval's parallax difference across the edge, and it is as large as the colour contrast across
that edge. So the count follows from the view's content, not from its path length alone (the
previous rule, ``⌈√(P/3.5)⌉`` keyframes for a near-far parallax of P pixels, was fitted on a plant
close-up, the densest depth edges measured, and gave the built-in rooms 4–5 keyframes where 2
already met the 40 dB goal).

Feature (:func:`edge_parallax_contrast`): a render of the mid-exposure pose at a quarter of the
resolution, on the job's backend (on a GPU it costs a device render; the backends' renders agree
to float rounding, so they pick the same count unless ``S`` falls within rounding of a threshold),
without defocus (sharper edges, more keyframes). For each pair of neighbouring coarse pixels,
``c²`` is the mean over channels of the squared difference of their sRGB-encoded colour (linear colour
clipped to [0, 1], the encoding the PSNR is measured on) and ``Δ`` the larger, over the exposure's
two ends, of how far apart that end's camera sees the first pixel's ray at its own depth and at
its neighbour's (the alpha-weighted mean depth where nothing covers a pixel, as the warp does, or
where its depth is not finite), in
the view's pixels (0 where either point is behind that camera, as the warp has no path there;
at most twice the view's width plus height, about the warp's longest walk): the parallax across
the edge. A turn gives none (it moves every depth alike; the warp is exact there), a smooth
surface little, a depth edge half the exposure's parallax (``K/2`` intervals' worth).
``S = mean(c² · Δ)`` over horizontal and vertical pairs: with the coarse grid a fixed fraction of the view, ``S`` is proportional to the share of the image that
lies in error bands, whatever the view's size.

Model (:func:`keyframes_for`): ``PSNR(K) ≈ A − B·10·log₁₀ S + C·10·log₁₀ K`` dB against N = 80
sub-steps (clip(sRGB) of linear light), least squares over the views with 30–52 dB at K = 1…6
of the dataset benchmark's 55 motion-blur views of the 4 benchmark rooms and 9 close-ups of the
plant capture (bench motion, ×0.3/0.5/0.8 of its distance, seeds 1–3): residual std 2.0 dB, worst
−5.8 dB (``--table`` prints these PSNR; fitted with one doubling pass, the three of
:data:`~spacedg.render.motion.DOUBLING_PASSES` cost 0.3–0.45 dB on average). The count is the
smallest K whose prediction reaches :data:`TARGET_DB` = 44 dB, 4 dB above the 40 dB goal, and at
least one keyframe per :data:`KEYFRAME_PATH_PX` = 128 px of the longest on-screen path (the
parallax model does not see how far a long interval's path bends).

Measured with ``benchmarks/motion_keyframes.py`` (both rules with the same doubling passes; ms =
the keyframe render with this count's measurement, fastest of 2): the dataset's 55 views of the 4
benchmark rooms, 105 keyframes instead of 188, 97.4 ms a view instead of 129.4 (another run than
:data:`~spacedg.render.motion.DOUBLING_PASSES`' 93.0 ms), worst 43.45 dB
(the previous rule 46.47); held out (measured once, nothing tuned on them), 54 views of the rooms
of seed 8181, 117 instead of 172, 126.4 ms instead of 147.9, worst 44.32 dB (45.70), residual
+1.4 ± 1.4 dB; 48 views of the rooms of seeds 6262 and 5858 (measured once, after the rule was
final), 108 instead of 189, 125.4 ms instead of 171.0, worst 42.69 dB (45.79). Plant close-ups
get as many or more (27 instead of 24 on the 9 fitted ones; 9 instead of 7 on 4 held-out ones at severity 3), worst 43.08 and 45.39 dB (the previous rule 41.32
and 43.29). ``benchmarks/render.py --only severity`` (rooms, the plant and two 10k mesh objects,
every severity and 4 × bench): 42.98–57.5 dB against N = 80 and 43.0–57.5 against N = 256, a probe
point's smear rippling no more than N = 80's own.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from spacedg.render.camera import Camera, exposure_poses
from spacedg.render.colour import linear_to_srgb

if TYPE_CHECKING:
    import torch

    from spacedg.render.gaussians import Gaussians
    from spacedg.render.settings import MotionBlur, RasterSettings

#: Predicted PSNR (dB against N = 80) the keyframe count must reach: 4 dB above the 40 dB goal
#: (about twice the model's residual std).
TARGET_DB = 44.0
#: The model's coefficients (module docstring): ``PSNR ≈ A − B·10·log₁₀ S + C·10·log₁₀ K``.
MODEL_A, MODEL_B, MODEL_C = 13.749, 1.003, 2.228
#: Longest on-screen path (pixels) one keyframe interval may cover: a longer interval's parabola
#: bends away from the true path whatever the scene's edges. A probe point's smear read along its
#: exact path (``benchmarks/render.py --only severity``, "close" = 4 × the bench motion, 343–405 px
#: paths on the teapot, the cat and the plant) ripples 96–97 % at one keyframe, 22–28 % at two
#: (170–200 px an interval; 41.3–47.6 dB against N = 80) and 12–13 % at three (114–135 px;
#: 44.2–52.7 dB), N = 80's own ripple being 12 %.
KEYFRAME_PATH_PX = 128.0
#: The feature's render is this many times coarser than the view, per side.
COARSE_FACTOR = 4


def edge_parallax_contrast(
    gaussians: Gaussians, camera: Camera, motion: MotionBlur, settings: RasterSettings, backend: str = "cpu", device: torch.device | None = None,
) -> float:
    """``S``, the mean over neighbouring pixel pairs of a coarse render of squared contrast times
    parallax difference (module docstring); ``inf`` when a gap or a colour is NaN. The coarse render
    runs on ``backend`` (``"cpu"`` or ``"torch"``) and ``device``, as :func:`~spacedg.render.composite.composite_view`."""
    from spacedg.render.composite import composite_view
    from spacedg.render.motion_error_cpu import edge_products
    from spacedg.render.motion_warp import COVERED_ALPHA, fill_depth, relative_transform

    width, height = max(2, camera.width // COARSE_FACTOR), max(2, camera.height // COARSE_FACTOR)
    coarse = camera.resized(width, height)
    images, _ = composite_view(gaussians, coarse, frozenset({"rgb", "depth"}), backend, device, settings, None)
    alpha, depth = images["alpha"], images["depth"]
    covered = (alpha > COVERED_ALPHA) & np.isfinite(depth)
    z = depth.astype(np.float64) if covered.all() else np.where(covered, depth.astype(np.float64), fill_depth(alpha, depth))
    # coarse pixel centres in the view's pixels, and the surface points there (mid-exposure camera frame)
    u = (np.arange(width) + 0.5) * (camera.width / width)
    v = (np.arange(height) + 0.5) * (camera.height / height)
    x_ray, y_ray = (u - camera.cx) / camera.fx, (v - camera.cy) / camera.fy  # the rays' x/z and y/z
    reach = 2.0 * (camera.width + camera.height)  # about the warp's longest walk: any longer gap is that long
    ends = exposure_poses(camera, np.array(motion.translation), np.array(motion.rotation), np.array([-0.5, 0.5]))
    with np.errstate(all="ignore"):
        encoded = linear_to_srgb(np.clip(images["rgb"].astype(np.float64), 0.0, 1.0))
    products_h = np.empty((height, width - 1))
    products_v = np.empty((height - 1, width))
    edge_products(
        x_ray, y_ray, z, relative_transform(camera.cam_to_world, ends[0]), relative_transform(camera.cam_to_world, ends[1]),
        float(camera.fx), float(camera.fy), float(reach), encoded, products_h, products_v,
    )
    total = float(np.sum(products_h) + np.sum(products_v))
    value = total / (products_h.size + products_v.size)
    return value if math.isfinite(value) else math.inf


def keyframes_for(edge_measure: float, path_px: float, max_count: int) -> int:
    """The keyframe count of a view whose :func:`edge_parallax_contrast` is ``edge_measure`` and whose
    longest on-screen path over the exposure is ``path_px`` pixels: the smallest count whose
    predicted PSNR reaches :data:`TARGET_DB`, and at least one per :data:`KEYFRAME_PATH_PX` of the
    path; within ``[1, max_count]`` (the most when either is not finite)."""
    if not (edge_measure >= 0.0 and path_px >= 0.0) or math.isinf(edge_measure) or math.isinf(path_px):
        return max(1, max_count)
    count = math.ceil(path_px / KEYFRAME_PATH_PX)
    if edge_measure > 0.0:  # log₁₀ of a finite measure is within ±324: 10^exponent stays finite
        exponent = (TARGET_DB - MODEL_A + MODEL_B * 10.0 * math.log10(edge_measure)) / (10.0 * MODEL_C)
        count = max(count, math.ceil(10.0**exponent - 1e-9))
    return int(min(max(count, 1), max(1, max_count)))
