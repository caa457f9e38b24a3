"""Answerability of degraded images: the share of items whose named objects stay discernible.

For every degradation at severities 1–5 and ``bench`` (and clean), on

- **rooms**: built-in procedural rooms, the objects every question family names
  (:func:`spacedg.data.answerability.named_objects`), at ``--size``;
- **object**: one real splat object (``../shared/data/splats/<--object>``, 0.25 m across) alone in
  front of nothing, filmed from 0.4–0.6 m on a ring (the "tabletop": one object on an empty
  background), the object itself named in every view,

it renders each item under each condition (:func:`spacedg.data.pipeline.degrade_variants`: the
pipeline's own images), finds the objects in the id map of the item's lens
(:func:`~spacedg.data.answerability.object_id_maps`) and prints a table per scene kind:
degradation × severity → share of items with every named object discernible (Weber contrast
>= 2 % with 1 % viewing flare and Rose SNR >= 5: :mod:`spacedg.data.answerability`). The time
per item is printed too (the measure against its render).

    PYTHONPATH=$PWD python benchmarks/answerability.py                 # 2 rooms x 24 questions + the object, 320x240
    PYTHONPATH=$PWD python benchmarks/answerability.py --rooms 3 --records 40 --size 640x480
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

import numpy as np

from spacedg.data.answerability import (
    answerability_table,
    condition_of,
    groups_answerability,
    item_answerability,
    object_id_maps,
    share_by_condition,
)
from spacedg.data.chain import Chain
from spacedg.data.gallery import GALLERY_PRESETS
from spacedg.data.pipeline import PipelineOptions, degrade_variants
from spacedg.plugins.registry import list_degradations
from spacedg.seeding import derive_seed

SPLATS = Path(__file__).resolve().parents[2] / "shared" / "data" / "splats"


def conditions(presets: tuple[str, ...] = GALLERY_PRESETS) -> list[Chain]:
    """Clean, then every registered degradation at every preset."""
    names = [spec.name for spec in list_degradations()]
    return [Chain()] + [Chain.parse(f"{name}:{preset}") for name in names for preset in presets]


def _id_maps(scene, views, provenance, options, cache):
    lens = tuple((e["name"], tuple(sorted(e["params"].items()))) for e in provenance if e["name"] == "distortion")
    key = (tuple(views), lens)
    if key not in cache:
        cache[key] = object_id_maps(scene, views, [e for e in provenance if e["name"] == "distortion"], options)
    return cache[key]


def measure(scene, items, chains, options, seed=0):
    """Rows ``{degradation_type, severity, answerable, groups}`` for ``items`` = ``[(views, groups or record)]``."""
    rows, cache = [], {}
    for k, (views, what) in enumerate(items):
        results = degrade_variants(scene, views, chains, derive_seed(seed, "answerability", k), options)
        for chain, result in zip(chains, results):
            maps = _id_maps(scene, views, result.degradations, options, cache)
            if isinstance(what, list):
                answer = groups_answerability(what, result.images, maps, views)
            else:
                answer = item_answerability(what, result.images, maps, views)
            kind, severity = condition_of(chain.name, result.degradations)
            rows.append({"degradation_type": kind, "severity": severity, "answerable": answer.answerable, "groups": answer.groups})
    return rows


def room_items(rooms: int, records: int, gaussians: int):
    """``[(scene, [(views, record)])]`` for built-in rooms: questions of every family, prepared scenes."""
    import tempfile

    from spacedg.qa.build import generate_records, prepare_scene
    from spacedg.qa.index import QABuildConfig
    from spacedg.scene.synthetic import RoomConfig, generate_room

    out = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(rooms):
            scene = generate_room(seed, RoomConfig(gaussians=gaussians))
            scene = prepare_scene(scene, Path(tmp) / f"room{seed}", QABuildConfig(), progress=False)
            recs = generate_records(scene, QABuildConfig(seed=seed, per_sub_type=2))
            named = [r for r in recs if r.geometry.get("refs") or r.geometry.get("counted") or r.geometry.get("instances")]
            rng = np.random.default_rng(seed)
            pick = rng.permutation(len(named))[:records]
            out.append((scene, [(tuple(named[i].views), named[i]) for i in sorted(pick)]))
    return out


def object_items(name: str, views: int, size: tuple[int, int]):
    """One splat object alone (0.25 m across, instance 0), ``views`` cameras on a ring at 0.4–0.6 m."""
    from spacedg.render.camera import Camera, look_at
    from spacedg.render.gaussians import Gaussians
    from spacedg.scene.box import OrientedBox
    from spacedg.scene.io.splat import read_splat
    from spacedg.scene.model import Instance, Scene

    g = read_splat(next((SPLATS / name).glob("*.splat")))
    means = np.asarray(g.means, dtype=np.float64)
    centre = (means.max(0) + means.min(0)) / 2
    k = 0.25 / float((means.max(0) - means.min(0)).max())
    scaled = Gaussians((means - centre) * k, g.quats, np.asarray(g.scales) * k, g.opacities, g.sh, np.zeros(len(means), np.int32))
    ext = (means.max(0) - means.min(0)) * k
    w, h = size
    cams = {}
    for i in range(views):
        a = 2 * math.pi * i / views
        r = 0.4 + 0.2 * (i % 3) / 2
        eye = np.array([r * math.cos(a), 0.12 * (1 - 2 * (i % 2)), r * math.sin(a)])
        f = 0.9 * w
        cams[f"view_{i:02d}"] = Camera(f, f, w / 2, h / 2, w, h, look_at(eye, np.zeros(3), np.array([0.0, -1.0, 0.0])))
    scene = Scene(f"object-{name}", scaled, cams, [Instance(0, name, name, OrientedBox(np.zeros(3), ext, np.eye(3)))], [0.0, -1.0, 0.0], None, {})
    return scene, [((v,), [(v, (0,))]) for v in cams]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rooms", type=int, default=2)
    parser.add_argument("--records", type=int, default=24, help="questions naming objects, per room")
    parser.add_argument("--gaussians", type=int, default=60_000)
    parser.add_argument("--object", default="teapot", help="splat folder under ../shared/data/splats")
    parser.add_argument("--views", type=int, default=12, help="views of the object")
    parser.add_argument("--size", default="320x240")
    parser.add_argument("--only", default=None, help="comma-separated degradations (default: all)")
    args = parser.parse_args(argv)
    size = tuple(int(v) for v in args.size.lower().split("x"))
    options = PipelineOptions(image_size=size)
    chains = conditions()
    if args.only:
        keep = set(args.only.split(","))
        chains = [c for c in chains if c.is_clean or c.name in keep]
    print(f"python {' '.join(sys.argv)}", flush=True)
    sets = []
    if (SPLATS / args.object).is_dir():
        sets.append(("object " + args.object, [object_items(args.object, args.views, size)]))
    else:
        print(f"(no {SPLATS / args.object}: the object scene is skipped)")
    if args.rooms:
        sets.append((f"{args.rooms} built-in room(s)", room_items(args.rooms, args.records, args.gaussians)))
    for title, scenes in sets:
        started, rows = time.perf_counter(), []
        for scene, items in scenes:
            rows += measure(scene, items, chains, options)
        seconds = time.perf_counter() - started
        print(f"\n### {title}: {len(rows) // len(chains)} items x {len(chains)} conditions at {size[0]}x{size[1]} "
              f"({seconds / max(len(rows), 1) * 1e3:.0f} ms per item and condition, render included)\n")
        print(answerability_table(share_by_condition(rows)), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
