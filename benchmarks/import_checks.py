"""What ``spacedg scenes import`` says about units, up and boxes, on the shared plant and on
fixtures written in the published layouts, each imported correctly and with one mistake applied.

For each capture: the unit decision (and the estimated metres per unit against the truth), the up
evidence, and the box fill table; for each mistake (a wrong ``--up``, unknown units left at the
default 1 m per unit, one box shifted by 7 cm), whether the import refused it (exit 2) and the
first line of its message. Never part of the test run.

    .venv/bin/python benchmarks/import_checks.py            # plant (when ../shared is beside) + fixtures
"""

from __future__ import annotations

import json
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from spacedg.errors import SpaceDGError  # noqa: E402
from spacedg.scene.importer import import_scene  # noqa: E402


def _attempt(label: str, run: Callable[[], object]) -> object | None:
    """Run one import; print its outcome in one line (ok, or refused and why)."""
    try:
        out = run()
    except SpaceDGError as err:
        print(f"  {label:<34} REFUSED (exit 2): {str(err).splitlines()[0][:150]}")
        return None
    print(f"  {label:<34} imported")
    return out


def _report(name: str, truth_mpu: float | None, report) -> None:  # type: ignore[no-untyped-def]
    """The unit decision, the up evidence and the box fill of a correct import."""
    print(f"\n=== {name}: layout {report.layout}, {report.views} views, {report.gaussians:,} Gaussians, {report.instances} boxes")
    if report.units is not None:
        est = report.units.estimate.metres_per_unit if report.units.estimate is not None else None
        vs = "" if truth_mpu is None or est is None else f"  (truth {truth_mpu:g}: {est / truth_mpu - 1:+.1%})"
        print("  " + report.units.text().replace("\n", "\n  ") + vs)
    for note in report.notes:
        if note.startswith("up evidence"):
            print(f"  {note}")
    if report.box_fill is not None:
        print(f"  box fill: {report.box_fill.summary()}")
        print("  " + report.box_fill.table().replace("\n", "\n  "))


def _shifted(boxes_json: Path, metres: float, unit: float) -> str:
    """Move the smallest box of a Holi-Spatial JSON by ``metres`` along x (in file units); its label."""
    records = json.loads(boxes_json.read_text())
    box = min(records, key=lambda r: float(np.prod(r["obb_extents"])))
    d = np.array([metres / unit, 0.0, 0.0])
    m = np.asarray(box["obb_transform"], dtype=float)
    m[:3, 3] += d
    box["obb_transform"] = m.tolist()
    box["bounding_box"] = [{"x": c["x"] + d[0], "y": c["y"], "z": c["z"]} for c in box["bounding_box"]]
    boxes_json.write_text(json.dumps(records))
    return str(box["label"])


def room_and_tabletop(root: Path) -> None:
    from tests.scene.unit_captures import MPU, write_unit_fixtures

    for name, folder, boxes in write_unit_fixtures(root):
        done = _attempt("correct (--metres-per-unit)", lambda: import_scene(folder, None, instances=boxes, metres_per_unit=MPU,
                                                                             progress=False))
        if done is not None:
            _report(name, MPU, done[1])
        print(f"  mistakes on {name}:")
        _attempt("units left unknown (no option)", lambda: import_scene(folder, None, instances=boxes, progress=False))
        _attempt("--up +y on a z-up capture", lambda: import_scene(folder, None, instances=boxes, up="+y",
                                                                     metres_per_unit=MPU, progress=False))
        moved = _shifted(boxes, 0.07, MPU)
        _attempt(f"smallest box ({moved}) shifted 7 cm", lambda: import_scene(folder, None, instances=boxes, metres_per_unit=MPU,
                                                                     progress=False))


def holi_release(root: Path) -> None:
    from tests.scene import holi_release as hr

    folder = hr.write_release(root / "holi", hr.released(hr.tiny_scene()))
    done = _attempt("Holi-Spatial release (one command)", lambda: import_scene(folder, None, progress=False))
    if done is not None:
        _report("Holi-Spatial released ScanNet++ scene", 1.0, done[1])


def scannetpp_iphone(root: Path) -> None:
    from spacedg.scene.io import write_ply
    from tests.scene import capture_layouts as cl
    from tests.scene import holi_release as hr

    truth = hr.tiny_scene()
    folder = cl.write_scannetpp_iphone(root / "iphone" / hr.SCENE_ID, truth)  # iphone/pose_intrinsic_imu.json (ARKit)
    (folder / "gs" / "point_cloud" / "iteration_30000").mkdir(parents=True)
    write_ply(folder / "gs" / "point_cloud" / "iteration_30000" / "point_cloud.ply", cl.without_ids(truth.gaussians))
    done = _attempt("ScanNet++ iPhone (ARKit poses)", lambda: import_scene(folder, None, device="iphone", progress=False))
    if done is not None:
        _report("ScanNet++ iPhone scene, cameras from pose_intrinsic_imu.json", 1.0, done[1])
    _attempt("ScanNet++ iPhone with --up +y", lambda: import_scene(folder, None, device="iphone", up="+y", progress=False))


def plant(root: Path) -> None:
    from import_capture import PLANT, plant_scene, write_capture

    if not PLANT.is_file():
        print(f"\n(plant skipped: {PLANT} not found)")
        return
    scene, boxes = plant_scene()
    folder = write_capture(root / "plant", scene, boxes)
    inst = root / "plant" / "instances.json"
    done = _attempt("plant (INRIA + COLMAP, up -y)", lambda: import_scene(folder, None, instances=inst, progress=False))
    if done is not None:
        _report("shared plant (real capture, units unknown: one box)", None, done[1])
    _attempt("plant with --up +y", lambda: import_scene(folder, None, instances=inst, up="+y", progress=False))


def main() -> None:
    with tempfile.TemporaryDirectory(prefix="spacedg-import-checks-") as tmp:
        root = Path(tmp)
        plant(root)
        room_and_tabletop(root)
        holi_release(root)
        scannetpp_iphone(root)


if __name__ == "__main__":
    main()
