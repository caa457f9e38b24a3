"""``spacedg eval``: score prediction files and write the paper's tables, correlations and plots.

Layout of the report folder::

    report.md                    every table below, with the plots, in one page
    summary.json                 per model: clean, each degradation, Avg., drop; |r| overall
    main.md / main.csv           the paper's Table 1: model × (Clean, 9 degradations, Avg.),
                                 non-image baselines in the "Base" band
    by_task_group.{md,csv}       model × task group × (Clean, degradations, Avg.)
    by_question_type.{md,csv}    … per question type (also by_sub_question_type.csv)
    by_answer_type.{md,csv}      … per answer type (MCQ, YN, NA, COUNT, SIZE_LIST)
    drop.{md,csv}                clean − degraded per model: Avg. and per degradation
    correlation.{md,csv}         point-biserial |r| across models: overall, answer format
                                 (MCA / NA), task group, question type (Figure 5)
    degradation_info.{md,csv}    Table 2 (Δ when degradation type and severity are in the
                                 prompt), when a model has default and degradation_info runs
    cot.{md,csv}                 Table 3 (w/o vs with two-stage CoT) and the degradation
                                 recognition accuracy, when a model has a cot run
    scores.csv                   long form: model, variant, slice kind, slice, condition, n, score
    items.csv                    every scored prediction (parsed value, score)
    plots/                       per_degradation.png, radar.png, drop.png, correlation.png, delta.png

Every number is a mean of per-item scores in [0, 1], shown as percent (see
:mod:`spacedg.eval.aggregate` for the averaging conventions).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from spacedg.errors import InvalidDataError
from spacedg.eval import plots  # matplotlib itself is imported on the first plot
from spacedg.eval.aggregate import (
    AVG,
    SLICE_KINDS,
    Cell,
    ItemScore,
    condition_order,
    mean,
    score_set,
    slice_table,
)
from spacedg.eval.bench import CLEAN, Bench
from spacedg.eval.correlation import MIN_MODELS, degradation_correlation
from spacedg.eval.labels import degradation_label
from spacedg.eval.predictions import PredictionSet, merge_shards
from spacedg.eval.prompts import known_degradations, parse_degradation_guess
from spacedg.eval.scoring import SCORER
from spacedg.eval.tables import (
    Table,
    csv_bytes,
    fmt_corr,
    fmt_delta,
    fmt_pct,
    is_number,
)
from spacedg.files import atomic_write_bytes

__all__ = ["Report", "build_report", "write_report"]

_TABLE_SLICES = ("task_group", "question_type", "answer_type")
_CORRELATION_PANELS = {"all": "(a) Overall", "answer_format": "(b) Answer format", "task_group": "(c) Task group",
                       "question_type": "(d) Question type"}


@dataclass
class Report:
    """Everything :func:`write_report` writes, as data.

    Attributes:
        sets: the prediction sets, in the order given.
        items: ``set label → scored items``.
        conditions: clean first, then degradations in the paper's order, then other chains.
        tables: ``set label → slice kind ("all" or a SLICE_KINDS key) → slice → condition → Cell``.
        correlation: ``slice kind → slice → condition → (r, models)`` over the default runs.
        out: named :class:`Table` s (``main``, ``by_task_group``, …).
    """

    sets: list[PredictionSet]
    items: dict[str, list[ItemScore]]
    conditions: list[str]
    tables: dict[str, dict[str, dict[str, dict[str, Cell]]]]
    correlation: dict[str, dict[str, dict[str, tuple[float, int]]]]
    out: dict[str, Table] = field(default_factory=dict)

    @property
    def degradations(self) -> list[str]:
        return [c for c in self.conditions if c != CLEAN]

    def overall(self, label: str) -> dict[str, float]:
        """``condition (and "avg") → score`` of one set over all items."""
        return {k: c.score for k, c in self.tables[label]["all"].get("all", {}).items()}

    def runs(self, variant: str) -> list[PredictionSet]:
        return [s for s in self.sets if s.variant == variant]


# ------------------------------------------------------------------ building
def build_report(sets: Sequence[PredictionSet], bench: Bench | None = None, *, missing: str = "error") -> Report:
    """Score ``sets`` (against ``bench`` when given, else against the rows the files carry)
    and compute every table. Sets with the same model and variant are merged when they answer
    disjoint items (the shards of one run), else an error. ``missing``: see
    :func:`~spacedg.eval.aggregate.score_set`."""
    if not sets:
        raise InvalidDataError("spacedg eval: give at least one prediction file")
    sets = merge_shards(list(sets))
    rows = bench.by_index if bench is not None else None
    items = {s.label: score_set(s, rows, missing=missing) for s in sets}
    conditions = condition_order({i.degradation_type for group in items.values() for i in group}, known_degradations())
    kinds = ("all", *SLICE_KINDS)
    tables = {label: {kind: slice_table(group, kind, conditions) for kind in kinds} for label, group in items.items()}
    degradations = [c for c in conditions if c != CLEAN]
    models = [s.label for s in sets if s.variant == "default"]
    correlation = {
        kind: degradation_correlation({m: tables[m][kind] for m in models}, degradations) for kind in _CORRELATION_PANELS
    }
    report = Report(list(sets), items, conditions, tables, correlation)
    report.out["main"] = _main_table(report)
    for kind in _TABLE_SLICES:
        report.out[f"by_{kind}"] = _slice_table(report, kind)
    report.out["drop"] = _drop_table(report)
    report.out["correlation"] = _correlation_table(report)
    if any(s.variant == "degradation_info" for s in sets):
        report.out["degradation_info"] = _delta_table(report, "degradation_info")
    if any(s.variant == "cot" for s in sets):
        report.out["cot"] = _cot_table(report)
        report.out["cot_recognition"] = _recognition_table(report)
    return report


def _score_columns(report: Report) -> list[str]:
    return [*report.conditions, AVG]


def _main_table(report: Report) -> Table:
    columns = _score_columns(report)
    table = Table("Scores per degradation (the paper's Table 1)", ["Model", *(degradation_label(c) for c in columns)])
    blind = report.runs("no_image")
    for s in blind:
        everything = mean(i.score for i in report.items[s.label])
        table.add([f"Non-Image ({s.model})", *([None] * (len(columns) - 1)), everything],
                  [f"Non-Image ({s.model})", *(["-"] * (len(columns) - 1)), fmt_pct(everything)])
    first_model = len(table.values)
    for s in report.sets:
        if s.variant == "no_image":
            continue
        scores = report.overall(s.label)
        values = [scores.get(c) for c in columns]
        table.add([s.label, *values], [s.label, *(fmt_pct(v) for v in values)])
    if blind:
        table.sections = {0: "Base", first_model: "Models"}
    table.bold_best(range(1, len(columns) + 1), rows=range(first_model, len(table.values)))
    table.note = (
        "Scores in %: accuracy for multiple-choice, yes/no and count questions, MRA for numeric answers, every "
        "question counted. Avg. = mean of the degradation columns. Non-Image rows: the question without images, "
        "scored over every item."
    )
    return table


def _slice_table(report: Report, kind: str) -> Table:
    columns = _score_columns(report)
    name = SLICE_KINDS[kind]
    table = Table(f"Scores by {name.lower()}", ["Model", name, *(degradation_label(c) for c in columns), "n"])
    for s in report.sets:
        for slice_name, cells in report.tables[s.label][kind].items():
            values = [cells[c].score if c in cells else None for c in columns]
            n = sum(cell.n for key, cell in cells.items() if key != AVG)
            table.add([s.label, slice_name, *values, n], [s.label, slice_name, *(fmt_pct(v) for v in values), str(n)])
    table.note = "n = items of the slice over every condition."
    return table


def _drop_table(report: Report) -> Table:
    degradations = report.degradations
    header = ["Model", "Clean", "Degraded (Avg.)", "Drop (pts)", "Relative drop (%)", "Largest drop",
              *(f"Δ {degradation_label(d)}" for d in degradations)]
    table = Table("Drop from clean to degraded", header)
    for s in report.sets:
        if s.variant == "no_image":
            continue
        scores = report.overall(s.label)
        clean, avg = scores.get(CLEAN), scores.get(AVG)
        drop = clean - avg if is_number(clean) and is_number(avg) else None
        relative = drop / clean if drop is not None and clean else None
        per = {d: clean - scores[d] if is_number(clean) and is_number(scores.get(d)) else None for d in degradations}
        finite = {d: v for d, v in per.items() if v is not None}
        worst = max(finite, key=finite.get) if finite else None
        table.add(
            [s.label, clean, avg, drop, relative, worst, *(per[d] for d in degradations)],
            [s.label, fmt_pct(clean), fmt_pct(avg), fmt_delta(drop), fmt_pct(relative), degradation_label(worst) if worst else "-",
             *(fmt_delta(per[d]) for d in degradations)],
        )
    table.note = "Drop = clean − degraded, in percentage points (positive: the degradation hurts)."
    return table


def _correlation_table(report: Report) -> Table:
    columns = [*report.degradations, AVG]
    table = Table("Degradation-wise correlation |r| (point-biserial, across models)",
                  ["Panel", "Slice", *(degradation_label(c) for c in columns), "Models"])
    for kind, panel in _CORRELATION_PANELS.items():
        for slice_name, row in report.correlation[kind].items():
            rs = [abs(row[c][0]) if is_number(row[c][0]) else None for c in columns]
            models = max((row[c][1] for c in columns), default=0)
            table.add([panel, slice_name, *rs, models], [panel, slice_name, *(fmt_corr(r) for r in rs), str(models)])
    n_models = len(report.runs("default"))
    table.note = (
        f"|r| between the clean/degraded indicator and the scores of the {n_models} default-prompt run(s); "
        "Avg. pairs each model's clean score with its degraded average. "
        + ("" if n_models >= MIN_MODELS else f"It needs at least {MIN_MODELS} models: give more prediction files.")
    )
    return table


def _paired(report: Report, variant: str) -> list[tuple[PredictionSet, PredictionSet]]:
    base = {s.model: s for s in report.runs("default")}
    return [(base[s.model], s) for s in report.runs(variant) if s.model in base]


def _delta_table(report: Report, variant: str) -> Table:
    columns = [*report.degradations, AVG]
    table = Table("Change when the degradation type and severity are in the prompt (the paper's Table 2)",
                  ["Model", *(f"Δ {degradation_label(c)}" for c in columns)])
    for base, run in _paired(report, variant):
        a, b = report.overall(base.label), report.overall(run.label)
        deltas = [b[c] - a[c] if is_number(a.get(c)) and is_number(b.get(c)) else None for c in columns]
        table.add([base.model, *deltas], [base.model, *(fmt_delta(d) for d in deltas)])
    table.note = f"Δ = {variant} − default prompt, percentage points, same model and bench."
    return table


def _cot_table(report: Report) -> Table:
    table = Table("Two-stage chain of thought (the paper's Table 3)", ["Model", "Prompt", "Clean", "Degraded (Avg.)"])
    for base, run in _paired(report, "cot"):
        for s, name in ((base, "w/o CoT"), (run, "with CoT")):
            scores = report.overall(s.label)
            table.add([base.model, name, scores.get(CLEAN), scores.get(AVG)],
                      [base.model, name, fmt_pct(scores.get(CLEAN)), fmt_pct(scores.get(AVG))])
    return table


def _recognition_table(report: Report) -> Table:
    columns = report.conditions
    table = Table("Degradation recognition accuracy in CoT stage 1", ["Model", *(degradation_label(c) for c in columns)])
    names = known_degradations()
    for s in report.runs("cot"):
        by_condition: dict[str, list[float]] = {}
        for item in report.items[s.label]:
            stage1 = str(s.extras.get(item.index, {}).get("stage1", ""))
            guess = s.extras.get(item.index, {}).get("degradation_guess") or parse_degradation_guess(stage1, names)
            by_condition.setdefault(item.degradation_type, []).append(float(guess == item.degradation_type))
        values = [mean(by_condition.get(c, [])) for c in columns]
        table.add([s.model, *values], [s.model, *(fmt_pct(v) for v in values)])
    table.note = "Share of items whose stage-1 answer names the item's degradation (clean: names none)."
    return table


# ------------------------------------------------------------------ writing
def _long_scores(report: Report) -> bytes:
    rows = []
    for s in report.sets:
        for kind, table in report.tables[s.label].items():
            for slice_name, cells in table.items():
                for condition, cell in cells.items():
                    rows.append([s.model, s.variant, kind, slice_name, condition, cell.n, cell.score, cell.parse_rate])
    return csv_bytes(["model", "variant", "slice_kind", "slice", "condition", "n", "score", "parse_rate"], rows)


def _item_rows(report: Report) -> bytes:
    header = ["model", "variant", "index", "record_id", "degradation_type", "question_type", "sub_question_type",
              "task_group", "answer_type", "answer", "prediction", "parsed", "score", "parse_ok", "missing"]
    rows = []
    for s in report.sets:
        for i in report.items[s.label]:
            parsed = list(i.parsed) if isinstance(i.parsed, tuple) else i.parsed
            rows.append([s.model, s.variant, i.index, i.record_id, i.degradation_type, i.question_type, i.sub_question_type,
                         i.task_group, i.answer_type, i.answer, i.prediction, "" if parsed is None else parsed, i.score,
                         int(i.parse_ok), int(i.missing)])
    return csv_bytes(header, rows)


def _summary(report: Report) -> dict[str, Any]:
    def clean_number(v: Any) -> Any:
        return v if is_number(v) else None

    models = {}
    for s in report.sets:
        scores = report.overall(s.label)
        items = report.items[s.label]
        models[s.label] = {
            "model": s.model, "variant": s.variant, "file": str(s.path), "items": len(items),
            "missing": sum(i.missing for i in items), "parse_rate": mean(float(i.parse_ok) for i in items),
            "scores": {k: clean_number(v) for k, v in scores.items()},
        }
    overall = report.correlation["all"].get("all", {})
    return {
        "scorer": SCORER, "conditions": report.conditions, "models": models,
        "correlation_overall": {k: {"r": clean_number(r), "models": m} for k, (r, m) in overall.items()},
    }


def _plots(report: Report, folder: Path) -> dict[str, Path]:
    runs = [s for s in report.sets if s.variant != "no_image"]
    if not runs:
        return {}
    scores = {s.label: {c: report.overall(s.label).get(c) for c in _score_columns(report)} for s in runs}
    written = {"per_degradation": plots.plot_degradation_bars(scores, folder / "per_degradation.png")}
    if report.degradations:
        written["radar"] = plots.plot_radar(scores, folder / "radar.png")
        drops = {m: {d: (v[CLEAN] - v[d]) if is_number(v.get(CLEAN)) and is_number(v.get(d)) else None
                     for d in report.degradations} for m, v in scores.items()}
        written["drop"] = plots.plot_drop(drops, folder / "drop.png")
    if report.degradations and len(report.runs("default")) >= MIN_MODELS:
        panels = {title: {slice_name: {c: abs(r) if is_number(r) else None for c, (r, _) in row.items()}
                          for slice_name, row in report.correlation[kind].items()}
                  for kind, title in _CORRELATION_PANELS.items()}
        written["correlation"] = plots.plot_correlation(panels, folder / "correlation.png")
    if "degradation_info" in report.out and report.out["degradation_info"].values:
        table = report.out["degradation_info"]
        keys = [*report.degradations, AVG]
        deltas = {row[0]: dict(zip(keys, row[1:])) for row in table.values}
        written["delta"] = plots.plot_delta(deltas, folder / "delta.png")
    return written


def write_report(report: Report, out_dir: str | Path, *, with_plots: bool = True) -> list[Path]:
    """Write the report folder (see the module docstring); returns the files written."""
    folder = Path(out_dir)
    folder.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    for stem, table in report.out.items():
        written += table.write(folder, stem)
    for name, data in (("scores.csv", _long_scores(report)), ("items.csv", _item_rows(report)),
                       ("summary.json", json.dumps(_summary(report), indent=2).encode() + b"\n")):
        atomic_write_bytes(folder / name, data)
        written.append(folder / name)
    images = _plots(report, folder / "plots") if with_plots else {}
    written += images.values()
    page = ["# SpaceDG evaluation report", "", f"Scorer: {SCORER}.", "",
            "Runs: " + ", ".join(f"`{s.label}` ({len(report.items[s.label])} items, {s.path.name})" for s in report.sets), ""]
    for name, table in report.out.items():
        page.append(table.markdown())
        plot = {"main": "per_degradation", "drop": "drop", "correlation": "correlation", "degradation_info": "delta"}.get(name)
        if plot in images:
            page.append(f"![{plot}](plots/{images[plot].name})\n")
        if name == "main" and "radar" in images:
            page.append("![radar](plots/radar.png)\n")
    atomic_write_bytes(folder / "report.md", "\n".join(page).encode())
    written.append(folder / "report.md")
    return written
