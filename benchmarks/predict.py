"""`spacedg predict` and `spacedg eval` throughput, and the error batching could introduce.

Prints tables only (never part of the test run).

    .venv/bin/python benchmarks/predict.py --bench runs/demo/bench            # after `make demo`
    .venv/bin/python benchmarks/predict.py --bench runs/demo/bench --family internvl --device cuda

Model: a real tiny transformers VLM built in code (:func:`spacedg.vlm.save_tiny_vlm`; random
weights, so the answers are noise; what is measured is the pipeline: image loading, chat
template, processor, generation, writing). For each batch size: items/s over the bench, and the
**disagreement** with batch size 1 (share of items whose generated text differs: left padding
must not change greedy answers; the reference is the one-by-one run). Then ``no_image``
(one call per distinct question) and ``spacedg eval`` on the predictions (scoring + tables +
plots), with its wall time.

``--model PATH`` measures a real model folder instead of the tiny one.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path


def _predictions(path: Path) -> dict[int, str]:
    return {int(x["index"]): x["prediction"] for x in map(json.loads, path.read_text().splitlines()) if x}


def main() -> None:
    from spacedg.eval.bench import load_bench
    from spacedg.eval.predict import bench_source, predict
    from spacedg.eval.predictions import read_predictions
    from spacedg.eval.report import build_report, write_report
    from spacedg.vlm import load_vlm, save_tiny_vlm

    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--bench", type=Path, required=True, help="an exported bench (spacedg export)")
    parser.add_argument("--model", type=Path, default=None, help="a model folder (default: a tiny model built in code)")
    parser.add_argument("--family", default="qwen2_5_vl", help="tiny model family (qwen2_vl, qwen2_5_vl, qwen3_vl, internvl)")
    parser.add_argument("--batch-sizes", default="1,4,16", help="comma-separated batch sizes; the first is the reference")
    parser.add_argument("--limit", type=int, default=None, help="first N items only")
    parser.add_argument("--device", default="cpu")
    args = parser.parse_args()

    bench = load_bench(args.bench)
    source = bench_source(bench)
    n = len(source.indices) if args.limit is None else min(args.limit, len(source.indices))
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        model_dir = args.model or save_tiny_vlm(work / f"tiny-{args.family}", args.family)
        t0 = time.perf_counter()
        vlm = load_vlm(model_dir, device=args.device)
        print(f"model {model_dir.name}: loaded in {time.perf_counter() - t0:.2f} s; bench {bench.path} ({n} of {len(bench)} items)")
        print(f"{'run':<22}{'items':>7}{'calls':>7}{'seconds':>9}{'items/s':>9}{'differs from ref':>18}")
        reference: dict[int, str] | None = None
        outputs = []
        for size in (int(s) for s in args.batch_sizes.split(",")):
            out = work / f"b{size}.jsonl"
            summary = predict(vlm, source, out, batch_size=size, limit=args.limit, progress=False, model_name=f"b{size}")
            answers = _predictions(out)
            if reference is None:
                reference, differs = answers, "reference"
            else:
                diff = sum(answers[i] != reference[i] for i in reference)
                differs = f"{diff}/{len(reference)} ({100 * diff / len(reference):.1f}%)"
            outputs.append(out)
            print(f"{'default, batch ' + str(size):<22}{summary.answered:>7}{summary.generated:>7}{summary.seconds:>9.2f}"
                  f"{summary.answered / summary.seconds:>9.1f}{differs:>18}")
        out = work / "blind.jsonl"
        summary = predict(vlm, source, out, variant="no_image", batch_size=16, limit=args.limit, progress=False, model_name="blind")
        print(f"{'no_image, batch 16':<22}{summary.answered:>7}{summary.generated:>7}{summary.seconds:>9.2f}"
              f"{summary.answered / summary.seconds:>9.1f}{'-':>18}")
        t0 = time.perf_counter()
        sets = [read_predictions(p) for p in [*outputs, out]]
        report = build_report(sets, bench, missing="skip" if args.limit is not None else "error")
        t_score = time.perf_counter() - t0
        files = write_report(report, work / "report")
        t_all = time.perf_counter() - t0
        items = sum(len(v) for v in report.items.values())
        print(f"eval: {len(sets)} files, {items} scored items: scoring + tables {t_score:.2f} s, "
              f"with writing {len(files)} files (plots included) {t_all:.2f} s")


if __name__ == "__main__":
    main()
