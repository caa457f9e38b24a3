"""``spacedg scenes``: build the built-in synthetic rooms, summarise scenes, draw floor plans."""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import asdict
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from spacedg.commands import _args
from spacedg.scene.synthetic.room import RoomConfig
from spacedg.errors import InvalidDataError, ParameterError


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    scenes = subparsers.add_parser("scenes", help="build, inspect and preview scenes")
    sub = scenes.add_subparsers(dest="scenes_command", required=True, metavar="ACTION")

    synth = sub.add_parser("synth", help="generate procedural indoor rooms into native scene folders")
    synth.add_argument("--n", type=int, required=True, help="number of rooms")
    synth.add_argument("--out", type=Path, required=True, help="folder that receives one sub-folder per room")
    synth.add_argument("--seed", type=int, default=0, help="seed of the first room; room i uses seed + i (default 0)")
    synth.add_argument("--gaussians", type=int, default=None, help="target Gaussians per room (default: 150k–300k by seed)")
    synth.add_argument("--min-views", type=int, default=48, help="fewest views per room (default 48)")
    synth.add_argument("--max-views", type=int, default=120, help="most views per room, >= --min-views (default 120)")
    synth.add_argument("--width", type=int, default=640, help="image width of the views, pixels")
    synth.add_argument("--height", type=int, default=480, help="image height of the views, pixels")
    synth.add_argument("--splat", type=Path, action="append", default=[],
                       help="a .splat object to place in every room (repeatable; label and up axis from its meta.json)")
    synth.add_argument("--splat-size", type=float, default=0.35, help="longest side of placed .splat objects, metres")
    synth.add_argument("--overwrite", action="store_true", help="regenerate rooms whose folder already exists")
    synth.set_defaults(func=_synth)

    info = sub.add_parser("info", help="counts, bounds and instances per label of scenes")
    info.add_argument("paths", type=Path, nargs="+", help="native scene folders, or folders of them")
    info.add_argument("--json", action="store_true", help="print JSON instead of text")
    info.set_defaults(func=_info)

    preview = sub.add_parser("preview", help="draw top-down floor plans of scenes into one PNG")
    preview.add_argument("paths", type=Path, nargs="+", help="native scene folders, or folders of them")
    preview.add_argument("--out", type=Path, required=True, help="PNG file to write")
    preview.add_argument("--columns", type=int, default=2, help="floor plans per row (default 2)")
    preview.set_defaults(func=_preview)


def _scene_dirs(paths: list[Path]) -> list[Path]:
    """Expand folders of scene folders; every result holds a scene.json (sorted by name)."""
    from spacedg.scene.store import scene_dirs_of

    return scene_dirs_of(paths)


def _synth(args: argparse.Namespace) -> int:
    from spacedg.scene.io import load_scene, save_scene
    from spacedg.scene.synthetic import CaptureConfig, ExternalObject, generate_room

    _check_synth(args)
    externals = tuple(ExternalObject.from_splat(p, size_m=args.splat_size) for p in args.splat)
    config = RoomConfig(
        gaussians=args.gaussians,
        capture=CaptureConfig(args.width, args.height, args.min_views, args.max_views),
        external=externals,
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


def _check_synth(args: argparse.Namespace) -> None:
    """Every flag of ``scenes synth``, before any room is generated."""
    _args.at_least("--n", args.n, 1)
    _args.seed("--seed", args.seed)
    _args.seed("--seed + --n - 1 (the last room's seed)", args.seed + args.n - 1)
    RoomConfig(gaussians=args.gaussians)  # its own range check ("gaussians must be in [10000, 5000000]")
    _args.at_least("--min-views", args.min_views, 1)
    _args.at_least("--max-views", args.max_views, 1)
    if args.min_views > args.max_views:
        raise ParameterError(
            f"--min-views {args.min_views} is more than --max-views {args.max_views}; each room takes between the two: "
            "pass --min-views <= --max-views"
        )
    _args.in_range("--width", args.width, 8, 16384, "pixels")
    _args.in_range("--height", args.height, 8, 16384, "pixels")
    _args.positive_number("--splat-size", args.splat_size)
    _args.output_folder("--out", args.out)


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
    return json.loads(json.dumps(record))


def _info(args: argparse.Namespace) -> int:
    from spacedg.scene.io import load_scene

    summaries = []
    for folder in _scene_dirs(args.paths):
        summary = load_scene(folder).summary()
        summary["path"] = str(folder)
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
    return 0


def _preview(args: argparse.Namespace) -> int:
    from spacedg.scene.floorplan import contact_sheet, floorplan
    from spacedg.scene.io import load_scene

    _args.at_least("--columns", args.columns, 1)
    _args.output_file("--out", args.out, (".png",))
    images = [floorplan(load_scene(folder)) for folder in tqdm(_scene_dirs(args.paths), desc="floor plans", unit="scene")]
    args.out.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(args.out), contact_sheet(images, columns=args.columns)[:, :, ::-1]):
        raise InvalidDataError(f"{args.out}: could not write the PNG")
    print(f"wrote {args.out} ({len(images)} floor plan(s))")
    return 0
