"""A small table type written as Markdown (for reading) and CSV (for tools), and number formats.

Scores are stored as fractions in [0, 1] and shown as percent with one decimal (the paper's
tables); differences as signed percentage points; correlations with two decimals. A missing
value (``None`` or NaN) is shown as ``-`` in Markdown and left empty in CSV.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from spacedg.files import atomic_write_bytes

__all__ = ["Table", "csv_bytes", "fmt_corr", "fmt_delta", "fmt_pct", "is_number"]


def is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def fmt_pct(value: Any) -> str:
    """0.5034 → ``"50.3"``; missing → ``"-"``."""
    return f"{100 * value:.1f}" if is_number(value) else "-"


def fmt_delta(value: Any) -> str:
    """0.014 → ``"+1.4"``, −0.0004 → ``"-0.0"``; missing → ``"-"``."""
    return f"{100 * value:+.1f}" if is_number(value) else "-"


def fmt_corr(value: Any) -> str:
    """0.4567 → ``"0.46"``; missing → ``"-"``."""
    return f"{value:.2f}" if is_number(value) else "-"


def csv_bytes(header: Sequence[str], rows: Sequence[Sequence[Any]]) -> bytes:
    """CSV text (UTF-8) of ``rows`` under ``header``; ``None`` and non-finite floats as empty cells."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(header)
    for row in rows:
        writer.writerow(["" if v is None or (isinstance(v, float) and not math.isfinite(v)) else v for v in row])
    return buffer.getvalue().encode()


@dataclass
class Table:
    """Rows of cells under a header. ``values`` keeps the raw numbers (for CSV and JSON),
    ``cells`` the formatted text (for Markdown); ``sections`` inserts a bold row before a row
    index (the paper's "Base" / "Models" bands); ``bold`` marks (row, column) cells."""

    title: str
    header: list[str]
    cells: list[list[str]] = field(default_factory=list)
    values: list[list[Any]] = field(default_factory=list)
    sections: dict[int, str] = field(default_factory=dict)
    bold: set[tuple[int, int]] = field(default_factory=set)
    note: str = ""

    def add(self, values: Sequence[Any], cells: Sequence[str]) -> None:
        if len(values) != len(self.header) or len(cells) != len(self.header):
            raise ValueError(f"{self.title}: a row needs {len(self.header)} cells")
        self.values.append(list(values))
        self.cells.append(list(cells))

    def bold_best(self, columns: Sequence[int], *, rows: Sequence[int] | None = None, highest: bool = True) -> None:
        """Bold the best number of each column among ``rows`` (all rows by default; needs ≥ 2)."""
        rows = list(range(len(self.values))) if rows is None else list(rows)
        if len(rows) < 2:
            return
        for col in columns:
            scored = [(self.values[r][col], r) for r in rows if is_number(self.values[r][col])]
            if len(scored) < 2:
                continue
            best = max(v for v, _ in scored) if highest else min(v for v, _ in scored)
            self.bold.update((r, col) for v, r in scored if v == best)

    def markdown(self) -> str:
        def line(cells: Sequence[str]) -> str:
            return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"

        numeric = [all(v is None or is_number(v) for v in column) for column in zip(*self.values)] or [False] * len(self.header)
        align = ["---:" if k > 0 and numeric[k] else "---" for k in range(len(self.header))]
        out = [f"### {self.title}", "", line(self.header), "|" + "|".join(align) + "|"]
        for r, cells in enumerate(self.cells):
            if r in self.sections:
                out.append(line([f"*{self.sections[r]}*"] + [""] * (len(self.header) - 1)))
            out.append(line([f"**{c}**" if (r, k) in self.bold else c for k, c in enumerate(cells)]))
        if self.note:
            out += ["", self.note]
        return "\n".join(out) + "\n"

    def csv_text(self) -> str:
        return csv_bytes(self.header, self.values).decode()

    def write(self, folder: Path, stem: str) -> list[Path]:
        """Write ``<stem>.md`` and ``<stem>.csv`` atomically; returns both paths."""
        paths = [folder / f"{stem}.md", folder / f"{stem}.csv"]
        atomic_write_bytes(paths[0], self.markdown().encode())
        atomic_write_bytes(paths[1], self.csv_text().encode())
        return paths
