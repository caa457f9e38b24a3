"""``spacedg eval preds… --bench DIR --out REPORT_DIR``: score predictions and write the paper's tables."""

from __future__ import annotations

import argparse
from pathlib import Path

from spacedg.commands import _args


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    parser = _args.add_command(
        subparsers, "eval", run, help="score prediction files and write tables (CSV + Markdown), correlations and plots",
    )
    parser.add_argument("predictions", nargs="+", help="prediction files: PATH, LABEL=PATH or LABEL@VARIANT=PATH")
    parser.add_argument("--bench", type=Path, default=None,
                        help="the bench the predictions answer (default: the questions the .jsonl files carry)")
    parser.add_argument("--out", type=Path, required=True, help="report folder")
    parser.add_argument("--missing", choices=("error", "wrong", "skip"), default="error",
                        help="bench items without a prediction: error (default), score them as wrong, or skip them "
                             "(score only the answered items, e.g. a subset)")
    parser.add_argument("--no-plots", action="store_true", help="tables only")


def run(args: argparse.Namespace) -> int:
    """Score one or more prediction files (spacedg predict's .jsonl, or VLMEvalKit's .xlsx/.tsv/.csv/.json
    with a 'prediction' column) and write the paper's tables: model x degradation, per task group,
    question type and answer type, the clean-to-degraded drop, the point-biserial |r| across models, and
    plots. Name a file's model with LABEL=PATH, and its prompt variant with LABEL@VARIANT=PATH
    (variants: default, no_image, degradation_info, cot).
    """
    from spacedg.eval.bench import load_bench
    from spacedg.eval.predictions import read_predictions
    from spacedg.eval.report import build_report, write_report

    _args.output_folder("--out", args.out)
    bench = load_bench(args.bench) if args.bench is not None else None
    sets = [read_predictions(source) for source in args.predictions]
    report = build_report(sets, bench, missing=args.missing)
    written = write_report(report, args.out, with_plots=not args.no_plots)
    print(report.out["main"].markdown())
    for s in sets:
        missing = sum(i.missing for i in report.items[s.label])
        if missing:
            print(f"note: {s.label}: {missing} item(s) without a prediction were scored as wrong")
    print(f"{len(written)} files in {args.out} (report.md collects them)")
    return 0
