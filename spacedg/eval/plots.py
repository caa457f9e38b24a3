"""PNG plots of an evaluation report (matplotlib, Agg canvas; pyplot's global state is not touched).

Inputs are nested mappings of fractions in [0, 1] (scores, drops, |r|), keyed by model or slice
and then by condition (``"ori"`` = clean, degradation names, ``"avg"``). Missing values
(``None``/NaN) leave a gap or an empty cell; they never fail a plot. Output is deterministic
(no timestamp in the PNG metadata).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.eval.labels import DEGRADATION_LABELS, degradation_label

__all__ = [
    "DEGRADATION_LABELS",
    "degradation_label",
    "plot_correlation",
    "plot_degradation_bars",
    "plot_delta",
    "plot_drop",
    "plot_radar",
]

_DPI = 150
_HEATMAP_FROM = 6  # panels with more slices than this become heatmaps


def _figure(width: float, height: float) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width, height), dpi=_DPI)
    FigureCanvasAgg(figure)
    return figure


def _save(figure: Any, path: str | Path) -> Path:
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, format="png", dpi=_DPI, bbox_inches="tight", metadata={"Software": None})
    return out


def _value(v: Any) -> float:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else math.nan


def _matrix(data: Mapping[str, Mapping[str, Any]], columns: Sequence[str], scale: float = 1.0) -> np.ndarray:
    return np.array([[_value(row.get(c)) * scale for c in columns] for row in data.values()], dtype=float).reshape(len(data), len(columns))


def _columns(data: Mapping[str, Mapping[str, Any]], what: str) -> list[str]:
    if not data:
        raise ValueError(f"{what}: nothing to plot (no rows)")
    columns: list[str] = []
    for row in data.values():
        columns += [c for c in row if c not in columns]
    if not columns:
        raise ValueError(f"{what}: nothing to plot (no columns)")
    ordered = [c for c in columns if c == "ori"] + [c for c in columns if c not in ("ori", "avg")] + [c for c in columns if c == "avg"]
    return ordered


def _colors(n: int) -> list[Any]:
    from matplotlib import colormaps

    cmap = colormaps["tab10" if n <= 10 else "tab20"]
    return [cmap(i % cmap.N) for i in range(n)]


def plot_degradation_bars(scores: Mapping[str, Mapping[str, Any]], path: str | Path, title: str = "Score per condition") -> Path:
    """Grouped bars: x = conditions (Clean first, Avg. last), one bar per model, y in %."""
    columns = _columns(scores, "plot_degradation_bars")
    values = _matrix(scores, columns, 100)
    models = list(scores)
    figure = _figure(max(7.0, 0.75 * len(columns) * max(1, min(len(models), 6)) / 2 + 3), 4.2)
    ax = figure.add_subplot()
    width = 0.8 / len(models)
    x = np.arange(len(columns))
    for k, (model, color) in enumerate(zip(models, _colors(len(models)))):
        bars = ax.bar(x - 0.4 + width * (k + 0.5), np.nan_to_num(values[k], nan=0.0), width, label=model, color=color)
        if len(models) <= 4:
            for bar, v in zip(bars, values[k]):
                if math.isfinite(v):
                    ax.annotate(f"{v:.1f}", (bar.get_x() + bar.get_width() / 2, v), ha="center", va="bottom", fontsize=6,
                                xytext=(0, 1), textcoords="offset points")
    ax.set_xticks(x, [degradation_label(c) for c in columns], rotation=30, ha="right")
    top = np.nanmax(values) if np.isfinite(values).any() else 100
    ax.set_ylim(0, max(10.0, min(100.0, top * 1.15 + 2)))
    ax.set_ylabel("score (%)")
    ax.set_title(title)
    ax.grid(axis="y", alpha=0.3)
    ax.legend(fontsize=7, ncols=max(1, math.ceil(len(models) / 12)), loc="upper left", bbox_to_anchor=(1.01, 1))
    return _save(figure, path)


def plot_radar(scores: Mapping[str, Mapping[str, Any]], path: str | Path, title: str = "Per-degradation performance") -> Path:
    """Radar chart: one polygon per model over the conditions (clean included, Avg. left out)."""
    columns = [c for c in _columns(scores, "plot_radar") if c != "avg"]
    values = _matrix(scores, columns, 100)
    angles = np.linspace(0, 2 * np.pi, len(columns), endpoint=False)
    figure = _figure(6.5, 5.5)
    ax = figure.add_subplot(projection="polar")
    for k, (model, color) in enumerate(zip(scores, _colors(len(scores)))):
        closed = np.append(values[k], values[k][:1])
        ax.plot(np.append(angles, angles[:1]), closed, color=color, linewidth=1.4, label=model)
        ax.fill(np.append(angles, angles[:1]), np.nan_to_num(closed), color=color, alpha=0.06)
    ax.set_xticks(angles, [degradation_label(c) for c in columns], fontsize=8)
    top = np.nanmax(values) if np.isfinite(values).any() else 100
    ax.set_ylim(0, max(10.0, min(100.0, math.ceil(top / 10) * 10)))
    ax.tick_params(axis="y", labelsize=7)
    ax.set_title(title, pad=18)
    ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.08, 1.05))
    return _save(figure, path)


def _heatmap(ax: Any, values: np.ndarray, rows: Sequence[str], columns: Sequence[str], *, cmap: str, vmin: float, vmax: float,
             fmt: str) -> Any:
    masked = np.ma.masked_invalid(values)
    image = ax.imshow(masked, cmap=cmap, vmin=vmin, vmax=vmax, aspect="auto")
    ax.set_xticks(np.arange(len(columns)), [degradation_label(c) for c in columns], rotation=35, ha="right", fontsize=7)
    ax.set_yticks(np.arange(len(rows)), list(rows), fontsize=7)
    for (i, j), v in np.ndenumerate(values):
        text = fmt.format(v) if math.isfinite(v) else "n/a"
        red, green, blue, _ = image.cmap(image.norm(v)) if math.isfinite(v) else (1, 1, 1, 1)
        dark = 0.299 * red + 0.587 * green + 0.114 * blue < 0.5  # perceived luminance of the cell
        ax.text(j, i, text, ha="center", va="center", fontsize=6, color="white" if dark else "black")
    return image


def _diverging(data: Mapping[str, Mapping[str, Any]], path: str | Path, what: str, title: str, label: str) -> Path:
    columns = _columns(data, what)
    values = _matrix(data, columns, 100)
    limit = float(np.nanmax(np.abs(values))) if np.isfinite(values).any() else 1.0
    limit = max(limit, 1.0)
    figure = _figure(max(6.0, 0.7 * len(columns) + 3), max(2.2, 0.32 * len(data) + 1.5))
    ax = figure.add_subplot()
    image = _heatmap(ax, values, list(data), columns, cmap="RdBu_r", vmin=-limit, vmax=limit, fmt="{:+.1f}")
    figure.colorbar(image, ax=ax, label=label, fraction=0.04)
    ax.set_title(title)
    return _save(figure, path)


def plot_drop(drops: Mapping[str, Mapping[str, Any]], path: str | Path) -> Path:
    """Heatmap of clean − degraded per model and degradation, in percentage points (red: worse)."""
    return _diverging(drops, path, "plot_drop", "Drop from clean (percentage points)", "clean − degraded (pts)")


def plot_delta(deltas: Mapping[str, Mapping[str, Any]], path: str | Path, title: str = "Change with degradation info in the prompt") -> Path:
    """Heatmap of a prompt variant's score change per model and degradation, in points."""
    return _diverging(deltas, path, "plot_delta", title, "Δ score (pts)")


def plot_correlation(panels: Mapping[str, Mapping[str, Mapping[str, Any]]], path: str | Path) -> Path:
    """The paper's Figure 5: one subplot per panel (overall, answer format, task group, question
    type); grouped |r| bars per degradation, or an annotated heatmap for panels with many slices."""
    kept = {title: slices for title, slices in panels.items() if slices}
    if not kept:
        raise ValueError("plot_correlation: nothing to plot (no panels with slices)")
    heights = [max(2.6, 0.3 * len(s) + 1.6) if len(s) >= _HEATMAP_FROM else 2.8 for s in kept.values()]
    columns = _columns(next(iter(kept.values())), "plot_correlation")
    figure = _figure(max(8.0, 0.75 * len(columns) + 4), sum(heights) + 0.6)
    grid = figure.add_gridspec(len(kept), 1, height_ratios=heights, hspace=0.9)
    for row, (title, slices) in enumerate(kept.items()):
        ax = figure.add_subplot(grid[row])
        cols = _columns(slices, "plot_correlation")
        values = _matrix(slices, cols)
        if len(slices) >= _HEATMAP_FROM:
            image = _heatmap(ax, values, list(slices), cols, cmap="viridis", vmin=0.0, vmax=1.0, fmt="{:.2f}")
            figure.colorbar(image, ax=ax, label="|r|", fraction=0.03)
        else:
            width = 0.8 / len(slices)
            x = np.arange(len(cols))
            for k, (name, color) in enumerate(zip(slices, _colors(len(slices)))):
                ax.bar(x - 0.4 + width * (k + 0.5), np.nan_to_num(values[k], nan=0.0), width, label=name, color=color)
            ax.set_xticks(x, [degradation_label(c) for c in cols], rotation=30, ha="right", fontsize=7)
            ax.set_ylim(0, 1)
            ax.set_ylabel("|r|")
            ax.grid(axis="y", alpha=0.3)
            ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1))
        ax.set_title(title, loc="left", fontsize=9)
    return _save(figure, path)
