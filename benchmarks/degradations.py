"""Degradation cost and strength: each degradation at ``bench`` against the clean sample of the same run.

Prints tables only (never part of the test run).

    .venv/bin/python benchmarks/degradations.py               # room seed 0, 3 views, 5 repeats
    .venv/bin/python benchmarks/degradations.py --views 1 --repeats 3
    .venv/bin/python benchmarks/degradations.py --motion reference   # motion blur at N = 80

For each view of a built-in synthetic room (640×480) and each repeat, in one interleaved run:

- the **clean sample**: one render + the exact 8-bit sRGB encode (``degrade(..., None)``);
- each of the nine degradations at the paper's ``bench`` preset, as a one-degradation sample
  (``degrade(..., name)``: its own render for raster-stage ones, the clean render again plus the
  degradation for post-render ones), with its time as a ratio to the clean sample's and, for
  post-render degradations, the overhead on top of the clean sample (target ≤ 0.5×): the time
  of its post-render stages (linear chain + encode + display chain, timed inside the pipeline)
  minus the clean sample's encode, over the clean sample's time (the difference of two whole
  ~30 ms samples would drown a few milliseconds in timer noise);
- the **bench set** of one view, ``degrade_variants(..., ["clean", all nine])``: renders shared
  between the clean image and the six post-render degradations. Target: ≤ 4× the clean sample
  plus the motion-blur cost (motion sample − clean sample).

Defocus footprint truncation: the bench defocus sample with blurred footprints cut at the
default 2.5 σ (energy renormalised) against the full 3.33 σ, time and PSNR.

Distance to clean: mean absolute difference of the 8-bit images (0–255) and PSNR (dB), averaged
over views. Times are medians over repeats, summed over views. Timings are wall clock on
whatever else the machine is doing: the first line prints the load average.
"""

from __future__ import annotations

import argparse
import math
import os
import platform
import time
from collections import defaultdict

import numpy as np

from spacedg.data.chain import BENCH_DEGRADATIONS
from spacedg.data.pipeline import PipelineOptions, degrade, degrade_variants
from spacedg.scene.synthetic import generate_room
from spacedg.plugins.registry import get_degradation
from spacedg.plugins.specs import Stage
from spacedg.render.settings import RasterSettings


def psnr(image: np.ndarray, reference: np.ndarray) -> float:
    mse = float(np.mean((image.astype(np.float64) - reference.astype(np.float64)) ** 2))
    return math.inf if mse == 0.0 else 10.0 * math.log10(255.0**2 / mse)


def timed(fn, *args, **kwargs):  # type: ignore[no-untyped-def]
    t0 = time.perf_counter()
    result = fn(*args, **kwargs)
    return (time.perf_counter() - t0) * 1e3, result


def machine_line() -> str:
    import numba

    return (
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, numba threads "
        f"{numba.get_num_threads()}, numpy {np.__version__}, load average {os.getloadavg()[0]:.2f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--room-seed", type=int, default=0, help="built-in synthetic room seed (default 0)")
    parser.add_argument("--views", type=int, default=3, help="number of views (default 3)")
    parser.add_argument("--repeats", type=int, default=5, help="timed repeats per view (default 5)")
    parser.add_argument("--motion", choices=("fast", "reference"), default="fast", help="motion blur sub-steps mode")
    args = parser.parse_args()

    scene = generate_room(args.room_seed)
    views = list(scene.views)[: args.views]
    options = PipelineOptions(motion=args.motion)
    print(machine_line())
    cam = scene.views[views[0]]
    print(f"scene: synthetic room seed {args.room_seed}, {len(scene.gaussians):,} Gaussians, {cam.width}x{cam.height}, "
          f"views {views}, {args.repeats} repeats, motion={args.motion}")

    # warm-up: compile every kernel once
    degrade_variants(scene, views[:1], ["clean", *BENCH_DEGRADATIONS], seed=0, options=options)

    per_view: dict[str, list[float]] = defaultdict(list)  # name -> per-view median ms
    post_view: dict[str, list[float]] = defaultdict(list)  # name -> per-view median post-render stage ms
    distance: dict[str, list[float]] = defaultdict(list)
    quality: dict[str, list[float]] = defaultdict(list)
    sub_steps: list[int] = []
    for v, view in enumerate(views):
        times: dict[str, list[float]] = defaultdict(list)
        post: dict[str, list[float]] = defaultdict(list)
        for r in range(args.repeats):
            seed = 1000 * v + r
            ms, clean = timed(degrade, scene, [view], None, seed, options)
            times["clean"].append(ms)
            post["clean"].append(clean.stats["encode_ms"])
            for name in BENCH_DEGRADATIONS:
                ms, out = timed(degrade, scene, [view], name, seed, options)
                times[name].append(ms)
                post[name].append(out.stats["linear_ms"] + out.stats["encode_ms"] + out.stats["display_ms"])
                if r == 0:
                    distance[name].append(float(np.abs(out.images.astype(np.float64) - clean.images).mean()))
                    quality[name].append(psnr(out.images, clean.images))
                    if name == "motion_blur":
                        sub_steps.extend(out.sub_steps)
            ms, _ = timed(degrade_variants, scene, [view], ["clean", *BENCH_DEGRADATIONS], seed, options)
            times["bench set"].append(ms)
        for name, values in times.items():
            per_view[name].append(float(np.median(values)))
        for name, values in post.items():
            post_view[name].append(float(np.median(values)))

    total = {name: float(np.sum(values)) for name, values in per_view.items()}
    post_total = {name: float(np.sum(values)) for name, values in post_view.items()}
    clean_ms = total["clean"]
    print(f"\nclean sample: {clean_ms / len(views):.1f} ms per view (render + exact sRGB encode; encode "
          f"{post_total['clean'] / len(views):.2f} ms)\n")
    print("| degradation | stage | sample ms per view | × clean sample | post-render stages ms | overhead on clean | mean |Δ| (0-255) | PSNR vs clean (dB) |")
    print("|---|---|---|---|---|---|---|---|")
    for name in BENCH_DEGRADATIONS:
        stage = get_degradation(name).stage
        ratio = total[name] / clean_ms
        extra = (post_total[name] - post_total["clean"]) / clean_ms
        overhead = f"{extra:.3f}×" if stage is not Stage.RASTER else "(own render)"
        print(f"| {name} | {stage.value} | {total[name] / len(views):.1f} | {ratio:.2f} | "
              f"{post_total[name] / len(views):.2f} | {overhead} | "
              f"{np.mean(distance[name]):.1f} | {np.mean(quality[name]):.1f} |")
    motion_cost = total["motion_blur"] - clean_ms
    budget = 4.0 * clean_ms + motion_cost
    print(f"\nmotion blur sub-steps rendered ({args.motion}): {sub_steps}")
    print(f"bench set (clean + 9) of one view: {total['bench set'] / len(views):.1f} ms per view = "
          f"{total['bench set'] / clean_ms:.2f}× clean; budget 4× clean + motion cost = {budget / len(views):.1f} ms "
          f"per view -> {'met' if total['bench set'] <= budget else 'NOT met'} "
          f"(set without motion: {(total['bench set'] - motion_cost) / clean_ms:.2f}× clean)")

    truncation_table(scene, views, args.repeats, options)


def truncation_table(scene, views: list[str], repeats: int, options: PipelineOptions) -> None:  # type: ignore[no-untyped-def]
    """Bench defocus with the default 2.5 σ truncation against the full 3.33 σ footprint."""
    from dataclasses import replace

    full = replace(options, settings=RasterSettings(defocus_extent=None))
    print("\n| view | full 3.33 σ ms | truncated 2.5 σ ms | speed-up | PSNR truncated vs full (dB) |")
    print("|---|---|---|---|---|")
    for v, view in enumerate(views):
        seed = 1000 * v
        t_full = [timed(degrade, scene, [view], "defocus", seed, full) for _ in range(repeats)]
        t_cut = [timed(degrade, scene, [view], "defocus", seed, options) for _ in range(repeats)]
        ms_full, ms_cut = np.median([t for t, _ in t_full]), np.median([t for t, _ in t_cut])
        print(f"| {view} | {ms_full:.1f} | {ms_cut:.1f} | {ms_full / ms_cut:.2f}× | "
              f"{psnr(t_cut[0][1].images, t_full[0][1].images):.1f} |")


if __name__ == "__main__":
    main()
