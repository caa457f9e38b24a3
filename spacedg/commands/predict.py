"""``spacedg predict --model PATH --bench DIR --out preds.jsonl``: answer a bench with a local VLM."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from spacedg.commands import _args
from spacedg.commands.sizes import image_size, pixel_budget
from spacedg.errors import ParameterError

#: Most tokens --max-new-tokens may ask for.
MAX_NEW_TOKENS = 1_000_000


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    from spacedg.eval.prompts import VARIANTS

    parser = _args.add_command(
        subparsers, "predict", run, help="run a local transformers VLM over a bench (batched, resumable)",
    )
    parser.add_argument("--model", type=Path, required=True, help="model folder (config.json + weights + processor files)")
    source = parser.add_mutually_exclusive_group(required=True)
    source.add_argument("--bench", type=Path, help="exported bench folder (spacedg export) or its .tsv")
    source.add_argument("--scenes", type=Path, nargs="+", help="scene folders: render SpaceDGDataset(split='bench') online")
    parser.add_argument("--out", type=Path, required=True, help="predictions file, *.jsonl (resumed when it exists)")
    variant = parser.add_mutually_exclusive_group()
    variant.add_argument("--no-image", dest="variant", action="store_const", const="no_image",
                         help="non-image baseline: the questions without their images")
    variant.add_argument("--degradation-info", dest="variant", action="store_const", const="degradation_info",
                         help="prepend the degradation type and its parameter ranges (the paper's Table 2)")
    variant.add_argument("--cot", dest="variant", action="store_const", const="cot",
                         help="two-stage chain of thought: name the degradation first, then reason")
    variant.add_argument("--variant", dest="variant", choices=VARIANTS, help="the prompt variant by name")
    parser.set_defaults(variant="default")
    parser.add_argument("--name", default=None, help="model name in reports (default: the model folder's name)")
    parser.add_argument("--batch-size", type=_args.whole(1), default=8, help="conversations per generate call (default 8)")
    parser.add_argument("--max-new-tokens", type=_args.whole(1, MAX_NEW_TOKENS), default=None, help="generation budget, >= 1 (default 32; cot 512)")
    parser.add_argument("--limit", type=_args.whole(1), default=None, help="answer at most N pending items (smoke runs)")
    parser.add_argument("--shard", default="0/1", help="i/n: answer every n-th item starting at i, into OUT with .shard{i}of{n} "
                                                       "before .jsonl; 'env' reads RANK/WORLD_SIZE (torchrun) or SLURM "
                                                       "variables (default 0/1); spacedg eval merges the shards")
    _args.add_device_argument(parser, "torch device: cpu, cuda or cuda:N (default: cuda, or cuda:LOCAL_RANK under a "
                                      "launcher, when available, else cpu)")
    parser.add_argument("--dtype", default="auto", choices=("auto", "float32", "bfloat16", "float16"),
                        help="weights dtype (default auto: bfloat16 on CUDA, float32 on CPU)")
    parser.add_argument("--min-pixels", type=pixel_budget, default=None, help="image budget: fewest pixels per image after resizing")
    parser.add_argument("--max-pixels", type=pixel_budget, default=None, help="image budget: most pixels per image after resizing")
    parser.add_argument("--image-size", type=image_size, default=None, help="--scenes only: WxH to render within, keeping each view's aspect ratio (default: the views' size)")
    parser.add_argument("--max-questions", type=_args.whole(1), default=None, help="--scenes only: at most N questions")
    parser.add_argument("--seed", type=_args.SEED, default=0, help="--scenes only: dataset seed (default 0)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def _check(args: argparse.Namespace) -> None:
    """The flags of ``predict`` that argparse cannot check alone, before the bench, the dataset
    or the model is loaded."""
    if args.min_pixels is not None and args.max_pixels is not None and args.min_pixels > args.max_pixels:
        raise ParameterError(f"--min-pixels {args.min_pixels} is more than --max-pixels {args.max_pixels}; pass min <= max")
    _args.output_file("--out", args.out, (".jsonl",))


def _default_device(torch: Any) -> str:
    """cuda:LOCAL_RANK (cuda:0 without a launcher) when CUDA is available, else cpu; checked."""
    import os

    from spacedg.devices import resolve_device

    if not torch.cuda.is_available():
        return "cpu"
    return str(resolve_device(f"cuda:{os.environ.get('LOCAL_RANK', '0')}", "the default device cuda:LOCAL_RANK"))


def run(args: argparse.Namespace) -> int:
    """Answer every item of an exported bench (--bench) or of SpaceDGDataset(split='bench') rendered online
    (--scenes) with a local transformers VLM (Qwen2-VL, Qwen2.5-VL, Qwen3-VL, InternVL, ...). Answers
    are appended to --out after each batch; a rerun skips answered items.
    """
    import os

    import torch

    from spacedg.data.shards import resolve_shard
    from spacedg.eval.predict import bench_source, dataset_source, predict, shard_path

    _check(args)
    if args.bench is not None:
        from spacedg.eval.bench import load_bench

        source = bench_source(load_bench(args.bench))
    else:
        from spacedg.data.dataset import SpaceDGDataset

        dataset = SpaceDGDataset(split="bench", scenes=args.scenes, image_size=args.image_size, seed=args.seed,
                                 max_questions=args.max_questions)
        source = dataset_source(dataset)
    shard = resolve_shard(args.shard, os.environ)
    device = args.device or _default_device(torch)
    summary = predict(
        args.model, source, shard_path(args.out, shard), variant=args.variant, model_name=args.name,
        batch_size=args.batch_size, max_new_tokens=args.max_new_tokens, limit=args.limit, shard=shard, device=device,
        dtype=args.dtype,
        min_pixels=args.min_pixels, max_pixels=args.max_pixels, progress=not args.no_progress,
    )
    rate = summary.answered / summary.seconds if summary.seconds > 0 else 0.0
    print(f"{summary.out}: {summary.answered} answered now ({summary.generated} model calls, {summary.seconds:.1f} s, "
          f"{rate:.2f} items/s), {summary.skipped} found answered, "
          f"{summary.total - summary.skipped - summary.answered} left of {summary.total}")
    return 0
