"""Do the presets depend on the image size? One table: degradation × severity, PSNR (dB) of

    (render at HIGH, degrade, area-downsample the 8-bit image to LOW)  vs  (render at LOW, degrade)

with the same chain, preset and seed at both sizes (default HIGH 1920×1080, LOW 640×360, a
factor of 3). The goal is ≥ 35 dB for every degradation but JPEG (whose 8×8 blocks are pixels
by nature). The ``clean`` row is the renderer's own agreement between the two sizes (a render
samples each pixel at its centre, a downsampled one averages 9): no degradation row can beat it
by much. Pixel parameters are stated at the reference size (1752×1168) and scaled with the
output (``ParamRange(per_size=True)``); random fields (drops, sensor noise) are drawn in
normalised coordinates, so both sizes see the same drops and the same photosites.

Every chain of one size goes through one ``degrade_variants`` call (the linear and display
chains share one clean render). Scenes: ``room`` (a built-in room with ``--gaussians``
Gaussians, its middle view) or ``plant`` (the shared real capture, an object on an empty
background, ``../shared/data/splats/plant``). Runs on any revision with ``degrade_variants``
(so the same command prints the table before a change)::

    .venv/bin/python benchmarks/resolution.py [--scene room|plant] [--high 1920x1080] [--low 640x360]
        [--severities bench,1,3,5] [--degradations haze,low_res] [--gaussians 20000] [--seed 1]
"""

from __future__ import annotations

import argparse
import math
import os
import time
from pathlib import Path

import cv2
import numpy as np

from spacedg.data.chain import BENCH_DEGRADATIONS
from spacedg.data.pipeline import PipelineOptions, degrade_variants
from spacedg.render import Camera
from spacedg.render.camera import look_at
from spacedg.render.settings import RasterSettings
from spacedg.scene.model import Scene

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "splats"
GOAL_DB = 35.0
EXEMPT = frozenset({"jpeg_compression"})  # 8x8 blocks in pixels by nature


def _size(text: str) -> tuple[int, int]:
    width, _, height = text.lower().partition("x")
    return int(width), int(height)


def room_scene(gaussians: int, size: tuple[int, int], seed: int = 3) -> Scene:
    """A built-in room with one view: its middle camera at ``size`` (intrinsics scaled per axis)."""
    from spacedg.scene.synthetic import RoomConfig, generate_room

    room = generate_room(seed, RoomConfig(gaussians=gaussians))
    names = sorted(room.views)
    camera = room.views[names[len(names) // 2]].resized(*size)
    return Scene("resolution-room", room.gaussians, {"view": camera}, room.instances, up=room.up)


def object_scene(path: Path, size: tuple[int, int], capture: tuple[int, int] | None, up: str = "-y") -> Scene:
    """A Gaussians file (``.splat``/``.ply``/``.spz``, e.g. the shared plant) as one object filling ~80 % of
    the frame's height, seen slightly from above; ``up`` is the file's up axis (the plant's is -y).

    ``capture``: the image size the Gaussians are taken to have been trained at (a file without
    cameras does not say): the view's ``capture_focal`` is its focal at that size (``None``: classic
    dilation, no capture scale; see :func:`spacedg.render.settings.footprint_dilation`)."""
    from spacedg.scene.capture_checks import parse_up
    from spacedg.scene.io import read_gaussians

    up_vec = parse_up(up)  # "+x".."-z" (a clear error otherwise)
    axis = int(np.argmax(np.abs(up_vec)))
    g = read_gaussians(path)
    lo, hi = np.percentile(g.means, 0.5, axis=0), np.percentile(g.means, 99.5, axis=0)
    centre, extent = 0.5 * (lo + hi), hi - lo
    side = next(i for i in range(3) if i != axis)  # the camera looks along the third axis
    depth_axis = 3 - axis - side
    height_extent, depth_extent = extent[axis], extent[depth_axis]
    width, height = size
    focal = 0.75 * width
    direction = np.zeros(3)
    direction[depth_axis], direction[axis] = 1.0, 0.25 * up_vec[axis]
    direction /= np.linalg.norm(direction)
    distance = 0.5 * height_extent * focal / (0.4 * height) + 0.5 * depth_extent
    pose = look_at(centre + distance * direction, centre, up_vec)
    capture_focal = None if capture is None else (0.75 * capture[0], 0.75 * capture[0])
    camera = Camera(focal, focal, width / 2, height / 2, width, height, pose, capture_focal=capture_focal)
    return Scene("resolution-object", g, {"view": camera}, up=tuple(up_vec))


def saved_scene(path: Path, size: tuple[int, int], view: str | None) -> Scene:
    """A saved scene (``spacedg scenes import`` output), one view (``view``, default its middle one),
    fitted to ``size`` (its own ``capture_focal``, set on import, keeps the trained look)."""
    from spacedg.scene.io.native import load_scene

    scene = load_scene(path)
    names = sorted(scene.views)
    name = view or names[len(names) // 2]
    camera = scene.views[name].fitted(*size)
    return Scene("resolution-saved", scene.gaussians, {"view": camera}, scene.instances, up=scene.up)


def psnr_u8(a: np.ndarray, b: np.ndarray) -> float:
    mse = float(np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2))
    return math.inf if mse == 0.0 else 10.0 * math.log10(255.0**2 / mse)


def pixel_params(provenance: list[dict]) -> str:
    """The parameters a chain recorded scaled with the image size (``param=value``; empty before
    presets scaled with the size)."""
    from spacedg.plugins import get_degradation

    out = []
    for entry in provenance:
        if "image_size" in entry:
            ranges = get_degradation(entry["name"]).presets[entry["preset"]]
            out += [f"{k}={v:.3g}" for k, v in entry["params"].items() if getattr(ranges[k], "per_size", 0)]
    return " ".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--scene", default="room",
                        help="room | plant | a Gaussians file (.splat/.ply/.spz, framed as one object) | a saved scene folder")
    parser.add_argument("--up", default="-y", help="a Gaussians file's up axis (+x..-z; the plant's is -y)")
    parser.add_argument("--capture", default="high",
                        help="WxH the Gaussians file was trained at ('high': the --high size; 'none': unknown, classic dilation)")
    parser.add_argument("--view", default=None, help="a saved scene's view (default: its middle one)")
    parser.add_argument("--high", type=_size, default=(1920, 1080), help="WxH rendered and area-downsampled")
    parser.add_argument("--low", type=_size, default=(640, 360), help="WxH rendered directly (same aspect ratio)")
    parser.add_argument("--severities", default="bench,1,2,3,4,5")
    parser.add_argument("--degradations", default=",".join(BENCH_DEGRADATIONS))
    parser.add_argument("--gaussians", type=int, default=20_000, help="room only")
    parser.add_argument("--seed", type=int, default=1, help="the sample's seed (same at both sizes)")
    parser.add_argument("--antialiased", action="store_true",
                        help="render with RasterSettings(antialiased=True) (opacity compensated for the eps2d dilation)")
    args = parser.parse_args()
    severities = [s.strip() for s in args.severities.split(",") if s.strip()]
    names = [d.strip() for d in args.degradations.split(",") if d.strip()]
    chains = ["clean"] + [f"{name}:{sev}" for name in names for sev in severities]
    capture = None if args.capture == "none" else (args.high if args.capture == "high" else _size(args.capture))
    source = SHARED / "plant" / "plant.splat" if args.scene == "plant" else Path(args.scene)
    if args.scene == "room":
        make = lambda size: room_scene(args.gaussians, size)  # noqa: E731
    elif source.is_dir():
        make = lambda size: saved_scene(source, size, args.view)  # noqa: E731
    else:
        make = lambda size: object_scene(source, size, capture, args.up)  # noqa: E731
    results, timing = {}, {}
    settings = RasterSettings(antialiased=True) if args.antialiased else None
    for size in (args.high, args.low):
        scene = make(size)
        t0 = time.perf_counter()
        results[size] = degrade_variants(scene, ["view"], chains, seed=args.seed, options=PipelineOptions(image_size=size, settings=settings))
        timing[size] = time.perf_counter() - t0
    (hw, hh), (lw, lh) = args.high, args.low
    what = f"{args.gaussians} Gaussians" if args.scene == "room" else (
        "saved scene, its own capture focal" if source.is_dir() else f"capture size {'unknown' if capture is None else '%dx%d' % capture}")
    print(f"Resolution table: {args.scene} ({what}), "
          f"seed {args.seed}; PSNR dB of area-downsample({hw}x{hh}) vs {lw}x{lh}, 8-bit sRGB; goal >= {GOAL_DB:g} dB "
          f"(JPEG exempt); load average {os.getloadavg()[0]:.2f}; degrade time {timing[args.high]:.1f} s at high, "
          f"{timing[args.low]:.1f} s at low")
    print(f"{'degradation':<17}" + "".join(f"{s:>8}" for s in severities) + "   pixels used at bench (high | low)")
    short = {}
    for i, chain in enumerate(chains):
        hi, lo = results[args.high][i].images[0], results[args.low][i].images[0]
        down = cv2.resize(hi, (lo.shape[1], lo.shape[0]), interpolation=cv2.INTER_AREA)
        value = psnr_u8(down, lo)
        name, _, sev = chain.partition(":")
        short.setdefault(name, {})[sev or "-"] = value
        if name != "clean" and name not in EXEMPT and value < GOAL_DB:
            short[name].setdefault("_below", []).append(sev)
        if sev == "bench":
            short[name]["_px"] = f"{pixel_params(results[args.high][i].degradations)} | {pixel_params(results[args.low][i].degradations)}"
    print(f"{'clean':<17}{short['clean']['-']:>8.2f}")
    failing = []
    for name in names:
        row = short[name]
        cells = "".join(f"{row[s]:>8.2f}" for s in severities)
        flag = " (exempt)" if name in EXEMPT else (" BELOW GOAL" if "_below" in row else "")
        print(f"{name:<17}{cells}   {row.get('_px', '').strip(' |') and row.get('_px', '')}{flag}")
        if "_below" in row:
            failing.append(f"{name} at {', '.join(row['_below'])}")
    print("every row but JPEG >= %g dB: %s" % (GOAL_DB, "yes" if not failing else "no (" + "; ".join(failing) + ")"))


if __name__ == "__main__":
    main()
