"""``spacedg qa build`` / ``spacedg qa stats``: per-scene question indexes and their balance."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from tqdm import tqdm

from spacedg.commands import _args
from spacedg.errors import InvalidDataError


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    qa = subparsers.add_parser("qa", help="build question indexes of scenes and summarise them")
    sub = qa.add_subparsers(dest="qa_command", required=True, metavar="ACTION")

    build = sub.add_parser(
        "build", help="generate every family's questions for scenes (JSONL per scene)",
        description="Build each scene's question index. Without --families: the full index <scene id>.qa.jsonl "
        "(every registered family), the one SpaceDGDataset, export and review read. With --families a,b: a selection "
        "index <scene id>.qa.a+b.jsonl (names sorted, joined by '+') written beside the full index, which is never "
        "replaced; its records equal that selection's records in a full index built with the same settings.",
    )
    build.add_argument("scenes", type=Path, nargs="+", help="native scene folders, or folders of them")
    build.add_argument("--out", type=Path, default=None, help="folder for the index files (default: next to each scene)")
    build.add_argument("--seed", type=int, default=0, help="master seed (default 0)")
    build.add_argument(
        "--families", default="",
        help="comma-separated family names: write them to their own <scene id>.qa.<a+b>.jsonl beside the full index, "
        "which stays untouched (default: all registered families, written to <scene id>.qa.jsonl)",
    )
    build.add_argument("--per-sub-type", type=int, default=25, help="records per sub_question_type and family per scene (default 25)")
    build.add_argument("--force", action="store_true", help="rebuild even when the index is up to date")
    build.add_argument("--backend", default="auto", choices=("auto", "cpu", "torch"), help="renderer for visibility/covisibility")
    build.set_defaults(func=_build)

    preview = sub.add_parser("preview", help="PNG sheet of a scene's questions: views, named objects' boxes, text")
    preview.add_argument("scene", type=Path, help="a native scene folder (its index is built first if missing)")
    preview.add_argument("--out", type=Path, required=True, help="PNG file to write")
    preview.add_argument("--n", type=int, default=8, help="number of questions (default 8, spread over question types)")
    preview.add_argument("--types", default="", help="comma-separated question types to show (default: all)")
    preview.add_argument("--seed", type=int, default=0, help="which questions are picked (default 0)")
    preview.add_argument("--thumb-width", type=int, default=256, help="width of each view, pixels")
    preview.add_argument("--backend", default="auto", choices=("auto", "cpu", "torch"))
    preview.set_defaults(func=_preview)

    stats = sub.add_parser("stats", help="counts per question type, answer balance, blind baseline")
    stats.add_argument("paths", type=Path, nargs="+", help="*.qa.jsonl files, or folders holding them (scene folders work)")
    stats.add_argument("--families", default="",
                       help="in folders, read the selection indexes that `qa build --families` wrote with these names "
                       "(default: the full indexes <scene id>.qa.jsonl)")
    stats.add_argument("--json", action="store_true", help="print JSON instead of tables")
    stats.set_defaults(func=_stats)


def _build(args: argparse.Namespace) -> int:
    from spacedg.commands.scenes import _scene_dirs
    from spacedg.data.qa_index import QABuildConfig, build_scene_index

    _args.seed("--seed", args.seed)
    _args.at_least("--per-sub-type", args.per_sub_type, 1)
    if args.out is not None:
        _args.output_folder("--out", args.out)
    config = QABuildConfig(seed=args.seed, families=_family_names(args.families), per_sub_type=args.per_sub_type)
    tqdm.write(f"{'scene':<16} {'records':>8} {'visibility s':>12} {'covis s':>8} {'generate s':>10} {'q/s':>8}  index")
    total = 0
    start = time.perf_counter()
    for folder in tqdm(_scene_dirs(args.scenes), desc="qa build", unit="scene"):
        result = build_scene_index(folder, config, out_dir=args.out, force=args.force, backend=args.backend)
        s = result.seconds
        gen = s.get("generate_s", 0.0)
        rate = f"{len(result.records) / gen:,.0f}" if gen > 0 and not result.reused else "-"
        note = "reused" if result.reused else ""
        tqdm.write(f"{result.scene_id:<16} {len(result.records):>8} {s.get('visibility_s', 0):>12.2f} {s.get('covisibility_s', 0):>8.2f} "
              f"{gen:>10.3f} {rate:>8}  {result.path} {note}")
        total += len(result.records)
    print(f"{total} records in {time.perf_counter() - start:.1f} s")
    return 0


def _family_names(text: str) -> tuple[str, ...]:
    return tuple(f.strip() for f in text.split(",") if f.strip())


def _index_files(paths: list[Path], families: tuple[str, ...] = ()) -> list[Path]:
    """Index files named by ``paths``: files as given; in folders (or their sub-folders) the full
    indexes ``*.qa.jsonl``, or with ``families`` that selection's ``*.qa.<selection>.jsonl``."""
    from spacedg.data.qa_index import selection_name

    selection = selection_name(families)
    pattern = f"*.qa.{selection}.jsonl" if selection else "*.qa.jsonl"
    found: list[Path] = []
    for path in paths:
        if path.is_file():
            found.append(path)
        elif path.is_dir():
            files = sorted(path.glob(pattern)) or sorted(path.glob(f"*/{pattern}"))
            if not files:
                others = sorted(p.name for p in [*path.glob("*.qa.*.jsonl"), *path.glob("*/*.qa.*.jsonl")])
                hint = f" (it has selection indexes {others[:3]}: pass --families)" if others and not selection else ""
                raise InvalidDataError(f"{path}: no {pattern} in it or its sub-folders{hint}; build them with `spacedg qa build`")
            found.extend(files)
        else:
            raise InvalidDataError(f"{path}: no such file or folder")
    return found


def _stats(args: argparse.Namespace) -> int:
    from spacedg.data.qa_index import read_index
    from spacedg.data.qa_stats import answer_balance, blind_baseline, count_table, format_table

    by_scene = {}
    for file in _index_files(args.paths, _family_names(args.families)):
        records = read_index(file)
        if records:
            by_scene.setdefault(records[0].scene_id, []).extend(records)
    every = [r for rs in by_scene.values() for r in rs]
    report = {
        "scenes": len(by_scene), "records": len(every), "counts": count_table(every),
        "balance": answer_balance(every), "blind_baseline": blind_baseline(by_scene) if len(by_scene) > 1 else [],
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    print(f"{report['records']} records from {report['scenes']} scene(s)\n")
    print(format_table(report["counts"]))
    bal = report["balance"]
    letters = "  ".join(f"{k} {v:.1f}%" for k, v in bal["letters"].items())
    print(f"\nMCQ correct letter over {bal['mcq_n']} records: {letters}")
    print(f"YN over {bal['yn_n']} records: yes {bal['yes_pct']:.1f}%")
    if report["blind_baseline"]:
        print("\nBlind baseline (leave-one-scene-out majority, accuracy %):")
        print(format_table(report["blind_baseline"]))
    return 0


def _pick(records: list, n: int, types: set[str], seed: int) -> list:
    """Up to ``n`` records, one question type after another (types in name order), seeded."""
    import numpy as np

    by_type: dict[str, list] = {}
    for r in records:
        if not types or r.question_type in types:
            by_type.setdefault(r.question_type, []).append(r)
    rng = np.random.default_rng(seed)
    queues = {t: [rs[i] for i in rng.permutation(len(rs))] for t, rs in sorted(by_type.items())}
    picked: list = []
    while len(picked) < n and any(queues.values()):
        for queue in queues.values():
            if queue and len(picked) < n:
                picked.append(queue.pop())
    return picked


def _preview(args: argparse.Namespace) -> int:
    from spacedg.commands.render import write_png_atomic
    from spacedg.scene.io import load_scene
    from spacedg.data.qa_index import build_scene_index
    from spacedg.data.qa_preview import qa_sheet

    if args.n < 1 or args.thumb_width < 32:
        raise InvalidDataError(f"--n must be >= 1 and --thumb-width >= 32, got {args.n} and {args.thumb_width}")
    _args.in_range("--thumb-width", args.thumb_width, 32, 4096, "pixels")
    _args.seed("--seed", args.seed)
    _args.output_file("--out", args.out, (".png",))
    types = {t.strip() for t in args.types.split(",") if t.strip()}
    index = build_scene_index(args.scene, backend=args.backend)
    records = _pick(index.records, args.n, types, args.seed)
    if not records:
        known = sorted({r.question_type for r in index.records})
        raise InvalidDataError(f"{args.scene}: no questions of type(s) {sorted(types)}; the index has {known}")
    scene = load_scene(args.scene)
    sheet = qa_sheet(scene, records, thumb_width=args.thumb_width, backend=args.backend)
    write_png_atomic(args.out, sheet[:, :, ::-1], "--out")
    print(f"wrote {args.out} ({len(records)} questions, {sheet.shape[1]}x{sheet.shape[0]} px)")
    return 0
