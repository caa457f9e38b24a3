"""``spacedg export --split bench --out DIR``: images + VLMEvalKit TSV + chat JSONL, sharded and resumable."""

from __future__ import annotations

import argparse
from pathlib import Path

from spacedg.errors import ParameterError


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = subparsers.add_parser(
        "export", help="render a split to PNGs + a VLMEvalKit TSV + chat JSONL (resumable, --shard i/n)",
        description="Render every item of a split and write images, <split>.tsv (VLMEvalKit / SpaceDG evaluator "
                    "columns) and <split>.jsonl (chat format). Finished chunks are skipped on a rerun; --shard i/n "
                    "splits the chunks across processes or machines (see docs/distributed-export.md).",
    )
    parser.add_argument("--split", default="bench", choices=("train", "val", "bench"))
    parser.add_argument("--out", type=Path, required=True, help="output folder")
    parser.add_argument("--scenes", type=Path, nargs="*", default=None, help="scene folders (default: the built-in rooms)")
    parser.add_argument("--degradations", default=None, help="comma-separated chains (default: the nine for bench, clean for train/val)")
    parser.add_argument("--question-types", default=None, help="comma-separated question types (default: all)")
    parser.add_argument("--image-size", default=None, help="WxH to render at, e.g. 640x480 (default: the views' own size)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--per-sub-type", type=int, default=25, help="questions per sub type and scene (index building)")
    parser.add_argument("--clean-prob", type=float, default=0.1, help="train/val only")
    parser.add_argument("--max-questions", type=int, default=None, help="keep at most N questions, spread over question types")
    parser.add_argument("--shard", default="0/1", help="i/n: export the chunks k with k %% n == i")
    parser.add_argument("--chunk-size", type=int, default=256, help="items per resumable chunk")
    parser.add_argument("--skip-bad-scenes", action="store_true", help="skip scenes that cannot be read (they are named)")
    parser.add_argument("--backend", default="auto", choices=("auto", "cpu", "torch"))
    parser.set_defaults(func=run)


def _size(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    try:
        w, h = (int(v) for v in text.lower().split("x"))
    except ValueError:
        raise ParameterError(f"--image-size must read WxH, e.g. 640x480, got {text!r}") from None
    if w < 8 or h < 8:
        raise ParameterError(f"--image-size {text}: width and height must be >= 8 pixels")
    return w, h


def _names(text: str | None) -> list[str] | None:
    return None if text is None else [t.strip() for t in text.split(",") if t.strip()]


def run(args: argparse.Namespace) -> int:
    from spacedg.data.dataset import SpaceDGDataset
    from spacedg.data.export import counts_table, export_split, parse_shard
    from spacedg.data.qa_index import QABuildConfig

    shard = parse_shard(args.shard)
    dataset = SpaceDGDataset(
        args.split, _names(args.degradations), scenes=args.scenes, question_types=_names(args.question_types),
        image_size=_size(args.image_size), seed=args.seed, clean_prob=args.clean_prob,
        qa_config=QABuildConfig(per_sub_type=args.per_sub_type),
        on_bad_scene="skip" if args.skip_bad_scenes else "raise", backend=args.backend, max_questions=args.max_questions,
    )
    summary = export_split(dataset, args.out, shard=shard, chunk_size=args.chunk_size)
    print(f"{len(dataset)} items in {summary.chunks_total} chunk(s); this shard wrote {len(summary.chunks_written)} "
          f"chunk(s) ({summary.items_written} items), skipped {len(summary.chunks_skipped)} finished")
    for folder, error in dataset.skipped.items():
        print(f"skipped scene {folder}: {error}")
    if summary.merged:
        print(f"wrote {args.out / (args.split + '.tsv')} and {args.out / (args.split + '.jsonl')}\n")
        print(counts_table(summary.counts))
    else:
        print("other shards still missing: run them, then any shard again (or this one) to merge")
    return 0
