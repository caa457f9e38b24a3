"""What ``spacedg qa stats`` reports about the selection modes (:mod:`spacedg.qa.modes`), the
counting answers and object re-asks.

- :func:`count_distribution`: how often each count is the answer of the COUNT records;
- :func:`object_reasks`: per sub type, records asking an object (or pair, triplet) already asked
  in the same scene and sub type **from any view** (the strict bench rule: 0 in a bench index;
  a dense train index re-asks on purpose);
- :func:`mode_row`: scenes, records and records per scene of one mode's indexes.
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.specs import AnswerType
from spacedg.qa.modes import subject_key
from spacedg.qa.stats import record_subject

__all__ = ["count_distribution", "object_reasks", "mode_row", "format_counts"]


def count_distribution(records: Iterable[QARecord]) -> dict[int, int]:
    """Count answer → number of COUNT records with it, in count order."""
    found = Counter(int(r.answer) for r in records if r.answer_type is AnswerType.COUNT)  # type: ignore[arg-type]
    return dict(sorted(found.items()))


def format_counts(dist: Mapping[int, int]) -> str:
    """``"0: 12  1: 12  2: 9  3: 2  4: 1"`` (``"none"`` when empty)."""
    return "  ".join(f"{k}: {v}" for k, v in dist.items()) or "none"


def object_reasks(records_by_scene: Mapping[str, Sequence[QARecord]]) -> list[dict[str, Any]]:
    """Per (question_type, sub_question_type) that names objects: ``n``, ``reasks`` (records whose
    object subject, views dropped, was already asked in the scene and sub type) and
    ``max_per_object`` (most records of one object subject in one scene); a final ``ALL`` row."""
    rows: dict[tuple[str, str], list[int]] = defaultdict(lambda: [0, 0, 0])
    for rs in records_by_scene.values():
        seen: Counter[tuple[str, str, str]] = Counter()
        for r in rs:
            subject = subject_key(record_subject(r), r.views, "bench")
            if "object" not in subject:
                continue  # camera motion, counting, existence: a view (pair) and label, not an object
            key = (r.question_type, r.sub_question_type, subject)
            row = rows[key[:2]]
            row[0] += 1
            row[1] += key in seen
            seen[key] += 1
            row[2] = max(row[2], seen[key])
    out = [{"question_type": q, "sub_question_type": s, "n": n, "reasks": k, "max_per_object": m}
           for (q, s), (n, k, m) in sorted(rows.items())]
    if out:
        out.append({"question_type": "ALL", "sub_question_type": "", "n": sum(r["n"] for r in out),
                    "reasks": sum(r["reasks"] for r in out), "max_per_object": max(r["max_per_object"] for r in out)})
    return out


def mode_row(mode: str, records_by_scene: Mapping[str, Sequence[QARecord]]) -> dict[str, Any]:
    """``{"mode", "scenes", "records", "per_scene", "reasks"}`` of one mode's indexes."""
    n = sum(len(rs) for rs in records_by_scene.values())
    reasks = object_reasks(records_by_scene)
    return {
        "mode": mode, "scenes": len(records_by_scene), "records": n,
        "per_scene": n / len(records_by_scene) if records_by_scene else 0.0,
        "reasks": reasks[-1]["reasks"] if reasks else 0,
    }
