"""Clean CPU render speed by stage, this checkout vs an older commit, with the error between them.

Issue 31 item 3: "the whole render at least 1.5x faster than before the last kernel work on 100k
Gaussians at 640x480, one thread". The old commit (default ``ef144fe``, the parent of the first
raster-kernel commit 385742e) is checked out as a git worktree under the temp folder; each side
runs in its own subprocess with ``NUMBA_NUM_THREADS`` set (default 1) and ``PYTHONPATH`` pointing at
its checkout, on the same scenes (built here once, saved to an ``.npz``; the plant is read from
``../shared/data/splats/plant`` at run time and skipped when absent).

    .venv/bin/python benchmarks/render_speed.py                  # 100k random, rooms 0 and 1, plant; 1 thread
    .venv/bin/python benchmarks/render_speed.py --runs 9 --old ef144fe --threads 1

Stages are timed by wrapping the module functions the render calls (``project_cpu.project_gaussians``,
``raster_cpu.bin_visible`` = depth sort + tile binning / pair generation, ``raster_cpu.composite``;
"other" = the rest of ``render()``: sRGB decode, output allocation, the Frame). Each cell is the
fastest of ``--rounds`` × ``--runs`` renders (each round one subprocess per side after a warm-up,
old and new alternating; on a loaded machine the minimum is the steadiest estimate). The error
columns compare the new render with the old one (all outputs): max |Δ| of linear rgb, alpha,
expected depth and median depth, and the count of pixels whose instance id differs.
Timings are wall-clock on whatever the machine is doing: read the ratios, measured in one run.

Vector width: this checkout asks numba for 512-bit vectors on AVX-512 hosts
(:mod:`spacedg.render.cpu_target`); a checkout from before that runs at numba's default (256-bit
on Intel's AVX-512 server cores). The header line says which each side used. ``--old-vectors full``
gives the old side the same setting (the kernel work alone); ``--old HEAD --old-vectors default``
compares this checkout with itself at numba's default width (the setting alone, and its error).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
STAGES = ("project", "bin", "composite", "other", "total")


# ------------------------------------------------------------------ scenes (driver side, this checkout)
def build_scenes(path: Path, with_plant: bool, rooms: list[int]) -> list[str]:
    """Save the benchmark scenes (Gaussians + camera) to ``path``; returns their names."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from device_paths import random_scene  # noqa: E402

    from spacedg.scene.synthetic import generate_room

    scenes = {}
    g, cam = random_scene(100_000, seed=100_000, degree=1)
    scenes["random100k"] = (g, cam, (np.arange(len(g)) % 13).astype(np.int32))
    for seed in rooms:  # built-in rooms, their middle view
        room = generate_room(seed)
        names = sorted(room.views)
        rcam = room.views[names[len(names) // 2]].resized(640, 480)
        scenes[f"room{seed}"] = (room.gaussians, rcam, room.gaussians.instance_ids)
    if with_plant:
        import render as render_bench  # benchmarks/render.py

        if render_bench.PLANT.is_file():
            pg, pcam = render_bench.plant_scene()
            scenes["plant"] = (pg, pcam, (np.arange(len(pg)) % 13).astype(np.int32))
    arrays = {}
    for name, (g, cam, ids) in scenes.items():
        for field in ("means", "quats", "scales", "opacities", "sh"):
            arrays[f"{name}/{field}"] = np.asarray(getattr(g, field))
        arrays[f"{name}/ids"] = np.asarray(ids if ids is not None else np.full(len(g), -1), np.int32)
        arrays[f"{name}/cam"] = np.array([cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height], np.float64)
        arrays[f"{name}/pose"] = np.asarray(cam.cam_to_world, np.float64)
    np.savez(path, **arrays)
    return list(scenes)


# ------------------------------------------------------------------ worker (runs in either checkout)
def _wrap(module, name: str, acc: dict, key: str) -> None:
    fn = getattr(module, name)

    def timed(*args, **kwargs):
        start = time.perf_counter()
        try:
            return fn(*args, **kwargs)
        finally:
            acc[key] = acc.get(key, 0.0) + time.perf_counter() - start

    setattr(module, name, timed)


def worker(scene_file: str, names: list[str], runs: int, out_file: str) -> None:
    """Time every scene's clean rgb render by stage and save its all-output images."""
    import dataclasses

    from spacedg.render import project_cpu, raster_cpu
    from spacedg.render.camera import Camera
    from spacedg.render.gaussians import Gaussians
    from spacedg.render.renderer import render

    import numba.core.registry

    data = np.load(scene_file)
    acc: dict = {}
    _wrap(project_cpu, "project_gaussians", acc, "project")
    _wrap(raster_cpu, "bin_visible", acc, "bin")
    _wrap(raster_cpu, "composite", acc, "composite")
    result, images = {}, {}
    for name in names:
        fx, fy, cx, cy, w, h = data[f"{name}/cam"]
        cam = Camera(fx, fy, cx, cy, int(w), int(h), data[f"{name}/pose"])
        g = Gaussians(*(data[f"{name}/{f}"] for f in ("means", "quats", "scales", "opacities", "sh")))
        g = dataclasses.replace(g, instance_ids=data[f"{name}/ids"])
        for outputs, label in (("rgb", "rgb"), ("all", "all")):
            render(g, cam, outputs=outputs, backend="cpu")  # warm-up (compiles or loads the caches)
            rows = []
            for _ in range(runs):
                acc.clear()
                start = time.perf_counter()
                frame = render(g, cam, outputs=outputs, backend="cpu")
                total = time.perf_counter() - start
                rows.append([acc.get("project", 0.0), acc.get("bin", 0.0), acc.get("composite", 0.0),
                             total - sum(acc.values()), total])
            result[f"{name}/{label}"] = np.array(rows).tolist()
            result[f"{name}/{label}/pairs"] = int(frame.stats.get("pairs", -1))
        for plane in ("rgb", "alpha", "depth", "median_depth", "instance_ids"):
            images[f"{name}/{plane}"] = getattr(frame, plane)
    np.savez(out_file, **images)
    features = numba.core.registry.cpu_target.target_context.codegen()._tm_features.split(",")  # what it compiled with
    result["vectors"] = "512-bit" if "-prefer-256-bit" in features and "+avx512f" in features else "numba's default"
    Path(out_file + ".json").write_text(json.dumps(result))


# ------------------------------------------------------------------ driver
def checkout(rev: str) -> Path:
    """A worktree of ``rev`` under the temp folder (made once)."""
    commit = subprocess.run(["git", "rev-parse", "--short", rev], cwd=ROOT, check=True, capture_output=True,
                            text=True).stdout.strip()
    path = Path(tempfile.gettempdir()) / f"spacedg_render_speed_{commit}"
    if not (path / "spacedg").is_dir():
        subprocess.run(["git", "worktree", "add", "--detach", str(path), commit], cwd=ROOT, check=True,
                       capture_output=True)
    return path


def run_side(src: Path, scene_file: Path, names: list[str], runs: int, threads: int, out: Path, vectors: str = "auto") -> dict:
    """One side's timings and images, in a subprocess of its checkout. ``vectors``: ``auto`` (what
    the checkout sets), ``default`` (numba's host features: 256-bit on Intel's AVX-512 servers) or
    ``full`` (what :mod:`spacedg.render.cpu_target` sets: 512-bit on AVX-512 hosts)."""
    env = dict(os.environ, PYTHONPATH=str(src), NUMBA_NUM_THREADS=str(threads))
    if vectors != "auto":  # numba's own setting, which spacedg leaves alone when it is given
        from numba.core.codegen import get_host_cpu_features

        env["NUMBA_CPU_FEATURES"] = get_host_cpu_features() + (",-prefer-256-bit" if vectors == "full" else "")
    cmd = [sys.executable, str(Path(__file__).resolve()), "--worker", str(scene_file), "--names", ",".join(names),
           "--runs", str(runs), "--out", str(out)]
    subprocess.run(cmd, env=env, check=True, cwd=str(src))
    return json.loads(Path(str(out) + ".json").read_text())


def errors(old: np.lib.npyio.NpzFile, new: np.lib.npyio.NpzFile, name: str) -> str:
    def mx(plane: str) -> float:
        return float(np.abs(old[f"{name}/{plane}"].astype(np.float64) - new[f"{name}/{plane}"]).max())

    ids = int(np.count_nonzero(old[f"{name}/instance_ids"] != new[f"{name}/instance_ids"]))
    return (f"{mx('rgb'):>9.1e} {mx('alpha'):>9.1e} {mx('depth'):>9.1e} {mx('median_depth'):>9.1e} {ids:>7d}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", default="ef144fe", help="the baseline commit (default ef144fe, before the kernel work)")
    parser.add_argument("--runs", type=int, default=5, help="timed renders per cell and round (default 5)")
    parser.add_argument("--rounds", type=int, default=2, help="old/new subprocess rounds, alternating (default 2)")
    parser.add_argument("--threads", type=int, default=1, help="numba threads (default 1)")
    parser.add_argument("--rooms", default="0,1", help="seeds of the built-in rooms (default 0,1)")
    parser.add_argument("--no-plant", action="store_true", help="skip the shared plant capture")
    parser.add_argument("--old-vectors", choices=("auto", "default", "full"), default="auto",
                        help="the old side's numba vectors: what its checkout sets (auto), numba's default, or the 512-bit "
                             "setting of spacedg.render.cpu_target (full); with --old HEAD and default: the setting alone")
    parser.add_argument("--worker", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--names", default="", help=argparse.SUPPRESS)
    parser.add_argument("--out", default="", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        worker(args.worker, args.names.split(","), args.runs, args.out)
        return
    tmp = Path(tempfile.mkdtemp(prefix="render_speed_"))
    names = build_scenes(tmp / "scenes.npz", not args.no_plant,
                         [int(r) for r in args.rooms.split(",") if r.strip()])
    old_src = checkout(args.old)
    rows: dict = {"old": {}, "new": {}}
    vectors: dict = {}
    for _ in range(args.rounds):  # old and new alternate, so a change in the machine's load hits both
        for side, src in (("old", old_src), ("new", ROOT)):
            out = run_side(src, tmp / "scenes.npz", names, args.runs, args.threads, tmp / f"{side}.npz",
                           args.old_vectors if side == "old" else "auto")
            vectors[side] = out.pop("vectors")
            for key, value in out.items():
                rows[side][key] = value if key.endswith("/pairs") else rows[side].get(key, []) + value
    timings = {side: {k: (v if k.endswith("/pairs") else np.min(np.array(v), axis=0).tolist()) for k, v in r.items()}
               for side, r in rows.items()}
    old_img, new_img = np.load(tmp / "old.npz"), np.load(tmp / "new.npz")
    print(f"clean CPU render 640x480, {args.threads} numba thread(s), fastest of {args.rounds} x {args.runs} per stage "
          f"(a loaded machine only ever adds time); old = {args.old}, "
          f"new = this checkout; load average {os.getloadavg()[0]:.2f}; numba vectors: old {vectors['old']}, new {vectors['new']}")
    print(f"{'scene':<11} {'out':<4} {'pairs':>7} " + " ".join(f"{s + ' ms':>16}" for s in STAGES)
          + "  speed-up  (old -> new per stage)")
    for key in sorted(k for k in timings["new"] if not k.endswith("/pairs")):
        o, n = timings["old"][key], timings["new"][key]
        cells = " ".join(f"{a * 1e3:>7.1f}->{b * 1e3:>7.1f}" for a, b in zip(o, n))
        name, label = key.split("/")
        print(f"{name:<11} {label:<4} {timings['new'][key + '/pairs']:>7} {cells}  {o[-1] / n[-1]:>5.2f}x")
    print(f"\nerror of new vs old (all outputs): {'scene':<11} {'rgb max':>9} {'a max':>9} {'d max':>9} "
          f"{'med max':>9} {'ids !=':>7}")
    for name in names:
        print(f"{'':<35}{name:<11} {errors(old_img, new_img, name)}")


if __name__ == "__main__":
    main()
