"""``spacedg gallery SCENE --view NAME --out gallery.png``: the degradation contact sheet of one view."""

from __future__ import annotations

import argparse
from pathlib import Path

from spacedg.commands import _args
from spacedg.errors import ParameterError


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    gallery = _args.add_command(
        subparsers, "gallery", _gallery, help="contact sheet of one view: clean + each degradation at severities 1-5 and bench",
    )
    gallery.add_argument("scene", type=Path, metavar="SCENE", help="native scene folder (holds scene.json)")
    gallery.add_argument("--view", default=None, help="view name (default: the scene's first view)")
    gallery.add_argument("--out", type=Path, required=True, help="PNG file to write")
    gallery.add_argument("--degradations", default=None, metavar="NAME[,NAME…]",
                         help="rows to show, comma-separated (default: every registered degradation)")
    gallery.add_argument("--seed", type=_args.SEED, default=0, help="sample seed for parameters and noise (default 0)")
    gallery.add_argument("--thumb-width", type=_args.whole(64, 2048, "pixels"), default=256, help="thumbnail width in pixels (default 256)")
    gallery.add_argument("--motion", choices=("fast", "reference"), default="fast",
                         help="motion blur sub-steps: renderer's fast choice (default) or the exact sub_steps")
    _args.add_backend_arguments(gallery)


def _gallery(args: argparse.Namespace) -> int:
    """Render one view of a native scene folder clean and under every registered degradation (third-party
    plugins included) at severities 1-5 and the paper's bench preset, labelled, as one PNG.
    """
    from spacedg.commands.render import _pick_view
    from spacedg.files import write_png
    from spacedg.data.gallery import gallery_sheet
    from spacedg.scene.io import load_scene
    from spacedg.data.pipeline import PipelineOptions

    _args.output_file("--out", args.out, (".png",))
    names = [n.strip() for n in args.degradations.split(",") if n.strip()] if args.degradations else None
    scene = load_scene(args.scene)
    view = args.view if args.view is not None else next(iter(scene.views), None)
    if view is None:
        raise ParameterError(f"scene {scene.id} has no views")
    _pick_view(scene, view)
    options = PipelineOptions(motion=args.motion, backend=args.backend, device=args.device)
    sheet = gallery_sheet(scene, view, names, seed=args.seed, thumb_width=args.thumb_width, options=options, progress=True)
    write_png(args.out, sheet, "--out", compression=9)
    print(f"wrote {args.out} ({sheet.shape[1]}x{sheet.shape[0]}): view {view}, {len(names) if names else 'all'} degradations")
    return 0
