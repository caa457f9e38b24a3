"""``spacedg qa build`` / ``stats`` / ``audit`` / ``preview``: per-scene question indexes, their
balance, repeats and ambiguities, and the blind stress test."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path
from typing import Any

from tqdm import tqdm

from spacedg.commands import _args, _vocabulary
from spacedg.errors import InvalidDataError

#: Most null audits `qa audit --null` runs (each is a full blind audit).
MAX_NULL_RUNS = 10_000


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    qa = subparsers.add_parser("qa", help="build question indexes of scenes and summarise them")
    sub = qa.add_subparsers(dest="qa_command", required=True, metavar="ACTION")

    build = _args.add_command(sub, "build", _build, help="generate every family's questions for scenes (JSONL per scene)")
    build.add_argument("scenes", type=Path, nargs="+", help="native scene folders, or folders of them")
    build.add_argument("--out", type=Path, default=None, help="folder for the index files (default: next to each scene)")
    build.add_argument("--seed", type=_args.SEED, default=0, help="master seed (default 0)")
    build.add_argument(
        "--families", default="",
        help="comma-separated family names: write them to their own <scene id>.qa.<a+b>.jsonl beside the full index, "
        "which stays untouched (default: all registered families, written to <scene id>.qa.jsonl)",
    )
    build.add_argument("--per-sub-type", type=_args.whole(1), default=25, help="records per sub_question_type and family per scene (default 25)")
    build.add_argument("--force", action="store_true", help="rebuild even when the index is up to date")
    build.add_argument("--shard", default="0/1",
                       help="i/n: build the scenes k (in sorted order) with k %% n == i, for n jobs on other machines; 'env' reads "
                       "RANK/WORLD_SIZE (torchrun), SLURM_ARRAY_TASK_ID/SLURM_ARRAY_TASK_COUNT or SLURM_PROCID/SLURM_NTASKS (default 0/1)")
    build.add_argument("--jobs", type=_args.whole(1), default=None,
                       help="processes, one scene each (default: min(scenes, cores) on the CPU, 1 with --device cuda; "
                       "1 = serially in this process); each renders with cores // jobs threads")
    build.add_argument("--mode", choices=("bench", "train"), default="bench",
                       help="bench: strict selection, an object asked at most once per sub type and scene (<id>.qa.jsonl); train: "
                            "dense, each object from many views, 4x the records (<id>.qa-train.jsonl); see docs/question-modes.md")
    build.add_argument("--partial-rounds", action="store_true",
                       help="also take partial rounds of the balancing cells' roles (bench mode): the candidates of a bench whose "
                            "roles are balanced across its scenes afterwards, as `spacedg export --split bench` builds them for the "
                            "blind pruning; such an index is not balanced on its own and is written to <id>.qa-pooled.jsonl "
                            "(`spacedg qa audit --debias --mode pooled` prunes them as the export does)")
    _args.add_backend_arguments(build, "renderer of visibility and covisibility")

    preview = _args.add_command(
        sub, "preview", _preview, help="PNG sheet of a scene's questions (from its index): views, named objects' boxes, text",
    )
    preview.add_argument("scene", type=Path, help="a native scene folder whose index `spacedg qa build` wrote beside it")
    preview.add_argument("--out", type=Path, required=True, help="PNG file to write")
    preview.add_argument("--n", type=_args.whole(1, 1000, "questions"), default=8,
                         help="number of questions (default 8, spread over question families)")
    preview.add_argument("--families", default="", help="comma-separated question families to show (default: all)")
    preview.add_argument("--seed", type=_args.SEED, default=0, help="which questions are picked (default 0)")
    preview.add_argument("--thumb-width", type=_args.whole(32, 4096, "pixels"), default=256, help="width of each view, pixels")
    _args.add_backend_arguments(preview, device=False)
    _vocabulary.add_deprecated(preview, "qa preview")

    stats = _args.add_command(
        sub, "stats", _stats, help="counts per question type, answer balance, blind stress test, repeats, ambiguities",
    )
    _add_index_inputs(stats)
    stats.add_argument("--scenes", type=Path, nargs="*", default=[],
                       help="scene folders (or folders of them) for the label ambiguity check when the indexes were written elsewhere")
    stats.add_argument("--no-blind", action="store_true", help="skip the blind stress test")
    stats.add_argument("--json", action="store_true", help="print JSON instead of tables")
    stats.add_argument("--mode", choices=("bench", "train"), default="bench",
                       help="which indexes the report reads (bench: <id>.qa.jsonl, train: <id>.qa-train.jsonl); "
                            "the records per scene and object re-asks of both modes are printed where they exist")

    audit = _args.add_command(
        sub, "audit", _audit, help="blind stress test: what text-only models answer without the images, per sub type",
    )
    _add_index_inputs(audit)
    audit.add_argument("--mode", choices=("bench", "train", "pooled"), default="bench",
                       help="which indexes it reads: bench <id>.qa.jsonl, train <id>.qa-train.jsonl, pooled <id>.qa-pooled.jsonl "
                            "(a bench's candidates, `qa build --partial-rounds`)")
    audit.add_argument("--solved", type=Path, default=None, help="write the ids of the records the blind models solve (JSONL)")
    audit.add_argument("--show", type=_args.whole(0), default=0, metavar="N", help="print this many solved questions per sub type")
    audit.add_argument("--no-learned", action="store_true", help="skip the logistic model (count-based priors only)")
    audit.add_argument("--null", type=_args.whole(0, MAX_NULL_RUNS, "runs"), default=0, metavar="RUNS",
                       help="also audit RUNS times with truths drawn independently of the text, and print the mean and 95th "
                            "percentile of the best excess over chance that chance alone gives at each sub type's n")
    audit.add_argument("--json", action="store_true", help="print JSON instead of tables")
    audit.add_argument("--debias", action="store_true",
                       help="also pool the records, probe them k-fold by scene (chance = 1 / options shown) and prune what the "
                       "blind models solve, as a bench export does (the cells' roles balanced across the scenes first, for indexes "
                       "built with --partial-rounds); print before/after per sub type and each round's removals")


def _build(args: argparse.Namespace) -> int:
    """Build each scene's question index. Without --families: the full index <scene id>.qa.jsonl (every
    registered family), the one SpaceDGDataset, export and review read. With --families a,b: a selection
    index <scene id>.qa.a+b.jsonl (names sorted, joined by '+') written beside the full index, which is
    never replaced; its records equal that selection's records in a full index built with the same
    settings. --shard i/n builds this job's share of the scenes; --jobs N builds N scenes at once (one
    process each); the index files are the same bytes whichever split (spacedg.qa.jobs).
    """
    import os

    from spacedg.commands.scenes import _scene_dirs
    from spacedg.data.shards import chunk_ids, resolve_shard
    from spacedg.data.workers import pool_plan
    from spacedg.qa.index import QABuildConfig, selected_families
    from spacedg.qa.jobs import build_indexes

    shard = resolve_shard(args.shard, os.environ)
    if args.out is not None:
        _args.output_folder("--out", args.out)
    config = QABuildConfig(seed=args.seed, families=_family_names(args.families), per_sub_type=args.per_sub_type, mode=args.mode,
                           partial_rounds=args.partial_rounds)
    selected_families(config.families)  # an unknown family name fails here, before the table starts
    every = _scene_dirs(args.scenes)
    mine = [every[k] for k in chunk_ids(len(every), 1, shard)]
    on_gpu = args.device not in (None, "cpu")
    plan = pool_plan(len(mine), jobs=1 if on_gpu and args.jobs is None else args.jobs)
    tqdm.write(f"shard {shard[0]}/{shard[1]}: {len(mine)} of {len(every)} scene(s); {plan.processes} process(es) x {plan.threads} thread(s)")
    tqdm.write(f"{'scene':<16} {'records':>8} {'visibility s':>12} {'covis s':>8} {'generate s':>10} {'q/s':>8}  index")
    total = 0
    start = time.perf_counter()
    rows = build_indexes(mine, config, out_dir=args.out, force=args.force, backend=args.backend, device=args.device,
                         jobs=plan.processes, threads=plan.threads, progress=plan.processes == 1)
    for row in tqdm(rows, total=len(mine), desc="qa build", unit="scene"):
        _print_row(row)
        total += row.records
    print(f"{total} records in {time.perf_counter() - start:.1f} s")
    return 0


def _print_row(row) -> None:
    """One line of the build table for a :class:`~spacedg.qa.jobs.BuildRow`."""
    s = row.seconds
    gen = s.get("generate_s", 0.0)
    rate = f"{row.records / gen:,.0f}" if gen > 0 and not row.reused else "-"
    note = "reused" if row.reused else ""
    tqdm.write(f"{row.scene_id:<16} {row.records:>8} {s.get('visibility_s', 0):>12.2f} {s.get('covisibility_s', 0):>8.2f} "
               f"{gen:>10.3f} {rate:>8}  {row.path} {note}")


def _family_names(text: str) -> tuple[str, ...]:
    return tuple(f.strip() for f in text.split(",") if f.strip())


def _index_files(paths: list[Path], families: tuple[str, ...] = (), mode: str = "bench") -> list[Path]:
    """Index files named by ``paths``: files as given; in folders (or their sub-folders) the full
    indexes ``*.qa.jsonl``, or with ``families`` that selection's ``*.qa.<selection>.jsonl``
    (``mode="train"``: ``*.qa-train.jsonl``, ``*.qa-train.<selection>.jsonl``)."""
    from spacedg.qa.index import selection_name

    selection = selection_name(families)
    head = "*.qa" if mode == "bench" else f"*.qa-{mode}"
    pattern = f"{head}.{selection}.jsonl" if selection else f"{head}.jsonl"
    found: list[Path] = []
    for path in paths:
        if path.is_file():
            found.append(path)
        elif path.is_dir():
            files = sorted(path.glob(pattern)) or sorted(path.glob(f"*/{pattern}"))
            if not files:
                others = sorted(p.name for p in [*path.glob("*.qa.*.jsonl"), *path.glob("*/*.qa.*.jsonl")])
                hint = f" (it has selection indexes {others[:3]}: pass --families)" if others and not selection else ""
                build = "`spacedg qa build --partial-rounds`" if mode == "pooled" else "`spacedg qa build`"
                raise InvalidDataError(f"{path}: no {pattern} in it or its sub-folders{hint}; build them with {build}")
            found.extend(files)
        else:
            raise InvalidDataError(f"{path}: no such file or folder")
    return found


def _records_by_scene(paths: list[Path], families: str, mode: str = "bench") -> dict[str, list]:
    from spacedg.qa.index import read_index

    by_scene: dict[str, list] = {}
    for file in _index_files(paths, _family_names(families), mode):
        records = read_index(file)
        if records:
            by_scene.setdefault(records[0].scene_id, []).extend(records)
    return by_scene


def _scenes_with_visibility(by_scene: dict[str, list], paths: list[Path], extra: list[Path]) -> dict[str, object]:
    """Scene id → scene with its cached visibility, for the scene folders found beside the
    indexes or under ``extra`` (missing scenes are left out)."""
    from spacedg.qa.index import QABuildConfig
    from spacedg.errors import SpaceDGError
    from spacedg.scene.io import load_scene
    from spacedg.scene.visibility import load_or_compute_visibility, with_visibility

    folders: dict[str, Path] = {}
    for root in [*paths, *extra]:
        root = root if root.is_dir() else root.parent
        for candidate in [root, *sorted(p.parent for p in root.glob("*/scene.json"))]:
            if (candidate / "scene.json").is_file():
                folders.setdefault(candidate.name, candidate)
    out: dict[str, object] = {}
    size = QABuildConfig().visibility_size
    for scene_id in by_scene:
        folder = folders.get(scene_id)
        if folder is None:
            continue
        try:
            scene = load_scene(folder)
            out[scene_id] = with_visibility(scene, load_or_compute_visibility(scene, folder / "cache", image_size=size, progress=False))
        except (SpaceDGError, OSError, ValueError) as err:
            tqdm.write(f"{folder}: no ambiguity check ({err})")
    return out


def _stats(args: argparse.Namespace) -> int:
    """Counts, correct-letter and yes/no balance, the blind stress test (as `qa audit`), the repeat rate
    (records re-asking a subject already asked in the scene and sub type) and ambiguity counts (label-
    only questions beside a related label or an object showing the label, undecidable size comparisons,
    imperceptible rotations; the label checks read the scenes' cached visibility: scene folders beside
    the indexes, or --scenes).
    """
    from spacedg.qa.audit import blind_audit, format_audit
    from spacedg.qa.stats import ambiguities, answer_balance, blind_baseline, count_table, format_table, repeat_rate

    by_scene = _records_by_scene(args.paths, args.families, args.mode)
    every = [r for rs in by_scene.values() for r in rs]
    scenes = _scenes_with_visibility(by_scene, args.paths, args.scenes)
    audit = blind_audit(by_scene) if len(by_scene) > 1 and not args.no_blind else None
    report = {
        "mode": args.mode, "scenes": len(by_scene), "records": len(every), "counts": count_table(every),
        "balance": answer_balance(every), "blind_baseline": blind_baseline(by_scene) if len(by_scene) > 1 else [],
        "blind": audit.to_dict() if audit else None,
        "repeats": repeat_rate(by_scene), "ambiguities": ambiguities(every, scenes),
        **_mode_report(args, by_scene),
    }
    if args.json:
        print(json.dumps(report, indent=2))
        return 0
    print(f"{report['records']} records from {report['scenes']} scene(s)\n")
    print(format_table(report["counts"]))
    bal = report["balance"]
    letters = "  ".join(f"{k} {v:.1f}%" for k, v in bal["letters"].items())
    print(f"\nMCQ correct letter over {bal['mcq_n']} records: {letters}")
    if bal["mcq3_n"]:
        letters3 = "  ".join(f"{k} {v:.1f}%" for k, v in bal["letters3"].items())
        print(f"3-option MCQ correct letter over {bal['mcq3_n']} records: {letters3}")
    print(f"YN over {bal['yn_n']} records: yes {bal['yes_pct']:.1f}%")
    if audit is not None:
        print("\nBlind stress test (leave-one-scene-out, text only; accuracy %, MRA % for metric answers):")
        print(format_audit(audit))
    rep = report["repeats"]
    if rep:
        total = rep[-1]
        worst = [r for r in rep[:-1] if r["repeats"]]
        print(f"\nRepeats (subject already asked in the scene and sub type): {total['repeats']} of {total['n']} "
              f"({total['repeat_pct']:.1f}%)")
        if worst:
            print(format_table(worst, ["question_type", "sub_question_type", "n", "repeats", "repeat_pct"]))
    _print_modes(report)
    amb = report["ambiguities"]
    print(f"\nAmbiguities: label-only questions beside a related label {amb['label_related']}, beside an object showing the "
          f"label unannotated {amb['label_shown_unannotated']} (of {amb['checked_label_only']} checked against {len(scenes)} "
          f"scene(s)); undecidable size comparisons {amb['size_undecidable']}; rotations naming a component under 5° "
          f"{amb['rotation_imperceptible']}")
    return 0


def _mode_report(args: argparse.Namespace, by_scene: dict[str, list]) -> dict[str, object]:
    """``count_answers``, ``object_reasks`` of the read mode and ``modes``: one row per mode whose indexes exist."""
    from spacedg.qa.mode_stats import count_distribution, mode_row, object_reasks

    every = [r for rs in by_scene.values() for r in rs]
    rows = [mode_row(args.mode, by_scene)]
    other = "train" if args.mode == "bench" else "bench"
    if all(p.is_dir() for p in args.paths):  # index files given one by one: their mode only
        try:
            rows.append(mode_row(other, _records_by_scene(args.paths, args.families, other)))
        except InvalidDataError:
            pass  # no index of the other mode there
    rows.sort(key=lambda row: row["mode"])
    return {"count_answers": count_distribution(every), "object_reasks": object_reasks(by_scene), "modes": rows}


def _print_modes(report: dict) -> None:
    from spacedg.qa.mode_stats import format_counts
    from spacedg.qa.stats import format_table

    print(f"\nCounting answers ({report['mode']}): {format_counts(report['count_answers'])}")
    reasks = report["object_reasks"]
    if reasks:
        total = reasks[-1]
        print(f"Object re-asks ({report['mode']}: same object or pair, same sub type and scene, any view): "
              f"{total['reasks']} of {total['n']}, at most {total['max_per_object']} per object")
        worst = [r for r in reasks[:-1] if r["reasks"]]
        if worst:
            print(format_table(worst, ["question_type", "sub_question_type", "n", "reasks", "max_per_object"]))
    print("\nSelection modes (docs/question-modes.md):")
    for row in report["modes"]:
        print(f"  {row['mode']:<6} {row['scenes']} scene(s), {row['records']} records ({row['per_scene']:.0f} per scene), "
              f"{row['reasks']} object re-asks")


def _audit(args: argparse.Namespace) -> int:
    """Leave-one-scene-out text-only predictors (majority letter, majority answer per template, option-text
    prior, per-label priors incl. mean size per label, a logistic model on the question text) trained on
    the other scenes and scored on the held-out one; prints accuracy (MRA for metric answers), chance,
    and how many items the blind models solve. Needs indexes of at least two scenes.
    """
    from spacedg.qa.audit import blind_audit, format_audit

    by_scene = _records_by_scene(args.paths, args.families, args.mode)
    if len(by_scene) < 2:
        raise InvalidDataError(f"qa audit: found question indexes of {len(by_scene)} scene(s); the blind models are trained on "
                               "other scenes and scored on a held-out one, so give at least two")
    start = time.perf_counter()
    balanced: dict[str, int] = {}
    if args.mode == "pooled":  # a bench's candidates: audited (and pruned) as the export uses them, roles balanced across scenes
        from spacedg.qa.cell_balance import balance_cells

        even = balance_cells([r for rs in by_scene.values() for r in rs])
        keep, balanced = {r.id for r in even.kept}, even.removed
        by_scene = {scene: [r for r in rs if r.id in keep] for scene, rs in by_scene.items()}
    report = blind_audit(by_scene, learned=not args.no_learned)
    if args.null > 0:
        from spacedg.qa.audit import null_audit, with_null

        report = with_null(report, null_audit(by_scene, args.null, learned=not args.no_learned))
    pruned = _debias(by_scene, not args.no_learned, balanced) if args.debias else None
    seconds = time.perf_counter() - start
    if args.solved is not None:
        from spacedg.files import atomic_write_bytes

        atomic_write_bytes(args.solved, "".join(json.dumps({"id": i}) + "\n" for i in report.solved).encode("utf-8"))
    if args.json:
        print(json.dumps({**report.to_dict(), **({"debias": pruned.to_dict()} if pruned else {}), "seconds": seconds}, indent=2))
        return 0
    n = sum(len(v) for v in by_scene.values())
    print(f"Blind stress test over {n} records of {len(by_scene)} scenes ({seconds:.1f} s): text-only models trained on the "
          "other scenes, scored on the held-out one; accuracy % (MRA % for NA / SIZE_LIST); chance = uniform over the "
          "options that can be correct")
    print(format_audit(report))
    if pruned is not None:
        from spacedg.qa.debias import format_debias

        print("\n" + format_debias(pruned))
    if args.show > 0:
        solved = set(report.solved)
        shown: dict[tuple[str, str], int] = {}
        for r in (r for rs in by_scene.values() for r in rs):
            key = (r.question_type, r.sub_question_type)
            if r.id in solved and shown.get(key, 0) < args.show:
                shown[key] = shown.get(key, 0) + 1
                options = "  ".join(r.options)
                print(f"\n[{key[0]}/{key[1]}] {r.id}\n  {r.question}\n  {options}\n  answer: {r.answer}")
    return 0


def _debias(by_scene: dict, learned: bool, balanced: dict[str, int]) -> Any:
    """The bench-level blind pruning of every record of ``by_scene``, pooled (:func:`spacedg.qa.debias.debias`;
    no trim to a size); ``balanced``: what balancing the cells across the scenes removed before (``--mode pooled``)."""
    from spacedg.qa.debias import debias

    result = debias([r for rs in by_scene.values() for r in rs], learned=learned)
    result.balanced = dict(balanced)
    return result


def _pick(records: list, n: int, types: set[str], seed: int) -> list:
    """Up to ``n`` records of the families ``types`` (all when empty), one family after another
    (in name order), seeded."""
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


def _add_index_inputs(parser: argparse.ArgumentParser) -> None:
    """The question indexes a reading subcommand takes: paths, and ``--families`` for selection indexes."""
    parser.add_argument("paths", type=Path, nargs="+", help="*.qa.jsonl files, or folders holding them (scene folders work)")
    parser.add_argument("--families", default="",
                        help="in folders, read the selection indexes that `qa build --families` wrote with these names "
                        "(default: the full indexes <scene id>.qa.jsonl)")


def _preview(args: argparse.Namespace) -> int:
    """Draw a PNG sheet of questions from a scene's question index: per question its views (real
    renders), the boxes of the objects it names, the question, options and answer. Reads the full
    index <scene id>.qa.jsonl that `spacedg qa build SCENE` writes beside the scene; writes only --out.
    """
    from spacedg.files import write_png
    from spacedg.qa.index import index_paths, read_index
    from spacedg.qa.preview import qa_sheet
    from spacedg.scene.io import load_scene

    _args.output_file("--out", args.out, (".png",))
    families = set(_family_names(args.families))
    scene = load_scene(args.scene)
    index, _ = index_paths(scene.id, args.scene if args.scene.is_dir() else args.scene.parent)
    if not index.is_file():
        raise InvalidDataError(f"{args.scene}: no question index {index.name} beside the scene; build it first with "
                               f"`spacedg qa build {args.scene}` (qa preview only reads indexes)")
    records = read_index(index)
    picked = _pick(records, args.n, families, args.seed)
    if not picked:
        known = sorted({r.question_type for r in records})
        raise InvalidDataError(f"{args.scene}: no questions of types {sorted(families)} in {index}; it has the families {known}")
    sheet = qa_sheet(scene, picked, thumb_width=args.thumb_width, backend=args.backend)
    write_png(args.out, sheet, "--out", compression=9)
    print(f"wrote {args.out} ({len(picked)} questions, {sheet.shape[1]}x{sheet.shape[0]} px)")
    return 0
