"""``spacedg render``: render one view of a native scene folder to an sRGB PNG (and a depth PNG)."""

from __future__ import annotations

import argparse
import math
import re
from dataclasses import replace
from pathlib import Path

import numpy as np

from spacedg.commands import _args, _vocabulary
from spacedg.commands.sizes import image_side, image_size
from spacedg.errors import InvalidDataError, ParameterError
from spacedg.files import write_png
from spacedg.limits import MAX_IMAGE_SIDE, check_image_size

#: Largest image side accepted by --image-size (and the deprecated --width / --height), pixels (:mod:`spacedg.limits`).
MAX_SIDE = MAX_IMAGE_SIDE
#: Most motion-blur sub-exposures (--sub-steps).
MAX_SUB_STEPS = 4096
#: Smallest share of covered pixels (alpha > ½) of a render that is not "empty".
MIN_COVERAGE = 0.001
#: Depth PNG unit: millimetres, so uint16 covers 0–65.535 m.
DEPTH_SCALE = 1000.0


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    render = _args.add_command(subparsers, "render", _render, help="render one view of a scene to a PNG")
    # Let comma lists that start with a minus ("--fisheye -0.2,0,0,0") be values, not options:
    # argparse before 3.13 only recognises plain negative numbers ("-0.2") as values.
    if hasattr(render, "_negative_number_matcher"):
        render._negative_number_matcher = re.compile(r"^-\.?\d")
    render.add_argument("scene", type=Path, metavar="SCENE", help="native scene folder (holds scene.json)")
    render.add_argument("--view", help="name of the view to render (see --list-views)")
    render.add_argument("--list-views", action="store_true", help="print the scene's view names and exit")
    render.add_argument("--out", type=Path, help="PNG file to write (8-bit sRGB)")
    render.add_argument("--depth-out", type=Path, default=None,
                        help="also write expected depth as a 16-bit PNG in millimetres (0 = no coverage)")
    render.add_argument("--image-size", type=image_size, default=None, metavar="WxH",
                        help="largest render size in pixels, e.g. 640x480: the view keeps its aspect ratio and "
                        "renders at the largest size of it that fits (a 16:9 view at 320x240 renders 320x180; "
                        "default: the view's own size)")
    render.add_argument("--defocus", metavar="APERTURE_PX,FOCUS_M", default=None,
                        help="thin-lens defocus: CoC radius in pixels at infinity, focus distance in metres")
    render.add_argument("--fisheye", metavar="K1,K2,K3,K4[,MAX_THETA]", default=None,
                        help="replace the lens with an equidistant fisheye (OpenCV model; MAX_THETA in radians)")
    render.add_argument("--motion", metavar="TX,TY,TZ,RX,RY,RZ", default=None,
                        help="camera motion over the exposure: translation in metres then axis-angle rotation "
                        "in radians, both in the camera frame (x right, y down, z forward)")
    render.add_argument("--sub-steps", type=_args.whole(1, MAX_SUB_STEPS), default=None,
                        help="motion blur sub-exposures (default 80; with --fast-motion the upper bound)")
    render.add_argument("--fast-motion", action="store_true",
                        help="the renderer's fast path: a few keyframes (from the on-screen motion) with each "
                        "pixel's path integrated through them (sub-steps on fisheye lenses)")
    _args.add_backend_arguments(render)
    render.add_argument("--allow-empty", action="store_true",
                        help="write the PNG even when the view renders (almost) nothing (default: exit non-zero)")
    # the old --width / --height (one alone keeps the view's aspect ratio until they go)
    _vocabulary.add_deprecated(render, "render", **{
        "--width": dict(dest="width", type=image_side, metavar="W"), "--height": dict(dest="height", type=image_side, metavar="H"),
    })


def parse_numbers(flag: str, text: str, names: tuple[str, ...], optional: int = 0) -> list[float]:
    """Strictly parse ``text`` as comma-separated finite numbers for ``flag``.

    ``names`` are the fields in order; the last ``optional`` of them may be left out.
    Raises :class:`ParameterError` naming the flag and the expected format.
    """
    required = names[: len(names) - optional]
    shape = ",".join(required) + "".join(f"[,{n}]" for n in names[len(required):])
    items = [item.strip() for item in text.split(",")]
    if not len(required) <= len(items) <= len(names):
        count = f"{len(names)}" if not optional else f"{len(required)} to {len(names)}"
        raise ParameterError(f"{flag} expects {count} comma-separated numbers {shape}, got {len(items)} in {text!r}")
    values = []
    for name, item in zip(names, items):
        try:
            value = float(item)
        except ValueError:
            raise ParameterError(f"{flag} expects numbers {shape}; {name} is {item!r} in {text!r}") from None
        if not math.isfinite(value):
            raise ParameterError(f"{flag} expects finite numbers {shape}; {name} is {item!r}")
        values.append(value)
    return values


def _size(camera_w: int, camera_h: int, args: argparse.Namespace) -> tuple[int, int]:
    """Requested render size (a bounding box, :meth:`Camera.fitted`): --image-size, else the
    view's; the deprecated --width or --height alone keeps the view's aspect ratio."""
    size = _args.image_size_of(args, min_side=1)
    if size is not None:
        return size
    width, height = getattr(args, "width", None), getattr(args, "height", None)
    if width is None and height is None:
        return camera_w, camera_h
    if width is None:
        width = max(1, round(camera_w * height / camera_h))
    if height is None:
        height = max(1, round(camera_h * width / camera_w))
    check_image_size(int(width), int(height), "--width/--height", "render smaller", ParameterError)
    return int(width), int(height)


def _pick_view(scene, name: str):  # type: ignore[no-untyped-def]
    try:
        return scene.camera(name)
    except ParameterError as err:
        raise ParameterError(f"--view {name!r}: no such view ({err}); see --list-views") from None


def _check_png(flag: str, path: Path) -> None:
    if path.suffix.lower() != ".png":
        raise ParameterError(f"{flag} {path}: write a .png file")


def encode_depth_mm(depth_m: np.ndarray) -> np.ndarray:
    """Depth in metres → uint16 millimetres (clipped to 65535; 0 stays 0 = no coverage)."""
    mm = np.round(np.nan_to_num(depth_m, nan=0.0, posinf=0.0, neginf=0.0).astype(np.float64) * DEPTH_SCALE)
    return np.clip(mm, 0, 65535).astype(np.uint16)


def _render(args: argparse.Namespace) -> int:
    """Render one named view of a native scene folder (from `spacedg scenes synth`) to an 8-bit sRGB PNG,
    optionally with defocus, a fisheye lens and camera motion blur.
    """
    from spacedg.scene.io import load_scene
    from spacedg.render import Defocus, FisheyeLens, MotionBlur, render
    from spacedg.render.renderer import resolve_backend

    # Check every flag before the (lazy, possibly large) Gaussians are read.
    if not args.list_views:
        if args.view is None:
            raise ParameterError("--view NAME is required (or pass --list-views to see the names)")
        if args.out is None:
            raise ParameterError("--out FILE.png is required")
        _args.output_file("--out", args.out, (".png",))
        if args.depth_out is not None:
            _args.output_file("--depth-out", args.depth_out, (".png",))
            if args.depth_out.resolve() == args.out.resolve():
                raise ParameterError("--depth-out must be another file than --out")
    defocus = None
    if args.defocus is not None:
        aperture, focus = parse_numbers("--defocus", args.defocus, ("APERTURE_PX", "FOCUS_M"))
        defocus = Defocus(aperture, focus)
    lens = None
    if args.fisheye is not None:
        values = parse_numbers("--fisheye", args.fisheye, ("K1", "K2", "K3", "K4", "MAX_THETA"), optional=1)
        try:
            lens = FisheyeLens(*values)
        except InvalidDataError as err:  # from the lens (e.g. MAX_THETA outside (0, π)): name the flag
            raise ParameterError(f"--fisheye {args.fisheye}: {err}") from None
    motion = None
    if args.motion is not None:
        v = parse_numbers("--motion", args.motion, ("TX", "TY", "TZ", "RX", "RY", "RZ"))
        sub_steps = 80 if args.sub_steps is None else args.sub_steps
        try:
            motion = MotionBlur(tuple(v[:3]), tuple(v[3:]), sub_steps=sub_steps, fast=args.fast_motion)
        except ParameterError as err:
            raise ParameterError(f"--motion/--sub-steps: {err}") from None
    elif args.sub_steps is not None or args.fast_motion:
        raise ParameterError("--sub-steps and --fast-motion apply to motion blur; pass --motion TX,TY,TZ,RX,RY,RZ too")
    backend, _ = resolve_backend(args.backend, args.device)
    _args.image_size_of(args, min_side=1)  # the size policy, before the scene is read

    scene = load_scene(args.scene)
    if args.list_views:
        for name, cam in scene.views.items():
            model = "fisheye" if cam.fisheye is not None else "pinhole"
            print(f"{name}  {cam.width}x{cam.height}  {model}")
        return 0
    camera = _pick_view(scene, args.view)
    width, height = _size(camera.width, camera.height, args)
    fitted = camera.fitted(width, height)  # never squeezed: the size is a bounding box
    if (fitted.width, fitted.height) != (width, height):
        print(f"view {args.view} is {camera.width}x{camera.height}: rendered at {fitted.width}x{fitted.height}, "
              f"the largest size of its aspect ratio within {width}x{height}")
    camera = fitted
    if lens is not None:
        camera = replace(camera, fisheye=lens)

    from spacedg.render.colour_cpu import encode_srgb_u8

    want_depth = args.depth_out is not None
    frame = render(
        scene.gaussians, camera, defocus=defocus, motion=motion,
        outputs="rgb,depth" if want_depth else "rgb", backend=backend, device=args.device,
    )
    covered = float((frame.alpha > 0.5).mean())
    if covered < MIN_COVERAGE and not args.allow_empty:
        from spacedg.render.coverage import CoverageLostError, coverage_problem

        lost = coverage_problem(scene.gaussians, camera, frame.alpha, frame.valid, defocus=defocus, motion=motion,
                                backend=backend, device=args.device)
        if lost is not None:  # the blur or the lens, not the frame, emptied it
            raise CoverageLostError(f"view {args.view} of {args.scene}: {lost} (--defocus, --motion, --fisheye); "
                                    "pass --allow-empty to write it anyway")
        raise InvalidDataError(
            f"view {args.view} of {args.scene} renders empty ({covered:.2%} of the pixels covered): the Gaussians and this "
            "camera do not meet (a frame mismatch? see `spacedg scenes info`); pass --allow-empty to write it anyway"
        )
    write_png(args.out, encode_srgb_u8(frame.rgb), "--out", compression=9)
    stats = frame.stats
    visible = f"{stats['visible']:,}" if "visible" in stats else "n/a"
    print(
        f"view {args.view}  {frame.width}x{frame.height}  backend {backend}  visible {visible} Gaussians  "
        f"{stats.get('ms', float('nan')):.1f} ms  "
        + (f"keyframes {stats['keyframes']}" if "keyframes" in stats else f"sub-steps {stats.get('sub_steps', 1)}")
        + f"  -> {args.out}"
    )
    if lens is not None:
        from spacedg.render.coverage import captured_share

        print(f"fisheye: the captured view covers {captured_share(fitted, camera):.1%} of the fisheye frame "
              "(the rest shows what the captured view did not)")
    if want_depth:
        depth_mm = encode_depth_mm(frame.depth)
        write_png(args.depth_out, depth_mm, "--depth-out", compression=9)
        covered = frame.depth > 0
        if covered.any():
            d = frame.depth[covered]
            clipped = int((depth_mm == 65535).sum())
            note = f", {clipped} pixel(s) clipped at 65.535 m" if clipped else ""
            print(
                f"depth {float(d.min()):.3f}–{float(d.max()):.3f} m over {covered.mean():.1%} of pixels "
                f"(uint16 mm{note}) -> {args.depth_out}"
            )
        else:
            print(f"depth: no coverage (all 0) -> {args.depth_out}")
    return 0
