"""Renderer speed and error: compiled CPU path vs torch path, and motion-blur sub-steps vs quality.

Prints tables only (never part of the test run). All renders are 640×480.

    .venv/bin/python benchmarks/render.py            # full run (a few minutes)
    .venv/bin/python benchmarks/render.py --quick    # 10k/100k scenes only (about a minute)
    .venv/bin/python benchmarks/render.py --torch-device cuda   # torch path on a GPU
    .venv/bin/python benchmarks/render.py --device cuda   # only the device table (gsplat backend vs gsplat's own, …)
    .venv/bin/python benchmarks/render.py --device cpu --sizes 10000   # the same code paths on a CPU (stand-ins)
    .venv/bin/python benchmarks/render.py --only severity --threads 1   # table 4 (about 4 minutes)
    .venv/bin/python benchmarks/render.py --only kernel --baseline main   # table 5: this checkout's CPU raster vs REV's

Timings are wall-clock (``time.perf_counter``) on whatever else the machine is doing: the
machine line prints the load average, run on an idle machine for numbers worth quoting.

1. Renderer: random scenes (10k / 100k / 300k Gaussians, seeded) and the real plant capture
   (``../shared/data/splats/plant``, skipped with a note when absent), each rendered by the
   compiled CPU path (median of 5 runs after a warm-up) and the torch path (median of 2
   runs after a warm-up; one run for 300k and under ``--quick``), with the largest and mean
   |Δ| between the two.
2. Motion blur on a built-in synthetic room (and on the plant): N = 80 reference, then fixed
   N sub-steps and the fast path, timed and scored by PSNR against the reference on the
   sRGB-encoded image clipped to [0, 1].
4. Motion blur by scene and severity (``--only severity``; two built-in rooms, the plant, two
   mesh-derived 10k objects; presets 1–4 and bench at their mid-range, plus "close" = 4× the
   bench motion): today's sub-step fast path beside the keyframe path — work, time × a clean
   render (alternating runs, medians), PSNR against N = 80 and N = 256, and a ghosting
   measure (:func:`ghosting`: the ripple of a probe point's smear). ``--threads 1`` for one
   numba thread.
5. CPU raster kernel, this checkout vs ``--baseline REV`` (``--only kernel``; default ``main``):
   REV's ``spacedg/render/raster_cpu.py`` is loaded from git beside this one and swapped in
   for the old renders; 100k random Gaussians and the plant at 1 numba thread and numba's
   default, old and new renders alternating (median of 11 each), rgb+alpha and all outputs:
   ms, speed-up, G Gaussian·pixel evaluations per second per thread (pairs * 256 / s /
   threads) and the mean |Δ| of rgb / alpha / depth between the two images (median depth and
   instance ids must match exactly). Then the stages alone on the same input: binning (depth
   sort + tiles) and compositing (rgb+alpha, all outputs), with "same" = bit-identical results.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import os
import platform
import time
from pathlib import Path
from typing import Callable

import numpy as np

from spacedg.scene.synthetic import generate_room
from spacedg.render.camera import Camera, look_at
from spacedg.render.colour import linear_to_srgb
from spacedg.render.frame import Frame
from spacedg.render.gaussians import Gaussians
from spacedg.render.renderer import render
from spacedg.render.settings import MotionBlur

from device_paths import print_table_head, random_scene  # noqa: E402 - benchmarks/ is on sys.path when run as a script

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "splats"
PLANT = SHARED / "plant" / "plant.splat"
WIDTH, HEIGHT, FOCAL = 640, 480, 500.0
TILE_PIXELS = 256
#: Camera motion over one exposure in the room (metres / radians, camera frame).
ROOM_MOTION = ((0.25, 0.05, 0.10), (0.02, 0.08, 0.01))
#: The plant is ~1 COLMAP unit tall and seen from ~1.5 units: a quarter of the room's
#: translation (same rotation) gives a comparable on-screen sweep.
PLANT_MOTION = ((0.0625, 0.0125, 0.025), (0.02, 0.08, 0.01))


# ------------------------------------------------------------------ scenes and cameras
def intrinsics(pose: np.ndarray) -> Camera:
    return Camera(FOCAL, FOCAL, WIDTH / 2, HEIGHT / 2, WIDTH, HEIGHT, pose)


def plant_scene() -> tuple[Gaussians, Camera]:
    """The plant capture, seen slightly from above (its up axis is -y) so it fills most of the frame."""
    from spacedg.scene.io import read_splat

    g = read_splat(PLANT)
    lo, hi = np.percentile(g.means, 0.5, axis=0), np.percentile(g.means, 99.5, axis=0)
    centre, extent = 0.5 * (lo + hi), hi - lo
    up = np.array([0.0, -1.0, 0.0])
    direction = np.array([0.0, -0.25, 1.0])
    direction /= np.linalg.norm(direction)
    # Object height spans ~90 % of the image height at the near face of its box.
    distance = 0.5 * extent[1] * FOCAL / (0.45 * HEIGHT) + 0.5 * extent[2]
    return g, intrinsics(look_at(centre + distance * direction, centre, up))


# ------------------------------------------------------------------ measuring
def timed(fn: Callable[[], Frame], runs: int, warmup: int = 1) -> tuple[float, Frame]:
    """Median wall time (s) of ``runs`` calls after ``warmup`` untimed ones, and the last frame."""
    frame = None
    for _ in range(warmup):
        frame = fn()
    times = []
    for _ in range(runs):
        start = time.perf_counter()
        frame = fn()
        times.append(time.perf_counter() - start)
    assert frame is not None
    return float(np.median(times)), frame


def encoded(rgb: np.ndarray) -> np.ndarray:
    return np.clip(linear_to_srgb(rgb.astype(np.float64)), 0.0, 1.0)


def psnr(image: np.ndarray, reference: np.ndarray) -> float:
    mse = float(np.mean((encoded(image) - encoded(reference)) ** 2))
    return math.inf if mse == 0.0 else 10.0 * math.log10(1.0 / mse)


def fmt_db(value: float) -> str:
    return "inf" if math.isinf(value) else f"{value:.2f}"


def machine_line(torch_device: str) -> str:
    import numba
    import torch

    return (
        f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"numba threads {numba.get_num_threads()}, torch {torch.__version__} "
        f"({torch.get_num_threads()} threads), torch path on {torch_device}, numpy {np.__version__}, "
        f"load average {os.getloadavg()[0]:.2f}"
    )


# ------------------------------------------------------------------ tables
def renderer_table(sizes: list[int], degree: int, with_plant: bool, torch_device: str, torch_runs: int) -> None:
    print(f"\n1. Renderer, {WIDTH}x{HEIGHT}: compiled CPU path (median of 5 after 1 warm-up) vs torch path "
          f"({f'median of {torch_runs}' if torch_runs > 1 else '1 run'} after 1 warm-up; 1 run for >= 300k)")
    print("   speed-up = torch ms / cpu ms (how many times faster the compiled path is).")
    print("   Gpix/s = Gaussian-pixel evaluations per second of the compiled path, counted as 256 pixels per "
          "composited Gaussian-tile pair: pairs * 256 / seconds.")
    print_table_head(
        "   |Δ| = absolute difference between the two paths' linear rgb / alpha, max and mean over pixels.",
        columns=(f"{'scene':<22} {'visible':>8} {'pairs':>9} {'cpu ms':>8} {'torch ms':>9} {'speed-up':>8} {'Gpix/s':>7} "
                 f"{'rgb max|Δ|':>10} {'rgb mean|Δ|':>11} {'a max|Δ|':>9} {'a mean|Δ|':>9}"),
    )
    cases: list[tuple[str, Callable[[], tuple[Gaussians, Camera]]]] = [
        (f"random {n // 1000}k, SH {degree}", lambda n=n: random_scene(n, seed=n, degree=degree)) for n in sizes
    ]
    if with_plant:
        if PLANT.is_file():
            cases.append(("plant capture 114k", plant_scene))
        else:
            print(f"(plant capture skipped: {PLANT} not found)")
    for name, make in cases:
        g, cam = make()
        t_cpu, f_cpu = timed(lambda: render(g, cam, outputs="rgb,alpha", backend="cpu"), runs=5)
        pairs = int(f_cpu.stats["pairs"])
        runs = 1 if len(g) >= 300_000 else torch_runs
        t_torch, f_torch = timed(lambda: render(g, cam, outputs="rgb,alpha", backend="torch", device=torch_device), runs=runs)
        d_rgb = np.abs(f_cpu.rgb.astype(np.float64) - f_torch.rgb)
        d_a = np.abs(f_cpu.alpha.astype(np.float64) - f_torch.alpha)
        print(f"{name:<22} {int(f_cpu.stats['visible']):>8} {pairs:>9} {t_cpu * 1e3:>8.1f} "
              f"{t_torch * 1e3:>9.1f} {t_torch / t_cpu:>7.1f}x {pairs * TILE_PIXELS / t_cpu / 1e9:>7.2f} "
              f"{d_rgb.max():>10.2e} {d_rgb.mean():>11.2e} {d_a.max():>9.2e} {d_a.mean():>9.2e}", flush=True)


def motion_table(title: str, g: Gaussians, cam: Camera, motion: tuple, counts: list[int]) -> None:
    translation, rotation = motion
    t_clean, clean = timed(lambda: render(g, cam, backend="cpu"), runs=5)
    t0 = time.perf_counter()
    reference = render(g, cam, motion=MotionBlur(translation, rotation, sub_steps=80), backend="cpu")
    t_ref = time.perf_counter() - t0
    print(f"\n{title}")
    print(f"   motion: translation {translation} , rotation {rotation} rad (camera frame); compiled CPU path")
    print(f"   clean render {t_clean * 1e3:.1f} ms (median of 5), {int(clean.stats['visible'])} visible, "
          f"{int(clean.stats['pairs'])} pairs; N = 80 reference took {t_ref * 1e3:.0f} ms")
    print("   time: median of 3 runs for N <= 8 and the fast path, else 1 run; "
          "PSNR vs N = 80 on clip(linear_to_srgb(rgb), 0, 1)")
    print_table_head(
        columns=f"{'sub-steps':<14} {'chosen N':>8} {'ms':>9} {'x clean':>8} {'PSNR dB':>8} {'max disp px':>11}",
    )
    rows: list[tuple[str, MotionBlur]] = [(f"N = {n}", MotionBlur(translation, rotation, sub_steps=n)) for n in counts]
    rows.append(("fast (<= 80)", MotionBlur(translation, rotation, sub_steps=80, fast=True)))
    for label, blur in rows:
        runs = 3 if blur.fast or blur.sub_steps <= 8 else 1
        t, frame = timed(lambda blur=blur: render(g, cam, motion=blur, backend="cpu"), runs=runs, warmup=0)
        disp = frame.stats.get("displacement_px", math.nan)
        disp_s = "-" if math.isnan(disp) else f"{disp:.1f}"
        print(f"{label:<14} {int(frame.stats['sub_steps']):>8} {t * 1e3:>9.1f} {t / t_clean:>8.1f} "
              f"{fmt_db(psnr(frame.rgb, reference.rgb)):>8} {disp_s:>11}", flush=True)


# ------------------------------------------------------------------ motion blur by severity (keyframes vs sub-steps)
def object_scene(path: Path, distance_scale: float = 1.0) -> tuple[Gaussians, Camera]:
    """A mesh-derived splat object (longest axis 2 units, up -y unknown: seen along +z), filling ~90 % of the frame."""
    from spacedg.scene.io import read_splat

    g = read_splat(path)
    lo, hi = np.percentile(g.means, 0.5, axis=0), np.percentile(g.means, 99.5, axis=0)
    centre, extent = 0.5 * (lo + hi), hi - lo
    direction = np.array([0.3, -0.3, 1.0])
    direction /= np.linalg.norm(direction)
    distance = distance_scale * (0.5 * float(extent.max()) * FOCAL / (0.45 * HEIGHT) + 0.5 * float(extent.max()))
    return g, intrinsics(look_at(centre + distance * direction, centre, np.array([0.0, -1.0, 0.0])))


def median_depth(g: Gaussians, cam: Camera) -> float:
    frame = render(g, cam, outputs="depth,alpha", backend="cpu")
    covered = frame.alpha > 0.5
    return float(np.median(frame.depth[covered])) if covered.any() else 1.0


def severity_motion(severity: str, depth_m: float, seed: int, scale: float = 1.0) -> tuple[tuple, tuple]:
    """The motion-blur preset's mid-range ``trans`` (scaled by the scene depth as the plugin does)
    and ``rot`` along fixed random directions (``seed``); ``scale`` multiplies both (close-ups)."""
    from spacedg.plugins.degradations.motion_blur import SPEC, random_unit_vector
    from spacedg.plugins.specs import REFERENCE_DEPTH_M

    preset = SPEC.presets[severity]
    trans = 0.5 * (preset["trans"].low + preset["trans"].high) * depth_m / REFERENCE_DEPTH_M * scale
    rot = min(0.5 * (preset["rot"].low + preset["rot"].high) * scale, math.pi)
    rng = np.random.default_rng(seed)
    direction, axis = random_unit_vector(rng), random_unit_vector(rng)
    return tuple(trans * direction), tuple(rot * axis)


def ghosting(g: Gaussians, cam: Camera, translation: tuple, rotation: tuple, depth_m: float, method: str, work: int) -> float:
    """Ghosting (%) of a method on a probe: one small bright Gaussian (σ = 1.5 px on screen) on the
    optical axis at the scene's median depth, rendered alone with the same motion and the same
    work (``N`` sub-steps, or ``K`` keyframes). Its smear is read (alpha, bilinear) along its
    exact on-screen path (400 points over the exposure) where it is at least 4.5 px (3 σ) from
    either end (``nan`` when the path is under 15 px), divided by its
    linear trend (zoom and speed change slowly): ``ghost = 100 · (1 − min / max)``. The
    bilinear read-out itself leaves ~4 % (N = 256 scores 3–5 %). A continuous smear is flat (≈ 0); stroboscopic copies
    leave gaps between them (→ 100 when the copies do not touch)."""
    from scipy.ndimage import map_coordinates

    from spacedg.render.camera import exposure_poses
    from spacedg.render.motion import MotionJob, render_motion_keyframes, render_motion_substeps

    point = cam.center + depth_m * cam.forward
    size = 1.5 * depth_m / cam.fx
    probe = Gaussians(point[None], [[1.0, 0, 0, 0]], [[size, size, size]], [0.9], np.ones((1, 1, 3)))
    blur = MotionBlur(translation, rotation, sub_steps=work, fast=True)
    job = MotionJob(probe, cam, blur, frozenset({"rgb"}))
    if method == "sub":
        frame = render_motion_substeps(job, fast=False)
    else:
        frame = render_motion_keyframes(job, keyframes=work)
    poses = exposure_poses(cam, np.array(translation), np.array(rotation), np.linspace(-0.5, 0.5, 400))
    uv = np.array([cam.with_pose(p).project(point[None])[0][0] for p in poses])
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(uv, axis=0), axis=1))])
    # away from the smear's ends by 3 σ of the probe (its own width rounds them)
    inside = (arc >= 4.5) & (arc <= arc[-1] - 4.5)
    inside &= (uv[:, 0] > 2) & (uv[:, 0] < cam.width - 2) & (uv[:, 1] > 2) & (uv[:, 1] < cam.height - 2)
    if arc[-1] < 15.0 or inside.sum() < 10:
        return math.nan  # too short a smear to tell copies from its ends
    values = map_coordinates(frame.alpha.astype(np.float64), [uv[inside, 1] - 0.5, uv[inside, 0] - 0.5], order=1)
    t = np.arange(values.size, dtype=np.float64)
    values = values / np.maximum(np.polyval(np.polyfit(t, values, 1), t), 1e-12)  # a slow trend (zoom, speed) is no ghost
    return float(100.0 * (1.0 - values.min() / max(values.max(), 1e-12)))


def motion_severity_table(cases: list[tuple[str, Gaussians, Camera, list[tuple[str, float]]]], runs: int) -> None:
    from spacedg.render.motion import MotionJob, render_motion_keyframes, render_motion_substeps

    rgb = frozenset({"rgb"})
    print("\n4. Motion blur by scene and severity, 640x480, compiled CPU path: today's sub-step fast path vs the keyframe path")
    print("   motion: the motion_blur preset's mid-range trans (scaled by the view's median depth / 2.5 m, as the plugin "
          "does) and rot, along fixed random directions; 'close' = 4x the bench motion (paths of hundreds of pixels)")
    print(f"   time: median of {runs} runs, alternating with clean renders (x clean = median / median clean); "
          "PSNR on clip(linear_to_srgb(rgb), 0, 1) against N = 80 and N = 256 sub-steps")
    print("   work: renders made (N = sub-steps; K = keyframes, each on a canvas widened by the path, plus the gathers)")
    print("   ghost % = 100 * (1 - min/max) of the smear of a probe point (sigma 1.5 px, on the optical axis at the scene's "
          "median depth) rendered alone with the same motion and work, read along its exact path >= 4.5 px from its "
          "ends, over its linear trend (nan: path < 15 px) (read-out floor ~4 %): 0 = continuous smear, 100 = separate copies (N = 80's own value in the last column)")
    print_table_head(
        columns=(f"{'scene':<16} {'sev':<5} {'path px':>7} {'clean ms':>8} | {'sub-step work':>13} {'x clean':>7} {'dB v80':>6} "
                 f"{'dB v256':>7} {'ghost%':>6} | {'keyframe work':>13} {'x clean':>7} {'dB v80':>6} {'dB v256':>7} {'ghost%':>6} "
                 f"| {'N80 ghost%':>10}"),
    )
    summary: list[tuple[float, float, float]] = []
    for name, g, cam, severities in cases:
        depth = median_depth(g, cam)
        for severity, scale in severities:
            translation, rotation = severity_motion(severity if severity != "close" else "bench", depth, seed=7, scale=scale)
            job = MotionJob(g, cam, MotionBlur(translation, rotation, sub_steps=80, fast=True), rgb)
            ref80 = render(g, cam, motion=MotionBlur(translation, rotation, sub_steps=80), backend="cpu")
            ref256 = render(g, cam, motion=MotionBlur(translation, rotation, sub_steps=256), backend="cpu")
            fns = {
                "clean": lambda: render(g, cam, backend="cpu"),
                "sub": lambda: render_motion_substeps(job, fast=True),
                "key": lambda: render_motion_keyframes(job),
            }
            times: dict[str, list[float]] = {k: [] for k in fns}
            frames: dict[str, Frame] = {}
            for k, fn in fns.items():  # warm-up (JIT)
                frames[k] = fn()
            for _ in range(runs):
                for k, fn in fns.items():
                    t0 = time.perf_counter()
                    frames[k] = fn()
                    times[k].append(time.perf_counter() - t0)
            t_clean = float(np.median(times["clean"]))
            cells = []
            for k in ("sub", "key"):
                f = frames[k]
                work = f"N = {int(f.stats['sub_steps'])}" if k == "sub" else f"K = {int(f.stats['keyframes'])}"
                ratio = float(np.median(times[k])) / t_clean
                used = int(f.stats["sub_steps"]) if k == "sub" else int(f.stats["keyframes"])
                p80, p256 = psnr(f.rgb, ref80.rgb), psnr(f.rgb, ref256.rgb)
                gh = ghosting(g, cam, translation, rotation, depth, k, used)
                cells.append(f"{work:>13} {ratio:>7.2f} {fmt_db(p80):>6} {fmt_db(p256):>7} {gh:>6.2f}")
                if k == "key":
                    summary.append((ratio, p80, p256))
            path = float(frames["key"].stats["displacement_px"])
            print(f"{name:<16} {severity:<5} {path:>7.0f} {t_clean * 1e3:>8.1f} | {cells[0]} | {cells[1]} | "
                  f"{ghosting(g, cam, translation, rotation, depth, 'sub', 80):>10.2f}", flush=True)
    if summary:
        arr = np.array(summary)
        print(f"keyframe path over {len(summary)} cases: x clean median {np.median(arr[:, 0]):.2f}, max {arr[:, 0].max():.2f}; "
              f"dB vs N=80 min {arr[:, 1].min():.2f}; dB vs N=256 min {arr[:, 2].min():.2f}")


def severity_section(room_seed: int, quick: bool) -> None:
    severities = [("1", 1.0), ("3", 1.0), ("bench", 1.0)] if quick else [("1", 1.0), ("2", 1.0), ("3", 1.0), ("4", 1.0), ("bench", 1.0)]
    cases = []
    for seed in ([room_seed] if quick else [room_seed, room_seed + 1]):
        room = generate_room(seed)
        names = sorted(room.views)
        cases.append((f"room {seed}", room.gaussians, room.views[names[len(names) // 2]].resized(WIDTH, HEIGHT), severities))
    if PLANT.is_file():
        g, cam = plant_scene()
        cases.append(("plant", g, cam, severities + [("close", 4.0)]))
        for name in ("teapot", "cat") if not quick else ("teapot",):
            path = SHARED / name / f"{name}_10k.splat"
            if path.is_file():
                g, cam = object_scene(path)
                cases.append((f"{name} 10k", g, cam, [("1", 1.0), ("bench", 1.0), ("close", 4.0)]))
    else:
        print(f"\n(plant and mesh objects skipped: {SHARED} not found)")
    motion_severity_table(cases, runs=3)


def load_baseline_raster(rev: str):
    """REV's ``spacedg/render/raster_cpu.py`` as a separate module (compiled into a temporary cache)."""
    import importlib.util
    import subprocess
    import sys
    import tempfile

    root = Path(__file__).resolve().parents[1]
    source = subprocess.run(["git", "show", f"{rev}:spacedg/render/raster_cpu.py"], cwd=root, check=True,
                            capture_output=True, text=True).stdout
    commit = subprocess.run(["git", "rev-parse", "--short", rev], cwd=root, check=True,
                            capture_output=True, text=True).stdout.strip()
    folder = Path(tempfile.gettempdir()) / f"spacedg_baseline_{commit}"
    folder.mkdir(exist_ok=True)
    path = folder / "baseline_raster_cpu.py"
    if not path.is_file() or path.read_text() != source:
        path.write_text(source)
    spec = importlib.util.spec_from_file_location("baseline_raster_cpu", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules["baseline_raster_cpu"] = module  # numba's cache pickles refer to the module by name
    spec.loader.exec_module(module)
    return module, commit


def kernel_table(rev: str) -> None:
    import numba

    from spacedg.render import raster_cpu

    old, commit = load_baseline_raster(rev)
    new_rasterize = raster_cpu.rasterize
    default_threads = int(numba.config.NUMBA_NUM_THREADS)
    print(f"\n5. CPU raster kernel, {WIDTH}x{HEIGHT}: this checkout (new) vs {rev} = {commit} (old), whole render() "
          "with the same projection; old/new alternating, median of 11 each after a warm-up")
    print("   Gev/s/thr = Gaussian-pixel evaluations per second per numba thread: pairs * 256 / s / threads.")
    print("   mean|Δ| = mean absolute difference of the new image from the old (rgb, alpha, depth); "
          "ids = median depth and instance ids identical.")
    print_table_head(
        columns=(f"{'scene':<11} {'outputs':<9} {'thr':>3} {'pairs':>7} {'old ms':>7} {'new ms':>7} {'x':>5} "
                 f"{'old Gev/s/thr':>13} {'new Gev/s/thr':>13} {'rgb mean|Δ|':>11} {'a mean|Δ|':>9} {'d mean|Δ|':>9} {'ids':>4}"),
    )
    cases = [("random 100k", lambda: random_scene(100_000, seed=100_000, degree=1))]
    if PLANT.is_file():
        cases.append(("plant 114k", plant_scene))
    else:
        print(f"(plant capture skipped: {PLANT} not found)")

    def run(g: Gaussians, cam: Camera, outputs: str, module) -> Frame:
        raster_cpu.rasterize = module.rasterize
        try:
            return render(g, cam, outputs=outputs, backend="cpu")
        finally:
            raster_cpu.rasterize = new_rasterize

    for name, make in cases:
        g, cam = make()
        g = dataclasses.replace(g, instance_ids=(np.arange(len(g)) % 13).astype(np.int32))
        for outputs, label in (("rgb,alpha", "rgb"), ("rgb,alpha,depth,median_depth,instance_ids", "all")):
            for threads in sorted({1, default_threads}):
                numba.set_num_threads(threads)
                f_old, f_new = run(g, cam, outputs, old), run(g, cam, outputs, raster_cpu)
                t_old, t_new = [], []
                for _ in range(11):
                    start = time.perf_counter()
                    run(g, cam, outputs, old)
                    t_old.append(time.perf_counter() - start)
                    start = time.perf_counter()
                    run(g, cam, outputs, raster_cpu)
                    t_new.append(time.perf_counter() - start)
                to, tn = float(np.median(t_old)), float(np.median(t_new))
                pairs = int(f_new.stats["pairs"])

                def mean_diff(a: np.ndarray | None, b: np.ndarray | None) -> str:
                    return "-" if a is None or b is None else f"{np.abs(a.astype(np.float64) - b).mean():.1e}"

                same = "-" if label == "rgb" else (
                    "yes" if np.array_equal(f_old.instance_ids, f_new.instance_ids)
                    and np.array_equal(f_old.median_depth, f_new.median_depth) else "NO")
                print(f"{name:<11} {label:<9} {threads:>3} {pairs:>7} {to * 1e3:>7.1f} {tn * 1e3:>7.1f} {to / tn:>4.2f}x "
                      f"{pairs * TILE_PIXELS / to / threads / 1e9:>13.2f} {pairs * TILE_PIXELS / tn / threads / 1e9:>13.2f} "
                      f"{mean_diff(f_old.rgb, f_new.rgb):>11} {mean_diff(f_old.alpha, f_new.alpha):>9} "
                      f"{mean_diff(f_old.depth, f_new.depth):>9} {same:>4}", flush=True)
        numba.set_num_threads(default_threads)
    stage_table(cases, old, default_threads)


def stage_table(cases: list, old, default_threads: int) -> None:
    """The stages of one render alone, old vs new on the same input: binning (sort + bin) and compositing."""
    import numba

    from spacedg.render.settings import RasterSettings

    settings = RasterSettings()
    print("\n   stages alone (same projection; binning = depth sort + tile binning; compositing on the same "
          "tile lists; rgb+alpha / all outputs), old/new alternating, median of 11:")
    print_table_head(
        columns=(f"{'scene':<11} {'stage':<15} {'thr':>3} {'old ms':>7} {'new ms':>7} {'x':>5} "
                 f"{'old Gev/s/thr':>13} {'new Gev/s/thr':>13} {'same':>5}"),
    )
    for name, make in cases:
        stage_rows(name, *make(), old, default_threads, settings)
    numba.set_num_threads(default_threads)


def stage_rows(name: str, g: Gaussians, cam: Camera, old, default_threads: int, settings) -> None:
    """One scene's rows of :func:`stage_table`."""
    import numba

    from spacedg.render import project_cpu, raster_cpu

    ids = (np.arange(len(g)) % 13).astype(np.int32)
    w, h = cam.width, cam.height
    packed, rects = project_cpu.project_gaussians(g, cam, settings)
    offsets, gauss = raster_cpu.bin_visible(packed, rects, w, h, True)
    pairs = gauss.shape[0]

    def binning(module):
        return module.bin_visible(packed, rects, w, h, True)

    def compositing(module, flags):
        shape = (h, w)
        out = [np.zeros((*shape, 3), np.float32), np.zeros(shape, np.float32), np.zeros(shape, np.float32),
               np.zeros(shape, np.float32), np.full(shape, -1, np.int32)]
        module.composite(offsets, gauss, packed, ids, w, h, (w + 15) // 16, settings.alpha_max, *flags, *out)
        return out

    stages = [("binning", binning),
              ("composite rgb", lambda m: compositing(m, (True, False, False))),
              ("composite all", lambda m: compositing(m, (True, True, True)))]
    for stage, fn in stages:
        for threads in sorted({1, default_threads}):
            numba.set_num_threads(threads)
            a, b = fn(old), fn(raster_cpu)
            same = all(np.array_equal(x, y) for x, y in zip(a, b))
            t_old, t_new = [], []
            for _ in range(11):
                start = time.perf_counter()
                fn(old)
                t_old.append(time.perf_counter() - start)
                start = time.perf_counter()
                fn(raster_cpu)
                t_new.append(time.perf_counter() - start)
            to, tn = float(np.median(t_old)), float(np.median(t_new))
            print(f"{name:<11} {stage:<15} {threads:>3} {to * 1e3:>7.1f} {tn * 1e3:>7.1f} {to / tn:>4.2f}x "
                  f"{pairs * TILE_PIXELS / to / threads / 1e9:>13.2f} {pairs * TILE_PIXELS / tn / threads / 1e9:>13.2f} "
                  f"{'yes' if same else 'NO':>5}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true",
                        help="10k/100k scenes only (no 300k), one timed torch run, fewer plant motion rows (about a minute)")
    parser.add_argument("--torch-device", default="cpu", help="torch device for the torch path (default cpu)")
    parser.add_argument("--room-seed", type=int, default=0, help="seed of the synthetic room (default 0)")
    parser.add_argument("--device", default=None,
                        help="run only the device table (benchmarks/device_paths.py): our gsplat backend vs "
                             "gsplat.rasterization vs our torch backend on this device vs our CPU path")
    parser.add_argument("--sizes", default="100000,1000000", help="Gaussian counts of the device table (default 100000,1000000)")
    parser.add_argument("--runs", type=int, default=5, help="timed runs per cell of the device table (default 5)")
    parser.add_argument("--only", choices=["renderer", "motion", "severity", "kernel"], default=None,
                        help="run one part: renderer (table 1), motion (tables 2-3), severity (table 4) or "
                             "kernel (table 5, this checkout's CPU raster vs --baseline)")
    parser.add_argument("--baseline", default="main",
                        help="git revision whose raster_cpu.py table 5 compares against (default main)")
    parser.add_argument("--threads", type=int, default=None, help="numba threads (default: numba's)")
    args = parser.parse_args()
    if args.threads:
        import numba

        numba.set_num_threads(args.threads)
    if args.device is not None:
        import device_paths

        if device_paths.device_ready(args.device):
            device_paths.render_table(args.device, [int(v) for v in args.sizes.split(",")], args.runs)
        return

    print(machine_line(args.torch_device))
    start = time.perf_counter()
    sizes = [10_000, 100_000] if args.quick else [10_000, 100_000, 300_000]
    if args.only in (None, "renderer"):
        renderer_table(sizes, degree=1, with_plant=True, torch_device=args.torch_device, torch_runs=1 if args.quick else 2)
    if args.only in (None, "severity"):
        severity_section(args.room_seed, args.quick)
    if args.only in (None, "kernel"):
        kernel_table(args.baseline)
    if args.only not in (None, "motion"):
        print(f"\ntotal {time.perf_counter() - start:.0f} s")
        return

    room = generate_room(args.room_seed)
    names = sorted(room.views)
    view = names[len(names) // 2]
    counts = [1, 4, 8, 16, 32, 80]
    motion_table(f"2. Motion blur, synthetic room seed {args.room_seed} ({len(room.gaussians)} Gaussians), view {view}, "
                 f"{WIDTH}x{HEIGHT}", room.gaussians, room.views[view].resized(WIDTH, HEIGHT), ROOM_MOTION, counts)
    if PLANT.is_file():
        g, cam = plant_scene()
        motion_table(f"3. Motion blur, plant capture ({len(g)} Gaussians), {WIDTH}x{HEIGHT}", g, cam, PLANT_MOTION,
                     [1, 4, 16, 80] if args.quick else counts)
    else:
        print(f"\n(plant motion blur skipped: {PLANT} not found)")
    print(f"\ntotal {time.perf_counter() - start:.0f} s")


if __name__ == "__main__":
    main()
