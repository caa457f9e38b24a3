"""Motion blur on close-ups: the keyframe path against N = 80 sub-steps, and its cost.

Scenes: the shared plant capture (``../shared/data/splats/plant``, a real phone capture) seen
from ``--factors`` × the distance of ``benchmarks/render.py``'s plant view (0.3: the plant's
leaves from 0.25 to 0.6 units, a close-up), and a built-in room's middle view; motion: the
``motion_blur`` bench preset's mid-range ``trans`` scaled by the view's median depth / 2.5 m (as
the plugin does) and ``rot``, along random directions (``--seeds``), 640×480. For each case it
prints the keyframes the rule picks (``K``), the PSNR against N = 80 (clip(sRGB) of linear light),
the time as a multiple of a clean render (medians of ``--runs``, alternating), and the same for
the previous rule (``max(⌈D/90⌉, 2 past 60 px, ⌈√(P/3.5)⌉)`` for a path of D px and a near-far
parallax of P px, at most 8; stop 48 and before). Goal: ≥ 40 dB within ≤ 8 renders::

    .venv/bin/python benchmarks/motion_closeup.py [--factors 0.3,0.5] [--seeds 1,2,3] [--runs 2] [--no-room]
"""

from __future__ import annotations

import argparse
import math
import time

import numpy as np

from render import PLANT, WIDTH, HEIGHT, median_depth, plant_scene, psnr, severity_motion  # benchmarks/ is on sys.path

from spacedg.render import render
from spacedg.render.camera import Camera, look_at
from spacedg.render.gaussians import Gaussians
from spacedg.render.motion import _DISPLACEMENT_SAMPLE, MotionJob, motion_extent, render_motion_keyframes
from spacedg.render.settings import MotionBlur


def motion_parallax(gaussians: Gaussians, camera: Camera, motion: MotionBlur) -> float:
    """The previous rule's parallax P (pixels): ``f · |t_xy| · (1/z₁₀ − 1/z₉₀)`` over a strided
    sample of Gaussian means visible at mid-exposure, strided as motion_extent strides them (0 when fewer than 2)."""
    stride = max(1, len(gaussians) // _DISPLACEMENT_SAMPLE)
    uv, depth, ok = camera.project(gaussians.means[::stride].astype(np.float64))
    visible = ok & camera.in_image(uv) & (depth > 1e-3)
    if visible.sum() < 2:
        return 0.0
    near, far = np.percentile(depth[visible], [10.0, 90.0])
    return float(0.5 * (camera.fx + camera.fy) * math.hypot(motion.translation[0], motion.translation[1]) * (1.0 / near - 1.0 / far))


def previous_rule(displacement: float, parallax: float) -> int:
    """The keyframe count of stop 48 and before, from the path D and the parallax P (pixels)."""
    count = max(math.ceil(displacement / 90.0), 2 if displacement > 60.0 else 1, math.ceil(math.sqrt(max(parallax, 0.0) / 3.5)))
    return int(min(max(count, 1), 8))


def cases(factors: list[float], room: bool):
    g, camera = plant_scene()
    lo, hi = np.percentile(g.means, 0.5, axis=0), np.percentile(g.means, 99.5, axis=0)
    centre = 0.5 * (lo + hi)
    for factor in factors:
        pose = look_at(centre + factor * (camera.center - centre), centre, np.array([0.0, -1.0, 0.0]))
        yield f"plant x{factor:g}", g, camera.with_pose(pose)
    if room:
        from spacedg.scene.synthetic import generate_room

        scene = generate_room(0)
        names = sorted(scene.views)
        yield "room 0", scene.gaussians, scene.views[names[len(names) // 2]].resized(WIDTH, HEIGHT)


def timed(fns: dict, runs: int) -> dict[str, tuple[float, object]]:
    frames = {k: fn() for k, fn in fns.items()}  # warm-up (JIT)
    times: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(runs):
        for k, fn in fns.items():
            t0 = time.perf_counter()
            frames[k] = fn()
            times[k].append(time.perf_counter() - t0)
    return {k: (float(np.median(times[k])), frames[k]) for k in fns}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--factors", default="0.3,0.5")
    parser.add_argument("--seeds", default="1,2,3")
    parser.add_argument("--runs", type=int, default=2)
    parser.add_argument("--no-room", action="store_true")
    args = parser.parse_args()
    if not PLANT.is_file():
        raise SystemExit(f"the plant capture is not at {PLANT}")
    print(f"Motion blur on close-ups, {WIDTH}x{HEIGHT}, CPU; bench motion scaled by the view's median depth; "
          "dB vs N = 80 sub-steps; x clean = median time / median clean render time")
    print(f"{'scene':<12} {'seed':>4} {'path px':>7} {'parallax':>8} | {'K':>2} {'dB v80':>6} {'x clean':>7} | "
          f"{'old K':>5} {'dB v80':>6} {'x clean':>7}")
    worst, costs = math.inf, []
    for name, g, camera in cases([float(f) for f in args.factors.split(",")], not args.no_room):
        depth = median_depth(g, camera)
        for seed in (int(s) for s in args.seeds.split(",")):
            translation, rotation = severity_motion("bench", depth, seed=seed)
            motion = MotionBlur(translation, rotation, sub_steps=80, fast=True)
            job = MotionJob(g, camera, motion, frozenset({"rgb"}))
            reference = render(g, camera, motion=MotionBlur(translation, rotation, sub_steps=80), backend="cpu")
            path, _ = motion_extent(g, camera, motion)
            parallax = motion_parallax(g, camera, motion)
            old = previous_rule(path, parallax)
            out = timed({"clean": lambda: render(g, camera, backend="cpu"), "new": lambda: render_motion_keyframes(job),
                         "old": lambda: render_motion_keyframes(job, keyframes=old)}, args.runs)
            clean = out["clean"][0]
            new_db, old_db = psnr(out["new"][1].rgb, reference.rgb), psnr(out["old"][1].rgb, reference.rgb)
            worst = min(worst, new_db)
            costs.append(out["new"][0] / clean)
            print(f"{name:<12} {seed:>4} {path:>7.0f} {parallax:>8.1f} | "
                  f"{int(out['new'][1].stats['keyframes']):>2} {new_db:>6.2f} {out['new'][0] / clean:>7.2f} | "
                  f"{old:>5} {old_db:>6.2f} {out['old'][0] / clean:>7.2f}", flush=True)
    print(f"keyframe rule: worst {worst:.2f} dB vs N = 80, cost x clean median {np.median(costs):.2f}, max {max(costs):.2f}")


if __name__ == "__main__":
    main()
