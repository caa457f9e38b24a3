"""Fresh-compiled vs cache-loaded numba kernels: do they give the same bytes?

numba compiles spacedg's kernels on first use and caches them on disk (``cache=True``); a later
process loads the cached machine code. The two must compute the same bits, or the first run on
a machine (or any run after the cache was invalidated) renders other images than later runs.
This script runs a set of cases covering every ``parallel=True`` / ``fastmath`` kernel (renders
on each backend path that uses numba: clean, defocus, fisheye, motion blur exact and fast; the
degradations whose stages use numba kernels) in two subprocesses that share one new, empty
``NUMBA_CACHE_DIR``: the first compiles every kernel and writes the cache, the second loads it.
It prints one SHA-256 per output array and exits 1 if any differs.

    .venv/bin/python benchmarks/numba_cache_determinism.py                 # every case, 320x240
    .venv/bin/python benchmarks/numba_cache_determinism.py --size 64x48 --cases motion_fast

Kernels reached (spacedg/render/…): raster_cpu ``composite_tiles`` (each output specialisation),
project_cpu, colour_cpu, motion_warp ``flow_field`` / ``doubling_pass`` /
``gather``; plugins/degradations ``_sensor`` (device presets, low light, over exposure) and
``water_droplets``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Callable

import numpy as np

#: Degradation chains run through the pipeline (each one sample of one view).
CHAINS = (
    "clean", "defocus", "distortion", "haze", "jpeg_compression", "low_light", "low_res",
    "motion_blur", "over_exposure", "water_droplets", "night_capture", "compressed_portrait",
)


def _sha(array: Any) -> str:
    return hashlib.sha256(np.ascontiguousarray(np.asarray(array)).tobytes()).hexdigest()


def _frame_hashes(prefix: str, frame: Any) -> dict[str, str]:
    out = {}
    for field in ("rgb", "alpha", "depth", "median_depth", "instance_ids"):
        value = getattr(frame, field, None)
        if value is not None:
            if hasattr(value, "detach"):
                value = value.detach().cpu().numpy()
            out[f"{prefix}/{field}"] = _sha(value)
    return out


def _cases(width: int, height: int) -> dict[str, Callable[[], dict[str, str]]]:
    """name -> function returning {output name: sha256} (imports happen inside, in the child)."""
    from dataclasses import replace

    from spacedg.render import Defocus, MotionBlur, render
    from spacedg.render.camera import FisheyeLens
    from spacedg.scene.synthetic import generate_room

    scene = generate_room(0)
    view = sorted(scene.views)[3]
    cam = scene.views[view].resized(width, height)
    g = scene.gaussians
    motion = ((0.05, 0.0, 0.0), (0.0, 0.03, 0.0))
    long_motion = ((0.25, 0.0, 0.1), (0.0, 0.08, 0.0))
    backends = ["cpu"]
    try:
        import torch  # noqa: F401

        backends.append("torch")
    except ImportError:
        pass

    def renders(prefix: str, **kw: Any) -> Callable[[], dict[str, str]]:
        def run() -> dict[str, str]:
            out: dict[str, str] = {}
            for backend in backends:
                out.update(_frame_hashes(f"{prefix}/{backend}", render(g, cam, backend=backend, **kw)))
            return out

        return run

    fisheye = replace(cam, fisheye=FisheyeLens(-0.24, 2e-4, 1.5e-4, 5e-5, 1.5))

    def fisheye_case() -> dict[str, str]:
        return _frame_hashes("fisheye/cpu", render(g, fisheye, backend="cpu", outputs="rgb,alpha,depth"))

    def degradations() -> dict[str, str]:
        from spacedg.data.pipeline import PipelineOptions, degrade_variants

        options = PipelineOptions(image_size=(width, height), backend="cpu")
        chains = [None if c == "clean" else c for c in CHAINS]
        results = degrade_variants(scene, [view], chains, seed=0, options=options)
        return {f"degrade/{name}": _sha(res.images) for name, res in zip(CHAINS, results)}

    return {
        "clean": renders("clean", outputs="all"),
        "clean_rgb": renders("clean_rgb", outputs="rgb"),
        "defocus": renders("defocus", outputs="rgb,alpha,depth", defocus=Defocus(aperture=6.0, focus=1.5)),
        "fisheye": fisheye_case,
        "motion_exact": renders("motion_exact", outputs="rgb,alpha,depth", motion=MotionBlur(*motion, sub_steps=12)),
        "motion_fast": renders("motion_fast", outputs="rgb,alpha,depth", motion=MotionBlur(*motion, sub_steps=80, fast=True)),
        "motion_fast_rgb": renders("motion_fast_rgb", outputs="rgb", motion=MotionBlur(*motion, sub_steps=80, fast=True)),
        # paths long enough for box-doubling passes before the gather (motion_warp.doubling_pass)
        "motion_fast_long": renders("motion_fast_long", outputs="rgb,alpha,depth", motion=MotionBlur(*long_motion, sub_steps=80, fast=True)),
        "degradations": degradations,
    }


def child(out: Path, width: int, height: int, names: list[str]) -> None:
    cases = _cases(width, height)
    hashes: dict[str, str] = {}
    for name in names or list(cases):
        hashes.update(cases[name]())
    out.write_text(json.dumps(hashes, indent=1, sort_keys=True))


def compare(width: int, height: int, names: list[str], cache_dir: Path | None = None,
            verbose: bool = True) -> tuple[dict[str, str], dict[str, str]]:
    """Run the cases fresh then cached (one new shared ``NUMBA_CACHE_DIR``); return both hash maps."""
    with tempfile.TemporaryDirectory(prefix="spacedg-numba-cache-") as tmp:
        env = dict(os.environ, NUMBA_CACHE_DIR=str(cache_dir or Path(tmp) / "cache"))
        root = str(Path(__file__).resolve().parents[1])
        env["PYTHONPATH"] = root + os.pathsep + env.get("PYTHONPATH", "") if env.get("PYTHONPATH") else root
        maps = []
        for run in ("fresh", "cached"):
            out = Path(tmp) / f"{run}.json"
            start = time.perf_counter()
            cmd = [sys.executable, str(Path(__file__).resolve()), "--child", str(out), "--size", f"{width}x{height}"]
            if names:
                cmd += ["--cases", *names]
            proc = subprocess.run(cmd, env=env, capture_output=True, text=True)
            if proc.returncode != 0:
                raise SystemExit(f"{run} run failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")
            if verbose:
                print(f"{run}: {time.perf_counter() - start:.1f} s", flush=True)
            maps.append(json.loads(out.read_text()))
    return maps[0], maps[1]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--size", default="320x240", help="render size WxH (default 320x240)")
    parser.add_argument("--cases", nargs="*", default=[], help="cases to run (default: all)")
    parser.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    width, height = (int(v) for v in args.size.lower().split("x"))
    os.environ.setdefault("SPACEDG_DISABLE_PLUGIN_AUTOLOAD", "1")
    if args.child:
        child(args.child, width, height, args.cases)
        return 0
    fresh, cached = compare(width, height, args.cases)
    names = sorted(fresh.keys() | cached.keys())
    bad = [n for n in names if fresh.get(n) != cached.get(n)]
    print(f"| case/output | fresh | cached | same |\n|---|---|---|---|")
    for n in names:
        print(f"| {n} | {fresh.get(n, 'missing')[:12]} | {cached.get(n, 'missing')[:12]} | {'yes' if n not in bad else 'NO'} |")
    print(f"{len(names) - len(bad)}/{len(names)} outputs identical fresh vs cached" + (f"; {len(bad)} differ" if bad else ""))
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
