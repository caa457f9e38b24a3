"""Evaluation: parsing model outputs and scoring them against SpaceDG answers.

See :mod:`spacedg.eval.parsing` (reading answers) and :mod:`spacedg.eval.scoring` (answer extraction, routing, MRA).
"""

from __future__ import annotations

from spacedg.eval.parsing import (
    extract_answer_text,
    parse_count,
    parse_mcq,
    parse_number,
    parse_size_list,
    parse_yes_no,
)
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
