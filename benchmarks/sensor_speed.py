"""The sensor noise draw (low light, over-exposure) of this checkout against an older commit: time and bytes.

Cases (fixed seeded inputs, float32 linear light):

- ``table``: 1168 × 1557 × 3 photosite values at low light's bench rates (< 64 electrons: the Poisson table);
- ``normal``: a 640 × 480 view at exposure 8, clipped (over-exposure: rates ≥ 10³, the normal approximation);
- ``mixed``: a 640 × 480 view at exposure 0.1 (rates on both sides of 64 in a block);
- ``binned``: low light's photosite pass of a 640 × 480 view at the bench pitch (grid 1557 × 1168).

Each side runs in a subprocess of its checkout (the old one a git worktree under the temp folder, as
``benchmarks/render_speed.py`` makes it) with ``NUMBA_NUM_THREADS`` (default 1), after a warm-up call; a cell is
the fastest of ``--runs`` calls over ``--rounds`` alternating rounds. ``sha256`` hashes every output of a side:
equal hashes, equal bytes.

    .venv/bin/python benchmarks/sensor_speed.py --old c79a7bf      # stop 64's head: before the Zen 3 gather tuning

Timings are wall clock on whatever the machine is doing; the header prints numba's CPU name.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def cases() -> dict:
    """Name → call(i) of the sensor on its fixed input (key ``77 + i``), returning the output array."""
    import numpy as np

    from spacedg.plugins.degradations import _photosite_kernel
    from spacedg.plugins.degradations._sensor import sensor_capture

    rng = np.random.default_rng(6)
    sites = (rng.random((1168, 1557, 3)) * 0.8 * 0.004).astype(np.float32)
    view = rng.random((480, 640, 3)).astype(np.float32)
    dark = view * np.float32(0.004)
    sensor = {"k": 1e-4, "sigma_read": 2.5e-4, "read_model": 0, "read_lambda": 0.14}
    out_sites, out_view = np.empty_like(sites), np.empty_like(view)
    return {
        "table": lambda i: sensor_capture(sites, exposure=1.0, key=77 + i, clip=False, noise=True, out=out_sites, **sensor),
        "normal": lambda i: sensor_capture(view, exposure=8.0, key=77 + i, clip=True, **sensor),
        "mixed": lambda i: sensor_capture(view, exposure=0.1, key=77 + i, clip=False, **sensor),
        "binned": lambda i: _photosite_kernel.binned_noise(dark, (1557, 1168), key=77 + i, out=out_view, **sensor),
    }


def worker(runs: int) -> None:
    """Print ``{"cpu": …, "ms": {case: fastest}, "sha256": …}`` for this process's checkout."""
    import numba
    import numpy as np

    timings, digest = {}, hashlib.sha256()
    for name, call in cases().items():
        call(0)
        best = float("inf")
        for i in range(runs):
            t0 = time.perf_counter()
            result = call(i)
            best = min(best, time.perf_counter() - t0)
            digest.update(np.ascontiguousarray(result).tobytes())
        timings[name] = best * 1e3
    codegen = numba.core.registry.cpu_target.target_context.codegen()
    print(json.dumps({"cpu": codegen.magic_tuple()[1], "ms": timings, "sha256": digest.hexdigest()}))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--old", default="c79a7bf", help="the commit to compare with (default: stop 64's head)")
    parser.add_argument("--runs", type=int, default=5)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.runs)
        return
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from render_speed import checkout

    sides = {"old": checkout(args.old), "new": ROOT}
    best: dict[str, dict[str, float]] = {"old": {}, "new": {}}
    hashes: dict[str, set[str]] = {"old": set(), "new": set()}
    cpu = "?"
    for _ in range(args.rounds):
        for side, src in sides.items():
            env = dict(os.environ, PYTHONPATH=str(src), NUMBA_NUM_THREADS=str(args.threads))
            done = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--worker", "--runs", str(args.runs)],
                                  env=env, cwd=str(src), check=True, capture_output=True, text=True)
            report = json.loads(done.stdout.strip().splitlines()[-1])
            cpu = report["cpu"]
            hashes[side].add(report["sha256"])
            for name, ms in report["ms"].items():
                best[side][name] = min(best[side].get(name, float("inf")), ms)
    print(f"numba CPU {cpu}, {args.threads} thread(s), fastest of {args.runs} runs x {args.rounds} rounds; old = {args.old}")
    print(f"{'case':8s} {'old ms':>8s} {'new ms':>8s} {'speed-up':>9s}")
    for name in best["new"]:
        print(f"{name:8s} {best['old'][name]:8.1f} {best['new'][name]:8.1f} {best['old'][name] / best['new'][name]:8.2f}x")
    same = len(hashes["old"]) == len(hashes["new"]) == 1 and hashes["old"] == hashes["new"]
    print("bytes:", "identical (sha256 " + next(iter(hashes["new"]))[:16] + ")" if same else f"DIFFER {hashes}")


if __name__ == "__main__":
    main()
