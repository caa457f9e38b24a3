"""Defocus against the thin-lens reference: one table, scene × severity × size × backend.

For each case the defocus render (``spacedg.render(..., defocus=...)``) is compared with
:func:`spacedg.render.thin_lens.thin_lens_render` (the mean of ``--samples`` pinhole renders over
a Gaussian lens, focus plane fixed; see that module for the derivation):

- ``light``: mean linear radiance of the defocus render over the clean render's (goal within 1 %);
  ``ref light``: the same for the thin-lens reference (what a lens does to the view's light);
- ``PSNR``: the defocus render against the reference, sRGB-encoded, clipped (goal ≥ 35 dB);
  ``conv``: PSNR between the two halves of the reference (each ``samples/2`` lens points on its
  own rotated spiral): the reference's own convergence (the full mean is ~3 dB better still);
- ``cost``: defocus render time over the clean render's (medians of ``--runs``; goal ≤ 3×).

Scenes: built-in room 0 (middle view), the shared plant capture (``../shared/data/splats/plant``),
an object on an empty background (the shared ``cube_10k``, filling ~40 % of the height), and a
close-up of the plant (camera at 45 % of its distance). Severities use the plugin's mid-range
aperture scaled to the image as ``min(W, H) / 1168`` (the ScanNet++ DSLR frame, 1752 × 1168, is the
reference size) and the low end of the focus range (1 m at the 2.5 m reference depth: 0.4 × the
view's median depth; points nearer than focus/4, where the model clamps r, are then rare);
``--focus high`` the far end, ``--focus low,high`` both.

    .venv/bin/python benchmarks/defocus_reference.py [--sizes 320x180,640x360] [--samples 96] [--backends cpu,torch] [--focus low,high]
"""

from __future__ import annotations

import argparse
import itertools
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from spacedg.render import Camera, Defocus, look_at, render  # noqa: E402
from spacedg.render.thin_lens import thin_lens_render  # noqa: E402
from spacedg.scene.synthetic import generate_room  # noqa: E402

from benchmarks.render import PLANT, SHARED, median_depth, plant_scene, psnr  # noqa: E402

REFERENCE_SHORT_SIDE = 1168  # ScanNet++ DSLR frames are 1752 × 1168


def scenes() -> list[tuple[str, object, Camera]]:
    from spacedg.scene.io import read_splat

    room = generate_room(seed=0)
    names = sorted(room.views)
    out = [("room", room.gaussians, room.views[names[len(names) // 2]])]
    if PLANT.exists():
        g, cam = plant_scene()
        out.append(("plant", g, cam))
        centre = cam.center + 2.0 * cam.forward  # roughly the plant's centre
        pose = np.array(cam.cam_to_world)
        pose[:3, 3] = centre - 0.45 * (centre - cam.center)
        out.append(("close-up", g, cam.with_pose(pose)))
    cube = SHARED / "cube" / "cube_10k.splat"
    if cube.exists():
        g = read_splat(cube, zero_quaternions="identity")
        c = 0.5 * (np.percentile(g.means, 1, 0) + np.percentile(g.means, 99, 0))
        out.append(("object", g, Camera(500.0, 500.0, 320.0, 240.0, 640, 480, look_at(c + np.array([1.2, -2.0, -5.5]), c, np.array([0.0, -1.0, 0.0])))))
    return out


def timed(fn, runs: int):  # type: ignore[no-untyped-def]
    fn()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", default="320x180,640x360")
    parser.add_argument("--samples", type=int, default=96)
    parser.add_argument("--runs", type=int, default=3)
    parser.add_argument("--severities", default="1,3,bench")
    parser.add_argument("--backends", default="cpu,torch")
    parser.add_argument("--focus", default="low", help="focus at the preset's low end (near: the default), high (far: "
                        "everything nearer is blurred, most by several px), or both, comma-separated")
    args = parser.parse_args()
    from spacedg.plugins.degradations.defocus import SPEC
    from spacedg.plugins.specs import REFERENCE_DEPTH_M

    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    focuses = args.focus.split(",")
    if not set(focuses) <= {"low", "high"}:
        raise SystemExit(f"--focus: expected low, high or low,high; got {args.focus!r}")
    print(f"thin-lens reference: {args.samples} lens points; light = mean radiance / clean; PSNR vs reference (sRGB); cost = time / clean")
    print(f"{'scene':<9} {'sev':<5} {'focus':<5} {'size':>8} {'aper px':>7} {'backend':<6} | {'light':>6} {'ref light':>9} | {'PSNR':>6} {'conv':>6} | {'cost':>5}")
    for name, g, view in scenes():
        depth = median_depth(g, view)
        for width, height in sizes:
            cam = view.fitted(width, height)
            for severity, focus in itertools.product(args.severities.split(","), focuses):
                preset = SPEC.presets[severity]
                aperture = 0.5 * (preset["aperture"].low + preset["aperture"].high) * min(cam.width, cam.height) / REFERENCE_SHORT_SIDE
                focus_depth = getattr(preset["depth"], focus)
                defocus = Defocus(aperture, focus_depth * depth / REFERENCE_DEPTH_M)
                half = args.samples // 2
                ref_a = thin_lens_render(g, cam, defocus, samples=half, seed=0)
                ref_b = thin_lens_render(g, cam, defocus, samples=half, seed=1)
                ref = (ref_a["rgb"] + ref_b["rgb"]) / 2.0
                conv = psnr(ref_a["rgb"], ref_b["rgb"])
                for backend in args.backends.split(","):
                    t_clean, clean = timed(lambda: render(g, cam, backend=backend), args.runs)
                    t_blur, blurred = timed(lambda: render(g, cam, defocus=defocus, backend=backend), args.runs)
                    base = float(clean.rgb.mean())
                    print(f"{name:<9} {severity:<5} {focus:<5} {cam.width:>4}x{cam.height:<4}{aperture:7.2f} {backend:<6} | "
                          f"{blurred.rgb.mean() / base:6.3f} {ref.mean() / base:9.3f} | {psnr(blurred.rgb, ref):6.2f} {conv:6.2f} | "
                          f"{t_blur / t_clean:5.2f}", flush=True)


if __name__ == "__main__":
    main()
