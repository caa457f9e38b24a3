"""Units of captures without metric scale: the estimate of ``spacedg.scene.units`` against the truth.

Prints numbers only (never part of the test run):

1. **sweep**: built-in rooms (metric truth) stored at a random scale (log-uniform 0.05–20 m per
   unit, as a COLMAP reconstruction would store them), z-up and y-up frames: the object estimate
   and the camera-height estimate against the true metres per unit, the spread, the agreeing
   objects, and whether the import would be refused at the default 1 m per unit (it must be
   exactly when the truth is more than ×1.5 away from 1); the up is the one the importer
   estimates from the cameras.
2. **fixtures**: the tests' room (INRIA output + COLMAP model + Holi-Spatial JSON) and object on a
   table (COLMAP project), at 0.145 m per unit, through ``import_scene``: the refusal, then the
   import with the estimate it names, and the unit report.
3. **plant**: the shared real phone capture's unit decision (one box: the estimate is unavailable).

    .venv/bin/python benchmarks/units.py              # 24 rooms
    .venv/bin/python benchmarks/units.py --rooms 60
    .venv/bin/python benchmarks/units.py --write runs/units   # only write the two fixtures (to try scenes import on)
"""

from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from spacedg.scene.io import estimate_up  # noqa: E402
from spacedg.scene.units import UnitsImplausibleError, decide_units  # noqa: E402


def sweep(rooms: int) -> None:
    from spacedg.scene.synthetic import CaptureConfig, RoomConfig, generate_room
    from tests.scene.unit_captures import in_file_units

    rng = np.random.default_rng(0)
    rows = []
    print(f"{'room':>5} {'frame':>5} {'truth m/u':>10} {'objects':>9} {'err':>7} {'spread':>6} {'agree':>7} {'camera':>9} {'err':>7} refused")
    for seed in range(rooms):
        frame = "z_up" if seed % 2 == 0 else "y_up"
        room = generate_room(seed, RoomConfig(gaussians=10_000, capture=CaptureConfig(160, 120, 12, 12), world_frame=frame))
        truth = float(np.exp(rng.uniform(np.log(0.05), np.log(20.0))))
        scaled = in_file_units(room, truth)
        d = decide_units("colmap", scaled.instances, scaled.views, estimate_up(scaled.views))
        e = d.estimate
        obj_err = None if e.metres_per_unit is None else e.metres_per_unit / truth - 1
        cam_err = None if e.camera is None else e.camera.metres_per_unit / truth - 1
        should = abs(np.log(truth)) > np.log(1.5)
        rows.append((obj_err, cam_err, d.implausible(), should))
        print(f"{seed:>5} {frame:>5} {truth:>10.4g} {e.metres_per_unit or float('nan'):>9.4g} "
              f"{'' if obj_err is None else f'{obj_err:+.1%}':>7} {e.spread or float('nan'):>6.2f} {e.agreeing:>3}/{len(e.objects):<3} "
              f"{'' if e.camera is None else f'{e.camera.metres_per_unit:.4g}':>9} {'' if cam_err is None else f'{cam_err:+.1%}':>7} "
              f"{d.implausible()}")
    obj = np.abs([r[0] for r in rows if r[0] is not None])
    cam = np.abs([r[1] for r in rows if r[1] is not None])
    print(f"objects: median |error| {np.median(obj):.1%}, max {obj.max():.1%} over {len(obj)} rooms")
    if len(cam):
        print(f"camera height: median |error| {np.median(cam):.1%}, max {cam.max():.1%} over {len(cam)} rooms with a floor")
    wrong = sum(r[2] != r[3] for r in rows)
    print(f"refusal at the default 1 m/unit matches 'truth more than x1.5 from 1' in {len(rows) - wrong} of {len(rows)} rooms")


def fixtures() -> None:
    from spacedg.scene.importer import import_scene
    from tests.scene.unit_captures import MPU, write_unit_fixtures

    with tempfile.TemporaryDirectory(prefix="spacedg-bench-units-") as tmp:
        for name, path, instances in write_unit_fixtures(Path(tmp)):
            print(f"\n[{name}] truth {MPU} m per unit")
            try:
                import_scene(path, None, instances=instances, progress=False)
                print("  NOT REFUSED")
                continue
            except UnitsImplausibleError as err:
                print(f"  refused: {err}")
                given = float(re.search(r"--metres-per-unit ([0-9.]+)", str(err)).group(1))  # type: ignore[union-attr]
            t0 = time.perf_counter()
            _, report = import_scene(path, None, instances=instances, metres_per_unit=given, progress=False)
            print(f"  with --metres-per-unit {given:g} ({given / MPU - 1:+.1%} off the truth), imported in {time.perf_counter() - t0:.2f} s:")
            print("  " + report.units.text().replace("\n", "\n  "))  # type: ignore[union-attr]


def plant() -> None:
    sys.path.insert(0, str(REPO / "benchmarks"))
    from import_capture import PLANT, plant_scene

    if not PLANT.is_file():
        print(f"\n[plant] not found at {PLANT}; skipped")
        return
    scene, _ = plant_scene()
    d = decide_units("inria", scene.instances, scene.views, scene.up)
    print("\n[plant (real capture, CC-BY-4.0 Marcel Padilla), truth unknown: COLMAP scale, not metric]")
    print("  " + d.text().replace("\n", "\n  "))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rooms", type=int, default=24)
    parser.add_argument("--write", type=Path, metavar="DIR", help="only write the two captures without metric scale under DIR")
    args = parser.parse_args()
    if args.write is not None:
        from tests.scene.unit_captures import MPU, write_unit_fixtures

        for name, path, instances in write_unit_fixtures(args.write):
            print(f"{name} ({MPU} m per file unit): spacedg scenes import {path} --instances {instances} --out {args.write / 'scenes' / (path.parent.name if path.name == 'output' else path.name)}")
        return
    sweep(args.rooms)
    fixtures()
    plant()


if __name__ == "__main__":
    main()
