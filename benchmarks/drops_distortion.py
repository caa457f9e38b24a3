"""Issue 29 items 3–5 measured: drops that refract, distortion on the camera's own focal lengths,
and fisheye + defocus chains that keep their image or name why not.

Prints three tables:

1. ``water_droplets`` per preset and seed on a 360×640 textured frame: the light of the drops
   outside their highlights over the light of the refracted background they show (goal within
   2 %), and on a black frame the largest value outside the highlights (goal 0) and the peak
   highlight.
2. ``distortion`` at bench k1 = −0.24 and mild k1 = −0.05: the width of a subject at the image
   centre over its clean width (the paper's lens vs the contained variant), and the share of the
   distorted frame the clean view covers.
3. ``degrade()`` chains of ``distortion`` (random parameters inside the hard limits) with a
   large ``defocus`` on the fuzz's tiny scene at 64×48: kept (with the imaged coverage), refused
   with :class:`~spacedg.render.coverage.CoverageLostError`, other errors, and black images
   returned without an error (goal 0).

    .venv/bin/python benchmarks/drops_distortion.py [--chains 200]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import cv2
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from spacedg.data.pipeline import PipelineOptions, degrade  # noqa: E402
from spacedg.errors import SpaceDGError  # noqa: E402
from spacedg.plugins.degradations import distortion, water_droplets as wd  # noqa: E402
from spacedg.render import render  # noqa: E402
from spacedg.render.coverage import CoverageLostError, captured_share  # noqa: E402
from spacedg.render.request import RenderRequest  # noqa: E402
from tests.fuzz_cases import _param, tiny_scene  # noqa: E402
from tests.plugins.degradations.test_raster import _width_at_half_alpha  # noqa: E402
from tests.plugins.degradations.test_water_droplets import _textured  # noqa: E402
from tests.render_helpers import camera  # noqa: E402


def drops_table() -> None:
    print("water_droplets (360x640): preset seed  light/refracted  black max outside highlight  peak highlight")
    image = _textured(360, 640)
    for preset in ("1", "2", "3", "4", "5", "bench"):
        for seed in range(3):
            p = wd.SPEC.sample_params(preset, np.random.default_rng(seed))
            field = wd.droplet_field(image.shape[:2], p["scale"], p["radius"], p["strength"], np.random.default_rng(seed))
            seen = wd.refracted_view(image, field)  # the scene through each drop (a minifying drop's mean)
            seen = cv2.GaussianBlur(seen, (p["blur_kernel"],) * 2, p["blur_sigma"], borderType=cv2.BORDER_REFLECT)
            behind = (1 - field.alpha[..., None]) * image + field.alpha[..., None] * seen
            lit = wd.SPECULAR_INTENSITY * field.highlight
            unlit = (field.alpha > 0) & (lit < 1e-4)
            out = wd.water_droplets(image, **p, rng=np.random.default_rng(seed))
            black = wd.water_droplets(np.zeros_like(image), **p, rng=np.random.default_rng(seed))
            print(f"  {preset:>5} {seed}  {out[unlit].sum() / behind[unlit].sum():.4f}  {black[lit == 0].max(initial=0.0):.1e}  {black.max():.3f}")


def distortion_table() -> None:
    from spacedg.render.gaussians import Gaussians

    rng = np.random.default_rng(11)
    n = 400
    means = np.column_stack([rng.uniform(-0.12, 0.12, n), rng.uniform(-0.02, 0.02, n), np.full(n, 2.0)])
    gauss = Gaussians.from_colors(means, np.tile([1.0, 0, 0, 0], (n, 1)), np.full((n, 3), 0.012), np.ones(n), np.full((n, 3), 0.8))
    clean = camera(320, 240)
    width = _width_at_half_alpha(render(gauss, clean).alpha)
    print("distortion (320x240, 65° view): k1  centre size paper  contained  captured share paper  contained")
    for k1 in (-0.24, -0.05):
        paper = distortion.distort(RenderRequest(clean), k1, 2e-4, 1e-4, 5e-5, 1.5)
        contained = distortion.distort_contained(RenderRequest(clean), k1, 2e-4, 1e-4, 5e-5, 1.5)
        print(f"  {k1:+.2f}  {_width_at_half_alpha(paper.render(gauss).alpha) / width:.4f}  "
              f"{_width_at_half_alpha(contained.render(gauss).alpha) / width:.4f}  "
              f"{captured_share(clean, paper.camera):.3f}  {captured_share(clean, contained.camera):.3f}")


def chains_table(chains: int) -> None:
    scene = tiny_scene()
    view = sorted(scene.views)[0]
    rng = np.random.default_rng(600)
    counts = {"kept": 0, "refused (CoverageLostError)": 0, "other clear error": 0, "black without error": 0}
    coverage = []
    for seed in range(chains):
        params = {p.name: _param(p, rng) for p in distortion.SPEC.params}
        chain = [{"name": "distortion", "params": params},
                 {"name": "defocus", "params": {"aperture": float(rng.choice([50.0, 200.0])), "depth": float(rng.uniform(0.5, 8.0))}}]
        try:
            images = degrade(scene, [view], chain, seed=seed, options=PipelineOptions(image_size=(64, 48))).images
        except CoverageLostError:
            counts["refused (CoverageLostError)"] += 1
            continue
        except SpaceDGError:
            counts["other clear error"] += 1
            continue
        counts["kept" if images.max() > 0 else "black without error"] += 1
        coverage.append(float((images.max(axis=-1) > 0).mean()))
    print(f"distortion + defocus (50/200 px) chains at 64x48, {chains} chains: {counts}; "
          f"kept images: median share of non-black pixels {np.median(coverage) if coverage else float('nan'):.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--chains", type=int, default=200)
    args = parser.parse_args()
    drops_table()
    distortion_table()
    chains_table(args.chains)


if __name__ == "__main__":
    main()
