"""Evaluation: answering a bench with a VLM, scoring the answers, and reporting like the paper.

* :mod:`spacedg.eval.parsing` reads answers; :mod:`spacedg.eval.scoring` routes and scores them (MRA).
* :mod:`spacedg.eval.bench` reads an exported bench; :mod:`spacedg.eval.predictions` reads prediction
  files (ours and VLMEvalKit's); :mod:`spacedg.eval.prompts` holds the paper's prompt variants.
* :mod:`spacedg.eval.predict` runs a local transformers VLM over a bench (``spacedg predict``).
* :mod:`spacedg.eval.aggregate`, :mod:`spacedg.eval.correlation`, :mod:`spacedg.eval.report` and
  :mod:`spacedg.eval.plots` make the tables, the point-biserial analysis and the plots (``spacedg eval``).
"""

from __future__ import annotations

from spacedg.eval.bench import Bench, BenchRow, load_bench
from spacedg.eval.parsing import (
    extract_answer_text,
    parse_count,
    parse_mcq,
    parse_number,
    parse_size_list,
    parse_yes_no,
)
from spacedg.eval.predictions import PredictionSet, read_predictions
from spacedg.eval.report import Report, build_report, write_report
from spacedg.eval.scoring import (
    ANSWER_PROMPT,
    MRA_THRESHOLDS,
    ScoreResult,
    mean_relative_accuracy,
    route,
    score,
    summarize,
)

__all__ = [
    "ANSWER_PROMPT",
    "Bench",
    "BenchRow",
    "PredictionSet",
    "Report",
    "build_report",
    "load_bench",
    "read_predictions",
    "write_report",
    "MRA_THRESHOLDS",
    "ScoreResult",
    "extract_answer_text",
    "mean_relative_accuracy",
    "parse_count",
    "parse_mcq",
    "parse_number",
    "parse_size_list",
    "parse_yes_no",
    "route",
    "score",
    "summarize",
]
