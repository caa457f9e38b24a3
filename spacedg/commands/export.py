"""``spacedg export --split bench --out DIR``: PNGs + VLMEvalKit TSV + chat JSONL, sharded and resumable."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import TYPE_CHECKING

from spacedg.commands import _args, _vocabulary
from spacedg.commands.sizes import image_size
from spacedg.errors import ParameterError

if TYPE_CHECKING:  # pragma: no cover
    from spacedg.files import ExclusiveLock


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = _args.add_command(
        subparsers, "export", run, help="render a split to PNGs + a VLMEvalKit TSV + chat JSONL (resumable, --shard i/n)",
    )
    parser.add_argument("--split", default="bench", choices=("train", "val", "bench"))
    parser.add_argument("--out", type=Path, required=True, help="output folder (shared by every shard)")
    parser.add_argument("--scenes", type=Path, nargs="+", default=None, help="scene folders or folders of them (default: the built-in rooms)")
    parser.add_argument("--degradations", default=None, help="comma-separated chains (default: the nine for bench, clean for train/val)")
    parser.add_argument("--families", default=None, help="comma-separated question families (default: all)")
    parser.add_argument("--image-size", type=image_size, default=None,
                        help="WxH in pixels, a bounding box: each view renders at the largest size of its own aspect "
                        "ratio within it, e.g. 640x480 (a 16:9 view at 320x240 renders 320x180; default: the views' own size)")
    parser.add_argument("--seed", type=_args.SEED, default=0, help="seed of the questions and of the degradations (default 0)")
    parser.add_argument("--per-sub-type", type=_args.whole(1), default=25, help="questions per sub type and scene when indexes are built (default 25)")
    parser.add_argument("--qa-mode", choices=("auto", "bench", "train"), default="auto",
                        help="question selection: bench (strict: an object once per sub type and scene) or train (dense: many views, "
                             "4x the questions); auto (default): bench for --split bench, train otherwise (docs/question-modes.md)")
    parser.add_argument("--clean-prob", type=_args.real(0.0, 1.0), default=0.1, help="share of clean items, train/val only (default 0.1)")
    parser.add_argument("--max-questions", type=_args.whole(1), default=None, help="keep at most N questions, shared round-robin over question types (with the blind pruning: "
                        "its trim takes the candidates to N so, each cell's roles kept balanced)")
    parser.add_argument("--shard", default="0/1", help="i/n: export the chunks k with k %% n == i; 'env' reads RANK/WORLD_SIZE "
                                                       "(torchrun) or SLURM_ARRAY_TASK_ID/COUNT (default 0/1)")
    parser.add_argument("--shard-size", type=_args.whole(1), default=None,
                        help="items per resumable chunk; the same in every shard (default 256)")
    parser.add_argument("--all-bench", action="store_true",
                        help="put every scene in the bench split (works from one scene); same as --split-fractions 0,1")
    parser.add_argument("--split-fractions", default=None, metavar="VAL,BENCH",
                        help="share of scenes for val and bench, the rest train (default 0.1,0.1; 0 leaves a split empty)")
    parser.add_argument("--skip-bad-scenes", action="store_true", help="skip scenes that cannot be read (they are named)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    parser.add_argument("--answerability", choices=("auto", "on", "off"), default="auto",
                        help="measure whether each item's named objects are discernible in its images and print the share "
                        "per degradation and severity (kept per item in summary.json); auto = for the bench split (default)")
    parser.add_argument("--debias", action=argparse.BooleanOptionalAction, default=True,
                        help="bench: blind pruning (on by default; --no-debias skips it): oversampled candidates (partial rounds "
                        "too, <id>.qa-pooled.jsonl), each balancing cell's roles evened across the scenes, probed k-fold by "
                        "scene with text-only models and pruned until every sub type is within chance + 3 (or its noise band), "
                        "then trimmed to the requested size; needs >= 2 bench scenes (docs/question-audit.md)")
    parser.add_argument("--oversample", type=_args.whole(1), default=None,
                        help="bench: candidates per requested record for the blind pruning, which trims back to the requested "
                        "size (candidate indexes are built at --per-sub-type x this; default 2; 1: at --per-sub-type, with partial rounds)")
    _args.add_backend_arguments(parser)
    _vocabulary.add_deprecated(parser, "export")


def _fractions(args: argparse.Namespace) -> tuple[float, float]:
    if args.all_bench and args.split_fractions is not None:
        raise ParameterError("--all-bench and --split-fractions are alternatives; pass one")
    if args.all_bench:
        if args.split != "bench":
            raise ParameterError(f"--all-bench puts every scene in the bench split, but --split is {args.split!r}")
        return (0.0, 1.0)
    if args.split_fractions is None:
        return (0.1, 0.1)
    try:
        val, bench = (float(v) for v in args.split_fractions.split(","))
    except ValueError:
        raise ParameterError(f"--split-fractions must read VAL,BENCH, e.g. 0.1,0.1 or 0,1, got {args.split_fractions!r}") from None
    return val, bench


def _shard_lock(out: Path, shard: tuple[int, int]) -> ExclusiveLock:
    """An exclusive lock on ``out/.shard-<i>-of-<n>.lock`` while this process writes shard i/n (freed on
    exit, even by ``kill -9``): a second run of the same shard fails at once, naming the first."""
    from spacedg.files import exclusive_lock

    out.mkdir(parents=True, exist_ok=True)
    i, n = shard
    return exclusive_lock(out / f".shard-{i}-of-{n}.lock", f"shard {i}/{n} of {out} is being written by another process")


def _qa_mode(args: argparse.Namespace) -> str:
    """--qa-mode, with ``auto`` resolved by the split (bench → ``bench``, train/val → ``train``)."""
    if args.qa_mode != "auto":
        return str(args.qa_mode)
    return "bench" if args.split == "bench" else "train"


def _bench_scenes(scenes: list[Path] | None, fractions: tuple[float, float]) -> int:
    """Scenes the bench split gets (the built-in rooms' 16 when ``--scenes`` is not given)."""
    from spacedg.data.bench_debias import bench_scene_count
    from spacedg.scene.store import scene_dirs_of

    return bench_scene_count(16 if scenes is None else len(scene_dirs_of(scenes)), fractions)


def _names(text: str | None) -> list[str] | None:
    return None if text is None else [t.strip() for t in text.split(",") if t.strip()]


def run(args: argparse.Namespace) -> int:
    """Render every item of a split and write images/, <split>.tsv (the public SpaceDG bench's format: its
    columns, names and lettered existence options; for --split bench also spacedg_bench.tsv, so the
    folder is VLMEvalKit's LMUData for --data spacedg_bench), <split>.jsonl (chat format) and
    summary.json. Finished chunks are skipped on a rerun; --shard i/n splits the chunks across processes
    or machines (see docs/distributed-export.md).
    """
    from spacedg.data.chain import Chain, split_chains
    from spacedg.data.dataset import SpaceDGDataset
    from spacedg.data.export import DEFAULT_SHARD_SIZE, export_bench
    from spacedg.data.shards import resolve_shard
    from spacedg.data.bench_debias import MIN_SCENES, OVERSAMPLE, debias_dataset, write_debias_report
    from spacedg.qa.debias import format_debias
    from spacedg.qa.index import QABuildConfig

    # every flag is checked before the (slow) dataset construction
    shard = resolve_shard(args.shard, os.environ)
    shard_size = DEFAULT_SHARD_SIZE if args.shard_size is None else args.shard_size
    size = args.image_size
    fractions = _fractions(args)
    chains = None if args.degradations is None else [t.strip() for t in split_chains(args.degradations) if t.strip()]
    for chain in chains or ():
        Chain.parse(chain).check()  # an unknown name or preset fails now, with suggestions
    _args.output_folder("--out", args.out)
    few = args.split == "bench" and args.debias and _bench_scenes(args.scenes, fractions) < MIN_SCENES
    debias = args.split == "bench" and args.debias and not few
    if args.oversample is not None and not debias:
        why = f"the bench has fewer than {MIN_SCENES} scenes" if few else "this run skips it"
        raise ParameterError(f"--oversample {args.oversample} is for the blind pruning of --split bench, and {why}")
    if few:
        print(f"blind pruning skipped: the bench split has fewer than {MIN_SCENES} scenes (the probe holds whole scenes out)")
    factor = (OVERSAMPLE if args.oversample is None else args.oversample) if debias else 1  # trimmed back to the requested size
    qa_mode = _qa_mode(args)
    dataset = SpaceDGDataset(
        args.split, chains, scenes=args.scenes, families=_names(args.families),
        image_size=size, seed=args.seed, clean_prob=args.clean_prob,
        qa_config=QABuildConfig(seed=args.seed, per_sub_type=args.per_sub_type * factor, mode=qa_mode,
                                 partial_rounds=debias and qa_mode == "bench"),
        on_bad_scene="skip" if args.skip_bad_scenes else "raise", backend=args.backend, device=args.device,
        # the pruning trims to --max-questions itself, cells balanced (a random subset of the candidates would break their rounds)
        max_questions=None if args.max_questions is None or debias else args.max_questions, split_fractions=fractions,
    )
    pruned = debias_dataset(dataset, args.per_sub_type, args.max_questions, args.seed) if debias else None
    if pruned is not None:
        print(format_debias(pruned) + "\n")
    counts = {name: sum(1 for s in dataset.scene_splits.values() if s == name) for name in ("train", "val", "bench")}
    print(f"scenes: {counts['bench']} bench, {counts['val']} val, {counts['train']} train; exporting split {args.split!r} "
          f"({len(dataset.scene_dirs)} scene(s), {len(dataset.records)} question(s))")
    if not len(dataset):
        raise ParameterError(f"split {args.split!r} has no items ({len(dataset.scene_dirs)} scene(s) in it); "
                             "pass --all-bench or --split-fractions to put scenes there, or check the scenes' questions (spacedg qa stats)")
    for folder, error in dataset.skipped.items():
        print(f"skipped scene {folder}: {error}")
    with _shard_lock(args.out, shard):
        measure = None if args.answerability == "auto" else args.answerability == "on"
        summary = export_bench(dataset, args.out, shard=shard, shard_size=shard_size, progress=not args.no_progress, answerability=measure)
        if pruned is not None:
            write_debias_report(pruned, args.out)
    print(f"{len(dataset)} items in {summary.chunks_total} chunk(s) of {shard_size}; shard {shard[0]}/{shard[1]} wrote "
          f"{len(summary.chunks_written)} chunk(s) ({summary.items_written} items) in {summary.seconds:.1f} s, "
          f"skipped {len(summary.chunks_skipped)} finished")
    if summary.merged:
        print(f"wrote {args.out / (args.split + '.tsv')}, {args.out / (args.split + '.jsonl')} and {args.out / 'summary.json'}\n")
        print(summary.merge.table)
        if summary.merge.answerability_table:
            print("\nanswerability: share of items whose named objects are discernible (Weber contrast >= 2 % with 1 % "
                  "viewing flare, SNR >= 5; spacedg.data.answerability), per degradation and severity:\n")
            print(summary.merge.answerability_table)
        if args.split == "bench":
            print(f"\nVLMEvalKit (public SpaceDG evaluator): LMUData={args.out} run.py --data spacedg_bench")
        for names, why in summary.merge.mismatches.items():
            print(f"WARNING: {names}: {why}; the public evaluator routes by question_type/sub_question_type only")
    else:
        missing = summary.merge.missing
        shown = ", ".join(map(str, missing[:10])) + (" …" if len(missing) > 10 else "")
        print(f"{len(missing)} chunk(s) still missing ({shown}): run the other shards; the last to finish merges "
              f"(or run any shard again)")
    return 0
