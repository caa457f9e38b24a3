"""Every layout ``spacedg scenes import`` accepts, its exact command and what the import says about
units and up, on fixtures written in the published layouts (``tests/scene/capture_layouts.py``,
``tests/scene/holi_release.py``, ``tests/scene/unit_captures.py``). Never part of the test run.

For each layout: the command (run in the fixture folder, through ``spacedg.cli.main``), its exit
status, and the lines of its summary about the layout, up, units and the up evidence (or the first
lines of its error).

    .venv/bin/python benchmarks/import_layouts.py                 # in a temporary folder
    .venv/bin/python benchmarks/import_layouts.py --keep runs/layouts
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import shlex
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from spacedg.cli import main as cli  # noqa: E402
from spacedg.scene.io import write_ply  # noqa: E402
from tests.scene import capture_layouts as cl  # noqa: E402
from tests.scene import holi_release as hr  # noqa: E402
from tests.scene.unit_captures import MPU, write_unit_fixtures  # noqa: E402

#: Summary lines kept (their first word), and the units report's continuation lines.
KEEP = ("layout", "views", "up", "units", "note         up evidence", "note         cameras: ARKit", "note         pose_intrinsic")


def run(title: str, argv: list[str]) -> None:
    """Run ``spacedg`` with ``argv`` and print the command, the exit status and the lines about units and up."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli(argv)
    print(f"\n### {title}\n\n    $ spacedg {shlex.join(argv)}\n    exit {code}")
    lines, keep = out.getvalue().splitlines(), False
    for line in lines:
        keep = (line.startswith(KEEP) or line.strip().startswith(("units:", "up check:", "bounds"))
                or (keep and line.startswith("             ") and not line.startswith("             0")))
        if keep:
            print(f"    {line}")
    for line in [e for e in err.getvalue().strip().splitlines() if "%|" not in e][:6]:
        print(f"    {line[:400]}")


def _room_metres(root: Path) -> None:
    room = cl.truth_room(seed=5, gaussians=10_000, views=8)
    cl.write_inria_output(root / "inria_m", room)
    (root / "inria_m" / "holi.json").write_text(json.dumps(cl.holi_spatial_json(room, {})))
    cl.write_colmap_text(root / "bare" / "sparse" / "0", room)
    cl.write_spz(root / "bare" / "room.spz", cl.without_ids(room.gaussians))
    cl.write_compressed_ply(root / "bare" / "room.compressed.ply", cl.without_ids(room.gaussians))
    (root / "bare" / "es.json").write_text(json.dumps(cl.embodiedscan_infos(room)))
    scannet = cl.write_scannetpp_dslr(root / "scannetpp" / "0a5c013435", room)
    cl.write_inria_output(scannet / "gs", room.transformed(cl.SCANNETPP_JSON[:3, :3], np.zeros(3)), with_colmap=False)


def _nerfstudio(root: Path) -> None:
    far = cl.truth_room(seed=6, gaussians=10_000, views=12, shift=(12.0, -9.0, 0.0))
    (root / "ns" / "data").mkdir(parents=True)
    (root / "ns" / "data" / "transforms.json").write_text(json.dumps(cl.transforms_json(far, world=cl.APPLIED)))
    cl.write_splatfacto(root / "ns" / "outputs" / "room" / "splatfacto" / "2024-01-01_000000", far, cl.APPLIED)
    (root / "ns" / "inst.json").write_text(json.dumps(cl.holi_spatial_json(far, {}, world=cl.APPLIED)))


def _iphone_and_holi(root: Path) -> None:
    truth = hr.tiny_scene()
    for name, colmap in (("iphone", None), ("iphone_colmap", 0.02)):
        folder = cl.write_scannetpp_iphone(root / name / "0a5c013435", truth, colmap=colmap)
        (folder / "gs" / "point_cloud" / "iteration_30000").mkdir(parents=True)
        write_ply(folder / "gs" / "point_cloud" / "iteration_30000" / "point_cloud.ply", cl.without_ids(truth.gaussians))
    hr.write_release(root / "holi", hr.released(truth))


def write_all(root: Path) -> None:
    """Every fixture under ``root``."""
    write_unit_fixtures(root / "units")
    _room_metres(root)
    _nerfstudio(root)
    _iphone_and_holi(root)
    cli(["scenes", "synth", "--n", "1", "--out", str(root / "own"), "--num-gaussians", "10000", "--min-views", "3", "--max-views", "4"])


def commands() -> list[tuple[str, list[str]]]:
    """(title, argv) of every import, paths relative to the fixtures' folder."""
    holi = Path("holi") / "GS_model_w_mesh_pp" / hr.SCENE_ID
    room_unknown, table = "units/room/output", "units/table"
    plain = ["--assign", "none"]
    return [
        ("INRIA output + COLMAP model + Holi-Spatial boxes, unknown units (0.145 m/unit): refused",
         ["scenes", "import", room_unknown, "--instances", "units/room/holi.json", "--out", "out/inria", *plain]),
        ("... the same with the number the refusal names",
         ["scenes", "import", room_unknown, "--instances", "units/room/holi.json", "--metres-per-unit", "0.152", "--out", "out/inria", *plain]),
        ("... with a wrong --up", ["scenes", "import", room_unknown, "--instances", "units/room/holi.json", "--metres-per-unit", "0.152",
                                   "--up", "+y", "--out", "out/inria_y", *plain]),
        ("INRIA output in metres (units unknown, the objects agree at 1 m/unit)",
         ["scenes", "import", "inria_m/output", "--instances", "inria_m/holi.json", "--out", "out/inria_m", *plain]),
        ("COLMAP project (object on a table, 0.145 m/unit): refused",
         ["scenes", "import", table, "--instances", f"{table}/instances.json", "--out", "out/colmap", *plain]),
        ("... with --metres-per-unit", ["scenes", "import", table, "--instances", f"{table}/instances.json", "--metres-per-unit",
                                        str(MPU), "--out", "out/colmap", *plain]),
        ("nerfstudio transforms.json + splatfacto export (dataparser_transforms.json found)",
         ["scenes", "import", "ns/data", "--gaussians-file", "ns/outputs/room/splatfacto/2024-01-01_000000/splat.ply",
          "--instances", "ns/inst.json", "--out", "out/ns", *plain]),
        ("ScanNet++ DSLR scene folder", ["scenes", "import", "scannetpp/0a5c013435", "--out", "out/dslr", *plain]),
        ("ScanNet++ iPhone, ARKit iphone/pose_intrinsic_imu.json",
         ["scenes", "import", "iphone/0a5c013435", "--scannetpp-camera", "iphone", "--out", "out/iphone", *plain]),
        ("ScanNet++ iPhone with iphone/colmap too (COLMAP used, ARKit compared)",
         ["scenes", "import", "iphone_colmap/0a5c013435", "--scannetpp-camera", "iphone", "--out", "out/iphone_colmap", *plain]),
        ("Holi-Spatial released scene (one command)", ["scenes", "import", str(holi), "--out", "out/holi"]),
        ("bare .spz + COLMAP cameras + EmbodiedScan boxes",
         ["scenes", "import", "bare/room.spz", "--cameras", "bare/sparse/0", "--instances", "bare/es.json", "--embodiedscan-scene",
          "room-000005", "--out", "out/spz", *plain]),
        ("bare .compressed.ply + COLMAP cameras, no boxes",
         ["scenes", "import", "bare/room.compressed.ply", "--cameras", "bare/sparse/0", "--out", "out/compressed", *plain]),
        ("our own scene folder (scenes synth)", ["scenes", "import", "own/room-000000", "--out", "out/own"]),
        ("... needs no import: scenes info", ["scenes", "info", "own/room-000000"]),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", type=Path, help="write the fixtures here and keep them")
    args = parser.parse_args()
    context: Callable[[], contextlib.AbstractContextManager[str]] = (
        (lambda: contextlib.nullcontext(str(args.keep))) if args.keep else (lambda: tempfile.TemporaryDirectory(prefix="spacedg-layouts-")))
    with context() as tmp:
        root = Path(tmp).resolve()
        root.mkdir(parents=True, exist_ok=True)
        with contextlib.redirect_stdout(io.StringIO()):
            write_all(root)
        cwd = os.getcwd()
        os.chdir(root)
        try:
            for title, argv in commands():
                run(title, argv)
        finally:
            os.chdir(cwd)


if __name__ == "__main__":
    main()
