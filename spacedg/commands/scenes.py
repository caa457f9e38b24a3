"""``spacedg scenes``: build the built-in synthetic rooms, summarise scenes, draw floor plans."""

from __future__ import annotations

import argparse
import json
import re
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
from tqdm import tqdm

from spacedg.commands import _args, _vocabulary
from spacedg.commands.sizes import image_side, image_size
from spacedg.errors import InvalidDataError, ParameterError
from spacedg.files import write_png
from spacedg.scene.importer import LAYOUTS
from spacedg.scene.synthetic.room import RoomConfig

#: Image size of a synthetic room's views unless --image-size says otherwise, pixels.
SYNTH_SIZE = (640, 480)
#: Range of --num-gaussians (RoomConfig's own check).
MIN_GAUSSIANS, MAX_GAUSSIANS = 10_000, 5_000_000


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    scenes = subparsers.add_parser("scenes", help="build, inspect and preview scenes")
    sub = scenes.add_subparsers(dest="scenes_command", required=True, metavar="ACTION")

    synth = _args.add_command(sub, "synth", _synth, help="generate procedural indoor rooms into native scene folders")
    synth.add_argument("--n", type=_args.whole(1), required=True, help="number of rooms")
    synth.add_argument("--out", type=Path, required=True, help="folder that receives one sub-folder per room")
    synth.add_argument("--seed", type=_args.SEED, default=0, help="seed of the first room; room i uses seed + i (default 0)")
    synth.add_argument("--num-gaussians", type=_args.whole(MIN_GAUSSIANS, MAX_GAUSSIANS), default=None, metavar="N",
                       help="target Gaussians per room (default: 150k–300k by seed)")
    synth.add_argument("--min-views", type=_args.whole(1), default=48, help="fewest views per room (default 48)")
    synth.add_argument("--max-views", type=_args.whole(1), default=120, help="most views per room, >= --min-views (default 120)")
    synth.add_argument("--image-size", type=image_size, default=None, metavar="WxH",
                       help=f"image size of the views, pixels (default {SYNTH_SIZE[0]}x{SYNTH_SIZE[1]})")
    synth.add_argument("--splat", type=Path, action="append", default=[],
                       help="a .splat object to place in every room (repeatable; label and up axis from its meta.json)")
    synth.add_argument("--splat-size", type=_args.real(0, above=True, unit="metres"), default=0.35,
                       help="longest side of placed .splat objects, metres")
    synth.add_argument("--row-probability", type=_args.real(0, 1, unit="probability"), default=RoomConfig.row_probability, metavar="P",
                       help="chance that a room has a row of 4-6 chairs or boxes of one model along a wall, for counting (default %(default)s; 0 gives the rooms of before)")
    synth.add_argument("--overwrite", action="store_true", help="regenerate rooms whose folder already exists")
    _vocabulary.add_deprecated(synth, "scenes synth", **{
        "--width": dict(dest="width", type=image_side, metavar="W"), "--height": dict(dest="height", type=image_side, metavar="H"),
    })

    imp = _args.add_command(
        sub, "import", _import, help="turn a real capture (INRIA / COLMAP / nerfstudio / ScanNet++ + boxes) into a native scene folder",
    )
    # let "--up -y" (an axis with a minus) be a value, not an option
    if hasattr(imp, "_negative_number_matcher"):
        imp._negative_number_matcher = re.compile(r"^-(?:[xyzXYZ]|\.?\d)")
    imp.add_argument("src", type=Path, metavar="SRC",
                     help="INRIA output folder, COLMAP project/model folder, nerfstudio folder or transforms.json, "
                          "ScanNet++ scene folder, or a Gaussians file (.ply/.splat/.spz) with --cameras")
    imp.add_argument("--out", type=Path, required=True, help="scene folder to write")
    imp.add_argument("--instances", type=Path, default=None,
                     help="instance boxes: spacedg / Holi-Spatial JSON, ScanNet++ segments_anno.json, EmbodiedScan JSON")
    imp.add_argument("--format", default="auto", choices=LAYOUTS, help="layout of SRC (default: detect)")
    imp.add_argument("--name", default=None, help="scene id (default: the folder or file name)")
    imp.add_argument("--up", default="auto", help="world up in the files' frame: auto (default), +z, -y, ... or x,y,z")
    imp.add_argument("--metres-per-unit", type=_args.real(0, above=True, unit="metres"), default=None, metavar="X",
                     help="metres per file unit, applied to every part (default: metric layouts 1; otherwise 1 only when the "
                          "labelled objects' sizes agree, else refused with their estimate)")
    imp.add_argument("--units", default="auto", choices=("auto", "metric"),
                     help="metric: the files are in metres (not checked); auto (default): decided from the layout and checked")
    imp.add_argument("--gaussians-file", type=Path, default=None, metavar="PATH",
                     help="Gaussians file, .ply/.splat/.spz (overrides what the layout picks)")
    imp.add_argument("--cameras", type=Path, default=None, help="COLMAP model folder, transforms.json or INRIA cameras.json")
    imp.add_argument("--dataparser-transforms", type=Path, default=None,
                     help="splatfacto's dataparser_transforms.json (found next to the ply when not given)")
    imp.add_argument("--undo-applied-transform", action="store_true",
                     help="move transforms.json cameras back to the COLMAP frame (Gaussians trained on the COLMAP model)")
    imp.add_argument("--masks", type=Path, default=None, help="folder of Holi-Spatial masks <image stem>/<label>.png")
    imp.add_argument("--assign", default="auto", choices=("auto", "boxes", "masks", "none"),
                     help="instance ids when the Gaussians carry none (default auto = boxes; a Holi-Spatial release scene: masks, "
                          "its RLE mask_encodings; masks votes with Holi-Spatial masks)")
    imp.add_argument("--scannetpp-camera", default="dslr", choices=("dslr", "iphone"),
                     help="which ScanNet++ capture's cameras to read: dslr (default) or iphone (iphone/nerfstudio, else the "
                          "bundle-adjusted iphone/colmap, else the ARKit iphone/pose_intrinsic_imu.json)")
    imp.add_argument("--embodiedscan-scene", default=None, help="scan to take from a multi-scan EmbodiedScan JSON")
    imp.add_argument("--drop-distortion", action="store_true", help="render distorted OPENCV cameras as ideal pinholes")
    imp.add_argument("--allow-frame-mismatch", action="store_true", help="write the scene even if the frame check fails")
    imp.add_argument("--trust-up", action="store_true",
                     help="write the scene with the given --up even if the capture's evidence (cameras, floor, boxes) contradicts it; "
                          "scene.json records the override")
    imp.add_argument("--overwrite", action="store_true", help="replace an existing scene folder")
    imp.add_argument("--json", action="store_true", help="print the report as JSON")
    _vocabulary.add_deprecated(imp, "scenes import")

    info = _args.add_command(sub, "info", _info, help="counts, bounds and instances per label of scenes")
    info.add_argument("paths", type=Path, nargs="+", help="native scene folders, or folders of them")
    info.add_argument("--json", action="store_true", help="print JSON instead of text")

    preview = _args.add_command(sub, "preview", _preview, help="draw top-down floor plans of scenes into one PNG")
    preview.add_argument("paths", type=Path, nargs="+", help="native scene folders, or folders of them")
    preview.add_argument("--out", type=Path, required=True, help="PNG file to write")
    preview.add_argument("--columns", type=_args.whole(1, 64, "floor plans per row"), default=2, help="floor plans per row (default 2)")


def _scene_dirs(paths: list[Path]) -> list[Path]:
    """Expand folders of scene folders; every result holds a scene.json (sorted by name)."""
    from spacedg.scene.store import scene_dirs_of

    return scene_dirs_of(paths)


def _synth(args: argparse.Namespace) -> int:
    from spacedg.scene.io import load_scene, save_scene
    from spacedg.scene.synthetic import CaptureConfig, ExternalObject, generate_room

    width, height = _check_synth(args)
    externals = tuple(ExternalObject.from_splat(p, size_m=args.splat_size) for p in args.splat)
    config = RoomConfig(
        gaussians=args.num_gaussians,
        capture=CaptureConfig(width, height, args.min_views, args.max_views),
        external=externals,
        row_probability=args.row_probability,
    )
    args.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for i in tqdm(range(args.n), desc="rooms", unit="room"):
        seed = args.seed + i
        scene_id = f"room-{seed:06d}"
        folder = args.out / scene_id
        if (folder / "scene.json").is_file() and not args.overwrite:
            existing = load_scene(folder)
            if existing.metadata.get("config") != _config_record(config):
                raise InvalidDataError(
                    f"{folder}: exists with other generation settings; pass --overwrite to regenerate it or choose another --out"
                )
            rows.append((scene_id, existing, None))
            continue
        start = time.perf_counter()
        scene = generate_room(seed, config, scene_id=scene_id)
        scene.metadata["config"] = _config_record(config)
        elapsed = time.perf_counter() - start
        save_scene(scene, folder)
        rows.append((scene_id, scene, elapsed))
    print(f"{'scene':<14} {'gaussians':>10} {'instances':>9} {'labels':>6} {'views':>5} {'seconds':>8}")
    for scene_id, scene, elapsed in rows:
        labels = len({inst.label for inst in scene.instances})
        g = scene.gaussians
        took = "exists" if elapsed is None else f"{elapsed:.2f}"
        print(f"{scene_id:<14} {len(g):>10,} {len(scene.instances):>9} {labels:>6} {len(scene.views):>5} {took:>8}")
    print(f"wrote {len(rows)} scene folder(s) under {args.out}")
    return 0


def _check_synth(args: argparse.Namespace) -> tuple[int, int]:
    """The flags of ``scenes synth`` that argparse cannot check alone, before any room is
    generated; returns the views' ``(width, height)``, pixels."""
    _args.seed("--seed + --n - 1 (the last room's seed)", args.seed + args.n - 1)
    if args.min_views > args.max_views:
        raise ParameterError(
            f"--min-views {args.min_views} is more than --max-views {args.max_views}; each room takes between the two: "
            "pass --min-views <= --max-views"
        )
    size = _args.image_size_of(args, SYNTH_SIZE)
    _args.output_folder("--out", args.out)
    return size if size is not None else SYNTH_SIZE


def _config_record(config: RoomConfig) -> dict:
    """JSON-stable record of generation settings (to detect a folder made with other ones)."""
    record = {
        "gaussians": config.gaussians,
        "min_objects": config.min_objects,
        "max_objects": config.max_objects,
        "twin_probability": config.twin_probability,
        "world_frame": config.world_frame,
        "capture": asdict(config.capture),
        "external": [
            {"label": e.label, "size_m": e.size_m, "placement": e.placement, "n": len(e.gaussians)} for e in config.external
        ],
    }
    if config.row_probability:  # absent at 0: rooms without rows are the rooms of before, and their folders stay valid
        record["row_probability"] = config.row_probability
    return json.loads(json.dumps(record))


def _import(args: argparse.Namespace) -> int:
    """Detect the layout of SRC, read Gaussians, cameras and instance boxes, check that they share one
    frame, give the Gaussians instance ids, and write a native scene folder (scene.json +
    gaussians.ply).
    """
    from spacedg.scene.importer import import_scene

    _, report = import_scene(
        args.src, args.out, instances=args.instances, format=args.format, name=args.name, up=args.up,
        metres_per_unit=args.metres_per_unit, units=args.units, gaussians=args.gaussians_file, cameras=args.cameras,
        dataparser_transforms=args.dataparser_transforms, undo_applied_transform=args.undo_applied_transform,
        masks=args.masks, assign=args.assign, device=args.scannetpp_camera, embodiedscan_scene=args.embodiedscan_scene,
        opencv_distortion="drop" if args.drop_distortion else "error",
        frame_check="warn" if args.allow_frame_mismatch else "error", trust_up=args.trust_up, overwrite=args.overwrite,
        progress=not args.json,
    )
    print(json.dumps(report.to_dict(), indent=2) if args.json else report.text())
    return 0


def _info(args: argparse.Namespace) -> int:
    from spacedg.scene.box_fill import measure_box_fill
    from spacedg.scene.frame_check import check_frame
    from spacedg.scene.io import load_scene
    from spacedg.scene.units import scene_units_line

    summaries = []
    for folder in _scene_dirs(args.paths):
        scene = load_scene(folder)
        summary = scene.summary()
        summary["path"] = str(folder)
        warnings_ = []
        if scene.instances and scene.gaussians.instance_ids is None:
            warnings_.append("the Gaussians carry no instance ids: qa build assigns them by boxes on each run; "
                             "re-import with `spacedg scenes import` (or spacedg.assign_instances + save_scene) to keep them")
        elif scene.instances:
            present = set(np.unique(scene.gaussians.instance_ids).tolist())
            empty = [inst.id for inst in scene.instances if inst.id not in present]
            if empty:
                warnings_.append(f"{len(empty)} instance(s) have no Gaussians (ids {empty[:8]}): their questions are skipped")
        fill = measure_box_fill(scene.gaussians.means, scene.instances) if scene.instances else None
        frame = check_frame(scene, renders=2, box_share=None if fill is None else fill.held_share)
        summary["frame_check"] = frame.to_dict()
        summary["units"] = scene_units_line(scene)
        summary["box_fill"] = None if fill is None else {"summary": fill.summary(), **fill.to_dict()}
        if fill is not None and fill.bad:
            warnings_ += [f"box {r.id} '{r.label}' is {r.status}: best shift {r.shift_text()}" for r in fill.bad]
        if not frame.ok:
            warnings_.append("frame check failed: " + "; ".join(frame.problems))
        if isinstance(scene.metadata.get("up_evidence"), dict):
            summary["up_evidence"] = scene.metadata["up_evidence"]
        summary["warnings"] = warnings_
        summaries.append(summary)
    if args.json:
        print(json.dumps(summaries, indent=2))
        return 0
    for s in summaries:
        lo, hi = np.array(s["bounds_min_m"]), np.array(s["bounds_max_m"])
        print(f"{s['id']}  ({s['path']})")
        print(f"  gaussians {s['gaussians']:,} (SH degree {s['sh_degree']}), views {s['views']}, instances {s['instances']}")
        print(f"  bounds min {lo.round(2).tolist()} max {hi.round(2).tolist()} m, size {(hi - lo).round(2).tolist()} m, up {s['up']}")
        labels = ", ".join(f"{label} ×{n}" for label, n in s["labels"].items())
        print(f"  instances per label: {labels or '(none)'}")
        print(f"  frame check: {'ok' if s['frame_check']['ok'] else 'MISMATCH'}")
        print(f"  units: {s['units']}")
        if "up_evidence" in s:
            print(_indented_up_evidence(s["up_evidence"]))
        if s["box_fill"] is not None:
            print(f"  box fill: {s['box_fill']['summary']}")
        for warning in s["warnings"]:
            print(f"  warning: {warning}")
    return 0


def _indented_up_evidence(record: dict) -> str:
    """The recorded up evidence of an imported scene, as ``scenes info`` prints it (or why it cannot)."""
    from spacedg.scene.up_evidence import evidence_report

    try:
        return "\n".join(("  up check: " if k == 0 else "  ") + line for k, line in enumerate(evidence_report(record).splitlines()))
    except (KeyError, TypeError, ValueError) as err:
        return f"  up evidence: unreadable record in scene.json ({type(err).__name__}: {err})"


def _preview(args: argparse.Namespace) -> int:
    from spacedg.scene.floorplan import contact_sheet, floorplan
    from spacedg.scene.io import load_scene

    _args.output_file("--out", args.out, (".png",))
    images = [floorplan(load_scene(folder)) for folder in tqdm(_scene_dirs(args.paths), desc="floor plans", unit="scene")]
    write_png(args.out, contact_sheet(images, columns=args.columns), "--out")
    print(f"wrote {args.out} ({len(images)} floor plan(s))")
    return 0
