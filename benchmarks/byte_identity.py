"""Byte identity of spacedg's outputs across a refactor: scenes, renders, question indexes, exports.

Runs the public surface only (the ``spacedg`` command line and the top-level Python API), so the
same script runs unchanged on any revision, then prints one SHA-256 per output file:

- three small built-in rooms (``scenes synth``: ``scene.json``, ``gaussians.ply``);
- renders of one view (``spacedg render``: clean, depth PNG, defocus, fisheye, motion blur exact
  and fast) and the raw float32 arrays of ``spacedg.render`` (rgb, alpha, depth, median depth,
  instance ids);
- each room's question index (``qa build``: ``<room>.qa.jsonl``);
- a small bench export (``export --split bench``: ``bench.tsv``, ``bench.jsonl``, every PNG) and a
  train export whose chains include a mixture, a preset and a ``+`` chain.

    .venv/bin/python benchmarks/byte_identity.py --record benchmarks/byte_identity_a89ff82.json
    .venv/bin/python benchmarks/byte_identity.py --check benchmarks/byte_identity_a89ff82.json

``--check`` prints every file whose hash differs (or is missing) and exits 1 if any does.
``summary.json`` files are left out of the comparison (they carry wall-clock times).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

BIN = Path(sys.executable).parent
SPACEDG = str(BIN / "spacedg")


def _run(*args: str) -> None:
    """Run one ``spacedg`` command; fail loudly with its output."""
    proc = subprocess.run([SPACEDG, *args], capture_output=True, text=True)
    if proc.returncode != 0:
        raise SystemExit(f"spacedg {' '.join(args)} failed ({proc.returncode}):\n{proc.stdout}\n{proc.stderr}")


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _array_sha(array: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(array).tobytes()).hexdigest()


def collect(work: Path) -> dict[str, str]:
    """Produce every output under ``work`` and return {relative name: sha256}."""
    hashes: dict[str, str] = {}
    scenes = work / "scenes"
    _run("scenes", "synth", "--n", "3", "--seed", "0", "--gaussians", "40000", "--min-views", "16",
         "--max-views", "20", "--width", "160", "--height", "120", "--out", str(scenes))
    for room in sorted(scenes.iterdir()):
        for name in ("scene.json", "gaussians.ply"):
            hashes[f"scenes/{room.name}/{name}"] = _sha(room / name)

    room0 = scenes / "room-000000"
    renders = work / "renders"
    renders.mkdir()
    variants = {
        "clean": [],
        "defocus": ["--defocus", "12,1.5"],
        "fisheye": ["--fisheye", "-0.24,2e-4,1.5e-4,5e-5,1.5"],
        "motion": ["--motion", "0.25,0,0.1,0,0.08,0", "--sub-steps", "24"],
        "motion_fast": ["--motion", "0.25,0,0.1,0,0.08,0", "--fast-motion"],
    }
    for name, extra in variants.items():
        out = renders / f"{name}.png"
        args = ["render", str(room0), "--view", "frame_0003", "--out", str(out), *extra]
        if name == "clean":
            args += ["--depth-out", str(renders / "clean_depth.png")]
        _run(*args)
    for png in sorted(renders.iterdir()):
        hashes[f"renders/{png.name}"] = _sha(png)

    import spacedg

    scene = spacedg.load_scene(room0)
    camera = scene.views[sorted(scene.views)[5]]
    frame = spacedg.render(scene.gaussians, camera, outputs="rgb,alpha,depth,median_depth,instance_ids")
    for field in ("rgb", "alpha", "depth", "median_depth", "instance_ids"):
        value = getattr(frame, field)
        if value is not None:
            hashes[f"frame/{field}"] = _array_sha(np.asarray(value))

    _run("qa", "build", str(scenes), "--per-sub-type", "6")
    for room in sorted(scenes.iterdir()):
        hashes[f"qa/{room.name}.qa.jsonl"] = _sha(room / f"{room.name}.qa.jsonl")

    bench = work / "bench"
    _run("export", "--split", "bench", "--scenes", str(scenes), "--out", str(bench), "--image-size",
         "96x72", "--max-questions", "22", "--no-progress")
    train = work / "train"
    _run("export", "--split", "train", "--scenes", str(scenes), "--out", str(train), "--image-size",
         "96x72", "--max-questions", "30", "--clean-prob", "0.2", "--degradations",
         "night_capture,haze:3+low_res,motion_blur:2,compressed_portrait,jpeg_compression", "--no-progress")
    for folder in (bench, train):
        for path in sorted(folder.rglob("*")):
            if path.is_file() and path.name != "summary.json" and not path.name.startswith("."):
                hashes[f"{folder.name}/{path.relative_to(folder)}"] = _sha(path)
    return hashes


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--record", type=Path, help="write the hashes of this revision to FILE")
    group.add_argument("--check", type=Path, help="compare this revision's hashes with FILE")
    parser.add_argument("--keep", type=Path, help="produce the outputs in this folder and keep them")
    args = parser.parse_args(argv)

    os.environ.setdefault("SPACEDG_DISABLE_PLUGIN_AUTOLOAD", "1")
    start = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        work = args.keep or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        hashes = collect(work)
    elapsed = time.perf_counter() - start
    revision = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    print(f"{len(hashes)} outputs hashed in {elapsed:.1f} s at {revision}")
    if args.record:
        args.record.write_text(json.dumps({"revision": revision, "hashes": hashes}, indent=1, sort_keys=True) + "\n")
        print(f"recorded in {args.record}")
        return 0
    reference = json.loads(args.check.read_text())
    expected: dict[str, str] = reference["hashes"]
    differing = sorted(k for k in expected.keys() | hashes.keys() if expected.get(k) != hashes.get(k))
    for name in differing:
        print(f"DIFFERS  {name}: {expected.get(name, 'missing')[:12]} -> {hashes.get(name, 'missing')[:12]}")
    print(f"{len(expected) - len(differing)}/{len(expected)} identical to {reference['revision']}"
          + ("" if not differing else f"; {len(differing)} differ"))
    return 1 if differing else 0


if __name__ == "__main__":
    raise SystemExit(main())
