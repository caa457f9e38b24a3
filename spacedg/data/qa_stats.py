"""Counts and answer balance of question records, and the blind baseline.

- :func:`count_table`: records per (question_type, sub_question_type) and answer type.
- :func:`answer_balance`: share of each correct letter A–D over MCQ records and of yes/no over
  YN records, in percent.
- :func:`blind_baseline`: leave-one-scene-out "always answer the most frequent answer of this
  sub type" accuracy on MCQ and YN records, against chance (25 % / 50 %). Two priors are
  measured: the most frequent **letter** (what a blind model can output) and the most
  frequent **option text** (a blind model that reads the options and picks the one that was
  most often right in the training scenes: catches text bias such as "forward" dominating).
"""

from __future__ import annotations

from collections import Counter, defaultdict
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from spacedg.plugins.answers import MCQ_LETTERS
from spacedg.plugins.qa_record import QARecord
from spacedg.plugins.specs import AnswerType

__all__ = ["count_table", "answer_balance", "blind_baseline", "format_table"]


def count_table(records: Iterable[QARecord]) -> list[dict[str, Any]]:
    """One row per (question_type, sub_question_type): ``n`` and the answer type."""
    counts: Counter[tuple[str, str, str]] = Counter(
        (r.question_type, r.sub_question_type, r.answer_type.value) for r in records
    )
    return [
        {"question_type": q, "sub_question_type": s, "answer_type": a, "n": n}
        for (q, s, a), n in sorted(counts.items())
    ]


def answer_balance(records: Iterable[QARecord]) -> dict[str, Any]:
    """``{"mcq_n", "letters": {A: %, ...}, "yn_n", "yes_pct"}``."""
    letters: Counter[str] = Counter()
    yes = no = 0
    for r in records:
        if r.answer_type is AnswerType.MCQ:
            letters[str(r.answer)] += 1
        elif r.answer_type is AnswerType.YN:
            yes += r.answer == "yes"
            no += r.answer == "no"
    mcq = sum(letters.values())
    return {
        "mcq_n": mcq,
        "letters": {k: (100.0 * letters[k] / mcq if mcq else 0.0) for k in MCQ_LETTERS},
        "yn_n": yes + no,
        "yes_pct": 100.0 * yes / (yes + no) if yes + no else 0.0,
    }


def _option_text(record: QARecord, letter: str) -> str:
    for line in record.options:
        if line.startswith(f"{letter}. "):
            return line[3:]
    return ""


def blind_baseline(records_by_scene: Mapping[str, Sequence[QARecord]]) -> list[dict[str, Any]]:
    """Leave-one-scene-out majority baselines per (question_type, sub_question_type), MCQ and YN.

    For each held-out scene, the priors are counted on the other scenes: the most frequent
    answer (letter or yes/no) and, for MCQ, the most frequent correct option text. On the held-out
    scene the letter prior answers that letter; the text prior picks the option whose text has the
    highest training count (ties → the first option). Rows give ``n``, ``chance`` and both
    accuracies in percent; a final row ``ALL`` pools every record.
    """
    keys = sorted({(r.question_type, r.sub_question_type) for rs in records_by_scene.values() for r in rs
                   if r.answer_type in (AnswerType.MCQ, AnswerType.YN)})
    hits: dict[tuple[str, str], list[int]] = defaultdict(lambda: [0, 0, 0])  # n, letter hits, text hits
    chance: dict[tuple[str, str], float] = {}
    for held in records_by_scene:
        answer_prior: dict[tuple[str, str], Counter[str]] = defaultdict(Counter)
        text_prior: dict[tuple[str, str], Counter[str]] = defaultdict(Counter)
        for scene, rs in records_by_scene.items():
            if scene == held:
                continue
            for r in rs:
                k = (r.question_type, r.sub_question_type)
                answer_prior[k][str(r.answer)] += 1
                if r.answer_type is AnswerType.MCQ:
                    text_prior[k][_option_text(r, str(r.answer))] += 1
        for r in records_by_scene[held]:
            k = (r.question_type, r.sub_question_type)
            if k not in keys:
                continue
            chance[k] = 25.0 if r.answer_type is AnswerType.MCQ else 50.0
            row = hits[k]
            row[0] += 1
            guess = answer_prior[k].most_common(1)[0][0] if answer_prior[k] else ("A" if r.answer_type is AnswerType.MCQ else "yes")
            row[1] += guess == str(r.answer)
            if r.answer_type is AnswerType.MCQ:
                texts = [(_option_text(r, letter), letter) for letter in MCQ_LETTERS]
                best = max(texts, key=lambda tl: text_prior[k][tl[0]])[1]
                row[2] += best == str(r.answer)
            else:
                row[2] += guess == str(r.answer)
    rows = []
    total = [0, 0, 0]
    total_chance = 0.0
    for k in keys:
        n, h_letter, h_text = hits[k]
        if n == 0:
            continue
        rows.append({"question_type": k[0], "sub_question_type": k[1], "n": n, "chance": chance[k],
                     "letter_prior": 100.0 * h_letter / n, "text_prior": 100.0 * h_text / n})
        total = [total[0] + n, total[1] + h_letter, total[2] + h_text]
        total_chance += chance[k] * n
    if total[0]:
        rows.append({"question_type": "ALL", "sub_question_type": "", "n": total[0], "chance": total_chance / total[0],
                     "letter_prior": 100.0 * total[1] / total[0], "text_prior": 100.0 * total[2] / total[0]})
    return rows


def format_table(rows: Sequence[Mapping[str, Any]], columns: Sequence[str] | None = None) -> str:
    """A Markdown table of ``rows`` (floats with one decimal)."""
    if not rows:
        return "(no rows)"
    cols = list(columns or rows[0].keys())
    def cell(v: Any) -> str:
        return f"{v:.1f}" if isinstance(v, float) else str(v)
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(cell(r.get(c, "")) for c in cols) + " |" for r in rows]
    return "\n".join(lines)
