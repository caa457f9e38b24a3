"""Covisibility of a 150-view synthetic room: run time, and reduced size against a 2× finer one.

Prints numbers only (never part of the test run).

    .venv/bin/python benchmarks/covisibility.py                 # 150 views, 200k Gaussians
    .venv/bin/python benchmarks/covisibility.py --gaussians 50000 --stride 2
    .venv/bin/python benchmarks/covisibility.py --visibility    # also time compute_visibility

The room comes from ``generate_room(seed, RoomConfig(capture=CaptureConfig(min_views=150,
max_views=150)))``: the capture config takes the view count directly, so the 150 views are
the generator's own hand-held trajectory (no interpolated cameras). Timings are wall-clock
(``time.perf_counter``), after a warm-up render that compiles the numba kernels; the machine
line prints the load average.

1. ``covisibility_matrix`` at the default reduced size (80×60): depth render time (all
   views) and matrix time (lift + project + depth test for all V² pairs) separately.
2. The same at 2× finer (160×120), and the mean / max |Δ| between the two raw matrices
   (off-diagonal), plus the share of pairs on different sides of the 0.25 pair threshold of
   the symmetric (min) matrix.
"""

from __future__ import annotations

import argparse
import os
import platform
import time

import numpy as np

from spacedg.scene.synthetic import RoomConfig, generate_room
from spacedg.scene.synthetic.trajectory import CaptureConfig
from spacedg.scene.covisibility import COVISIBILITY_IMAGE_SIZE, covisibility_matrix, symmetrize
from spacedg.scene.visibility import compute_visibility
from spacedg.render.renderer import render


def _machine() -> str:
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, load {load:.2f}"


def _run(scene, size: tuple[int, int], stride: int) -> tuple[np.ndarray, dict[str, float]]:
    timings: dict[str, float] = {}
    _, matrix = covisibility_matrix(scene, image_size=size, stride=stride, progress=False, timings=timings)
    return matrix, timings


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seed", type=int, default=3)
    parser.add_argument("--views", type=int, default=150)
    parser.add_argument("--gaussians", type=int, default=200_000)
    parser.add_argument("--stride", type=int, default=1, help="lift every stride-th pixel row/column of view i")
    parser.add_argument("--visibility", action="store_true", help="also time compute_visibility over all views")
    args = parser.parse_args()

    t0 = time.perf_counter()
    capture = CaptureConfig(min_views=args.views, max_views=args.views)
    scene = generate_room(args.seed, RoomConfig(gaussians=args.gaussians, capture=capture))
    print(f"machine: {_machine()}")
    print(f"scene: {scene!r} generated in {time.perf_counter() - t0:.1f} s; image {next(iter(scene.views.values())).width}×"
          f"{next(iter(scene.views.values())).height}")
    warm = next(iter(scene.views.values())).resized(32, 24)
    render(scene.gaussians, warm, outputs="depth,instance_ids")  # compile numba kernels

    base_size = COVISIBILITY_IMAGE_SIZE
    fine_size = (2 * base_size[0], 2 * base_size[1])
    results = {}
    for size in (base_size, fine_size):
        t = time.perf_counter()
        matrix, timings = _run(scene, size, args.stride)
        total = time.perf_counter() - t
        results[size] = matrix
        v = matrix.shape[0]
        print(f"covisibility {size[0]}×{size[1]} stride {args.stride}: {v} views, render {timings['render_s']:.2f} s "
              f"({1e3 * timings['render_s'] / v:.1f} ms/view), matrix {timings['matrix_s']:.2f} s "
              f"({1e3 * timings['matrix_s'] / v:.1f} ms/row), total {total:.2f} s")

    base, fine = results[base_size], results[fine_size]
    off = ~np.eye(base.shape[0], dtype=bool)
    diff = np.abs(base - fine)[off]
    print(f"{base_size[0]}×{base_size[1]} vs {fine_size[0]}×{fine_size[1]} (raw, off-diagonal): "
          f"mean |Δ| {diff.mean():.4f}, max |Δ| {diff.max():.4f}, p99 |Δ| {np.quantile(diff, 0.99):.4f}")
    sb, sf = symmetrize(base), symmetrize(fine)
    flips = ((sb > 0.25) != (sf > 0.25))[off]
    print(f"pairs above 0.25 (min-symmetrised): {int((sb > 0.25)[off].sum()) // 2} vs {int((sf > 0.25)[off].sum()) // 2}; "
          f"pairs that change side: {int(flips.sum()) // 2} of {int(off.sum()) // 2}")
    print(f"mean covisibility (raw, off-diagonal): {base[off].mean():.4f}")

    if args.visibility:
        t = time.perf_counter()
        vis = compute_visibility(scene, progress=False)
        total = time.perf_counter() - t
        records = sum(len(row) for row in vis.values())
        visible = sum(1 for row in vis.values() for r in row.values() if r.visible_pixels > 0)
        print(f"compute_visibility 160×120: {len(vis)} views × {len(scene.instances)} instances in {total:.2f} s "
              f"({1e3 * total / len(vis):.1f} ms/view); {visible} of {records} records with visible pixels")


if __name__ == "__main__":
    main()
