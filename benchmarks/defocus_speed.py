"""Defocus cost and error by scene and severity: the model before issue 21 part 3 beside today's.

Prints one table (never part of the test run). Per scene (built-in rooms 0 and 1, the shared plant
capture when ``../shared/data/splats/plant`` exists), defocus preset (1–5 and bench, mid-range
aperture) and focus (``near``: the low end of the preset's focus range, 1 m at the 2.5 m reference
depth, i.e. 0.4 × the view's median depth; ``far``: the high end, 8 m → 3.2 × the median depth;
the foreground is then the most blurred), at 448×336 on the compiled CPU path:

- ``clean ms``: a sharp render (median);
- ``old ×`` / ``new ×``: a defocus render's time over the clean render's, old and new timed
  alternately in one process (medians of ``--runs``). **old** is the model as it was (sharp
  measurement pass at full resolution, no coarse composite: :func:`old_render_cpu`, today's driver with those two switched off);
  **new** is :func:`spacedg.render.defocus.render_cpu`;
- ``PSNR`` (dB, sRGB-encoded, clipped to [0, 1]) and ``mean|Δ|`` (linear light) of new against old;
- ``energy``: mean linear radiance / mean alpha of the defocus render over the sharp render's,
  old then new (the model keeps a view's light; see :mod:`spacedg.render.defocus`).

    .venv/bin/python benchmarks/defocus_speed.py [--threads 1] [--runs 5] [--quick]
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from spacedg.render import Defocus, render  # noqa: E402
from spacedg.render import defocus as model  # noqa: E402
from spacedg.scene.synthetic import generate_room  # noqa: E402

from benchmarks.render import PLANT, median_depth, plant_scene, psnr  # noqa: E402 - the render benchmark's scenes and PSNR

WIDTH, HEIGHT = 448, 336
SEVERITIES = ("1", "2", "3", "4", "5", "bench")


NEW_RENDER_CPU = model.render_cpu


def old_render_cpu(*args):  # type: ignore[no-untyped-def]
    """The model before issue 21 part 3: today's driver with the sharp measurement at full
    resolution (``MEASURE_SCALE = 1``) and no coarse composite (``COMPOSITE_MIN_COC = 0``). Its
    numpy factors then gave the bytes the compiled ones give (``tests/render/test_defocus.py``)."""
    saved = model.MEASURE_SCALE, model.COMPOSITE_MIN_COC
    model.MEASURE_SCALE, model.COMPOSITE_MIN_COC = 1.0, 0.0
    try:
        return NEW_RENDER_CPU(*args)
    finally:
        model.MEASURE_SCALE, model.COMPOSITE_MIN_COC = saved


def scenes(quick: bool) -> list[tuple[str, object, object]]:
    out = []
    for seed in (0,) if quick else (0, 1):
        room = generate_room(seed=seed)
        names = sorted(room.views)
        out.append((f"room {seed}", room.gaussians, room.views[names[len(names) // 2]].resized(WIDTH, HEIGHT)))
    if PLANT.exists():
        g, cam = plant_scene()
        out.append(("plant", g, cam.resized(WIDTH, HEIGHT)))
    else:
        print(f"(plant skipped: {PLANT} not found)")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--threads", type=int, default=None, help="numba threads (default: numba's)")
    parser.add_argument("--runs", type=int, default=5, help="alternating timed runs per cell (default 5)")
    parser.add_argument("--quick", action="store_true", help="room 0 and the plant, severities 1, 3, 5")
    args = parser.parse_args()
    import numba

    from spacedg.plugins.degradations.defocus import SPEC
    from spacedg.plugins.specs import REFERENCE_DEPTH_M

    if args.threads:
        numba.set_num_threads(args.threads)
    print(f"numba threads {numba.get_num_threads()}, {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}; "
          f"{WIDTH}x{HEIGHT}, compiled CPU path, medians of {args.runs} alternating runs")
    print(f"{'scene':<8} {'sev':<5} {'focus':<9} {'aper':>5} {'clean ms':>8} | {'old ms':>7} {'new ms':>7} | "
          f"{'old ×':>6} {'new ×':>6} | {'PSNR':>6} {'mean|Δ|':>8} | energy old rad/cov  new rad/cov")
    severities = ("1", "3", "5") if args.quick else SEVERITIES
    for name, g, cam in scenes(args.quick):
        depth = median_depth(g, cam)
        for severity in severities:
            preset = SPEC.presets[severity]
            aperture = 0.5 * (preset["aperture"].low + preset["aperture"].high)
            focus_range = preset["depth"]
            for label, focus_m in (("near", focus_range.low), ("far", focus_range.high)):
                focus = focus_m * depth / REFERENCE_DEPTH_M
                defocus = Defocus(aperture, focus)
                sharp = render(g, cam)
                frames = {}
                times: dict[str, list[float]] = {"clean": [], "old": [], "new": []}
                for i in range(args.runs + 1):
                    for which in ("clean", "old", "new"):
                        model.render_cpu = old_render_cpu if which == "old" else NEW_RENDER_CPU
                        start = time.perf_counter()
                        frame = render(g, cam) if which == "clean" else render(g, cam, defocus=defocus)
                        if i > 0:
                            times[which].append(time.perf_counter() - start)
                        frames[which] = frame
                model.render_cpu = NEW_RENDER_CPU
                ms = {k: 1e3 * float(np.median(v)) for k, v in times.items()}
                old, new = frames["old"], frames["new"]
                diff = float(np.abs(new.rgb - old.rgb).mean())
                energy = "  ".join(
                    f"{f.rgb.mean() / sharp.rgb.mean():.3f}/{f.alpha.mean() / sharp.alpha.mean():.3f}" for f in (old, new)
                )
                print(f"{name:<8} {severity:<5} {label} {focus:4.2f} {aperture:5.1f} {ms['clean']:8.1f} | {ms['old']:7.1f} {ms['new']:7.1f} | "
                      f"{ms['old'] / ms['clean']:6.2f} {ms['new'] / ms['clean']:6.2f} | {psnr(new.rgb, old.rgb):6.2f} {diff:8.5f} | "
                      f"      {energy}", flush=True)


if __name__ == "__main__":
    main()
