"""Importing real captures: time and quality of ``import_scene`` and ``assign_instances``.

Prints numbers only (never part of the test run). Two captures, both written first in the
layouts real tools produce (INRIA output folder + COLMAP text model + Holi-Spatial JSON):

1. **plant**: the shared real phone capture (``../shared/data/splats/plant/plant.splat``,
   113,648 Gaussians, CC-BY-4.0 Marcel Padilla), with 36 cameras on an orbit around it (the
   file has none) and one "potted plant" box (2–98 % of the centres).
2. **synthetic 1.5M**: a built-in room at ScanNet++ size (``--gaussians``, default 1,500,000) whose
   true instance ids are known, with its own hand-held views.

For each: import time split into reading, frame check, instance assignment and saving; the
assignment's coverage (Gaussians assigned, mean box coverage, mean rendered-mask IoU when
masks exist) and, for the synthetic room, agreement with the true ids. Then the visibility
and covisibility time per view of the 1.5M room (``prepare_scene`` at the default sizes).

    .venv/bin/python benchmarks/import_capture.py                     # both
    .venv/bin/python benchmarks/import_capture.py --gaussians 300000   # a smaller room
    .venv/bin/python benchmarks/import_capture.py --skip-synthetic
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from spacedg.render.camera import Camera, look_at  # noqa: E402
from spacedg.scene.io import read_splat, write_ply  # noqa: E402
from spacedg.scene.model import Scene  # noqa: E402

PLANT = REPO.parent / "shared" / "data" / "splats" / "plant" / "plant.splat"


def orbit_cameras(means: np.ndarray, up: np.ndarray, n: int = 36, width: int = 640, height_px: int = 480) -> dict[str, Camera]:
    """Phone-like orbit: ``n`` views at 1.8× the object's radius, two heights, looking at its centre."""
    centre = np.median(means, axis=0)
    radius = float(np.percentile(np.linalg.norm(means - centre, axis=1), 95))
    a = np.cross(up, [1.0, 0, 0]) if abs(up[0]) < 0.9 else np.cross(up, [0, 1.0, 0])
    a /= np.linalg.norm(a)
    b = np.cross(up, a)
    views = {}
    for k in range(n):
        angle = 2 * np.pi * k / (n // 2)
        height = 0.25 if k < n // 2 else 0.7
        eye = centre + 1.8 * radius * (np.cos(angle) * a + np.sin(angle) * b) + height * radius * up
        f = 0.9 * width
        views[f"IMG_{k:04d}"] = Camera(f, f, width / 2, height_px / 2, width, height_px, look_at(eye, centre, up))
    return views


def write_capture(root: Path, scene: Scene, boxes: list[dict]) -> Path:
    """INRIA output folder (latest iteration ply, cfg_args → COLMAP text model) + Holi-Spatial JSON."""
    sys.path.insert(0, str(REPO))
    from tests.scene.capture_layouts import write_inria_output

    out = write_inria_output(root, scene)
    (root / "instances.json").write_text(json.dumps(boxes))
    return out


def holi_boxes(instances) -> list[dict]:
    out = []
    for inst in instances:
        t = np.eye(4)
        t[:3, :3], t[:3, 3] = inst.box.rotation, inst.box.center
        out.append({"ins_id": str(inst.id), "label": inst.label, "obb_transform": t.tolist(), "obb_extents": inst.box.extents.tolist(),
                    "bounding_box": [{"x": x, "y": y, "z": z} for x, y, z in inst.box.corners().tolist()], "images": [],
                    "description": inst.description})
    return out


def run_import(name: str, root: Path, out: Path, truth: np.ndarray | None) -> Scene:
    from spacedg.scene.importer import import_scene

    start = time.perf_counter()
    scene, report = import_scene(out, root / "scene", instances=root / "instances.json", progress=False)
    total = time.perf_counter() - start
    s = report.seconds
    a = report.assignment
    print(f"\n[{name}] {report.gaussians:,} Gaussians, {report.views} views, {report.instances} instances")
    print(f"  import {total:.2f} s = read {s.get('read', 0):.2f} + frame check {s.get('frame_check', 0):.2f} + "
          f"assign {s.get('assign_instances', 0):.2f} + save {s.get('save', 0):.2f}")
    print(f"  frame check: {report.frame.summary()}")
    if report.units is not None:
        print("  " + report.units.text().replace("\n", "\n  "))
    if a is not None:
        covered = [c.box_coverage for c in a.instances if c.gaussians]
        iou = a.mean_mask_iou()
        print(f"  assignment ({a.method}): {a.seconds:.2f} s, {a.assigned:,}/{a.total:,} Gaussians assigned "
              f"({a.assigned / a.total:.1%}), {len(a.empty_instances)} empty instance(s), mean box coverage "
              f"{np.mean(covered) if covered else 0:.1%}" + (f", mean rendered-mask IoU {iou:.3f}" if iou is not None else ""))
    if truth is not None:
        got = scene.gaussians.instance_ids
        labelled = truth >= 0
        print(f"  agreement with the true ids: {np.mean(got[labelled] == truth[labelled]):.1%} of truly labelled Gaussians, "
              f"{np.mean(got[~labelled] == -1):.1%} of unlabelled ones kept -1")
    return scene


def plant_scene() -> tuple[Scene, list[dict]]:
    """The shared plant with an orbit of cameras and one box (see the module docstring)."""
    from spacedg.scene.box import OrientedBox
    from spacedg.scene.model import Instance

    g = read_splat(PLANT)
    up = np.array([0.0, -1.0, 0.0])  # meta.json: up axis -y
    means = g.means.astype(np.float64)
    lo, hi = np.percentile(means, [2, 98], axis=0)
    plant = Instance(1, "potted plant", "a green leafy houseplant", OrientedBox((lo + hi) / 2, hi - lo))
    return Scene("plant", g, orbit_cameras(means, up), [plant], up), holi_boxes([plant])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gaussians", type=int, default=1_500_000)
    parser.add_argument("--views", type=int, default=60)
    parser.add_argument("--skip-plant", action="store_true")
    parser.add_argument("--skip-synthetic", action="store_true")
    parser.add_argument("--write-plant", type=Path, default=None, metavar="DIR",
                        help="only write the plant capture (INRIA folder + COLMAP model + Holi-Spatial JSON) to DIR and exit")
    args = parser.parse_args()
    if args.write_plant is not None:
        out = write_capture(args.write_plant, *plant_scene())
        print(f"wrote {out} (INRIA output), {args.write_plant / 'data' / 'sparse' / '0'} (COLMAP), {args.write_plant / 'instances.json'}")
        return
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, load {os.getloadavg()[0]:.2f}")
    from spacedg.render import render

    with tempfile.TemporaryDirectory(prefix="spacedg-bench-import-") as tmp:
        tmp_path = Path(tmp)
        if not args.skip_plant:
            if not PLANT.is_file():
                print(f"plant capture not found at {PLANT}; skipped")
            else:
                scene, boxes = plant_scene()
                render(scene.gaussians.subset(slice(0, 1000)), next(iter(scene.views.values())).resized(64, 48))  # compile
                out = write_capture(tmp_path / "plant", scene, boxes)
                run_import("plant (real capture, CC-BY-4.0 Marcel Padilla)", tmp_path / "plant", out, None)
        if not args.skip_synthetic:
            from spacedg.qa.build import prepare_scene
            from spacedg.qa.index import QABuildConfig
            from spacedg.scene.synthetic import CaptureConfig, RoomConfig, generate_room

            t0 = time.perf_counter()
            room = generate_room(3, RoomConfig(gaussians=args.gaussians, capture=CaptureConfig(640, 480, args.views, args.views)))
            print(f"\n(generated the {len(room.gaussians):,}-Gaussian room in {time.perf_counter() - t0:.1f} s)")
            truth = room.gaussians.instance_ids
            out = write_capture(tmp_path / "room", room, holi_boxes(room.instances))
            scene = run_import(f"synthetic room, {len(room.gaussians):,} Gaussians", tmp_path / "room", out, truth)
            timings: dict[str, float] = {}
            prepare_scene(scene, None, QABuildConfig(), progress=False, timings=timings)
            n = len(scene.views)
            print(f"  visibility {timings['visibility_s']:.2f} s ({1000 * timings['visibility_s'] / n:.0f} ms/view), covisibility "
                  f"{timings['covisibility_s']:.2f} s ({1000 * timings['covisibility_s'] / n:.0f} ms/view) for {n} views "
                  f"(default sizes 160×120 and 80×60)")


if __name__ == "__main__":
    main()
