"""PNG plots of an evaluation report (matplotlib, Agg canvas; pyplot's global state is not touched).

Inputs are nested mappings of fractions in [0, 1] (scores, drops, deltas, |r|), keyed by model or
slice and then by condition (``"ori"`` = clean, degradation names, ``"avg"``); plots show them in
percent / percentage points (|r| stays as is). Columns are ordered Clean first, then as the first
row lists them (later rows may add more), Avg. last. Missing values (``None``/NaN) leave a gap or an
``n/a`` cell; they never fail a plot. Output is deterministic (no timestamp or version in the PNG).

* :func:`plot_degradation_bars` - grouped bars, one colour per model (the paper's Table 1 as a chart);
* :func:`plot_radar` - one polygon per model over the conditions (the paper's radar figure);
* :func:`plot_drop` / :func:`plot_delta` - diverging, annotated heatmaps in points;
* :func:`plot_correlation` - the paper's degradation-wise |r| figure, one subplot per panel.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from numbers import Real
from pathlib import Path
from typing import Any

import numpy as np

from spacedg.data.chain import CLEAN
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

_AVG = "avg"
_HEATMAP_ABOVE = 5  # a correlation panel with more slices than this is drawn as a heatmap
_NA = "n/a"
_NA_COLOR = "#9a9a9a"
_GAP_FACE = "#f0f0f0"  # background of heatmap cells without a value


# ---------------------------------------------------------------- helpers


def _figure(width: float, height: float) -> Any:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    figure = Figure(figsize=(width, height), dpi=_DPI, layout="constrained")
    FigureCanvasAgg(figure)
    return figure


def _save(figure: Any, path: str | Path) -> Path:
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    figure.savefig(out, format="png", dpi=_DPI, bbox_inches="tight", pad_inches=0.08, facecolor="white",
                   metadata={"Software": None})
    return out


def _value(v: Any) -> float:
    if isinstance(v, Real) and not isinstance(v, bool):
        f = float(v)
        return f if math.isfinite(f) else math.nan
    return math.nan


def _matrix(data: Mapping[str, Mapping[str, Any]], columns: Sequence[str], scale: float = 1.0) -> np.ndarray:
    rows = [[_value(row.get(c)) * scale for c in columns] for row in data.values()]
    return np.array(rows, dtype=float).reshape(len(data), len(columns))


def _columns(data: Mapping[str, Mapping[str, Any]], what: str) -> list[str]:
    """Clean first, the others in first-seen order (the first row's order), Avg. last."""
    if not data:
        raise ValueError(f"{what}: nothing to plot (no models / slices given)")
    seen: dict[str, None] = {}
    for name, row in data.items():
        if not isinstance(row, Mapping):
            raise TypeError(f"{what}: the entry for {name!r} is not a mapping of condition -> value")
        seen.update(dict.fromkeys(str(c) for c in row))
    columns = list(seen)
    if not columns:
        raise ValueError(f"{what}: nothing to plot (no conditions given)")
    middle = [c for c in columns if c not in (CLEAN, _AVG)]
    return [c for c in (CLEAN,) if c in seen] + middle + [c for c in (_AVG,) if c in seen]


def _colors(n: int) -> list[Any]:
    """``n`` distinct colours: tab10 up to 10, tab20 up to 20, then tab20 + tab20b + tab20c."""
    from matplotlib import colormaps

    if n <= 10:
        palette = [colormaps["tab10"](i) for i in range(10)]
    else:
        palette = [colormaps["tab20"](i) for i in range(20)]
        if n > 20:
            palette += [colormaps[name](i) for name in ("tab20b", "tab20c") for i in range(20)]
    return [palette[i % len(palette)] for i in range(n)]


def _fits_in_a_row(names: Sequence[str], width_in: float, reserved_chars: int = 0) -> bool:
    """Whether a one-row legend of ``names`` (about 7.5 pt text) fits in ``width_in`` inches."""
    chars = sum(len(n) + 5 for n in names) + reserved_chars
    return chars <= width_in * 11


def _legend(ax: Any, names: Sequence[str], width_in: float, *, above: str = "center", reserved_chars: int = 0) -> bool:
    """Entries that fit in one row go above the plot (``above``: centred or at the right, beside a
    left-aligned title); otherwise they go in columns at the right. Returns whether it went above."""
    n = len(names)
    if n <= 6 and _fits_in_a_row(names, width_in, reserved_chars):
        anchor = (0.5, 1.0) if above == "center" else (1.0, 1.0)
        ax.legend(loc=f"lower {above}", bbox_to_anchor=anchor, ncols=n, fontsize=7.5, frameon=False,
                  handlelength=1.2, borderaxespad=0.1, columnspacing=1.2)
        return True
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), ncols=max(1, math.ceil(n / 16)), fontsize=7,
              frameon=False, handlelength=1.2, columnspacing=1.0)
    return False


def _nice_top(values: np.ndarray, cap: float, step: float) -> float:
    if not np.isfinite(values).any():
        return cap
    top = float(np.nanmax(values))
    return min(cap, max(step, math.ceil(top * 1.12 / step) * step))


def _grouped_bars(ax: Any, values: np.ndarray, names: Sequence[str], columns: Sequence[str], *, fmt: str | None,
                  fontsize: float = 6.0) -> None:
    """One bar group per column, one bar per row of ``values``; NaN → no bar (and ``n/a`` if labelled)."""
    n = max(1, len(names))
    width = 0.82 / n
    x = np.arange(len(columns))
    for k, (name, color) in enumerate(zip(names, _colors(n))):
        row = values[k]
        centres = x - 0.41 + width * (k + 0.5)
        ax.bar(centres, np.where(np.isfinite(row), row, 0.0), width, label=name, color=color, edgecolor="white",
               linewidth=0.4 if n <= 8 else 0.0, zorder=2)
        if fmt is None:
            continue
        for cx, v in zip(centres, row):
            text, y, colour = (fmt.format(v), v, "black") if math.isfinite(v) else (_NA, 0.0, _NA_COLOR)
            ax.annotate(text, (cx, y), xytext=(0, 1.5), textcoords="offset points", ha="center", va="bottom",
                        fontsize=fontsize, color=colour, rotation=90 if n > 2 else 0, zorder=3)
    ax.set_xticks(x, [degradation_label(c) for c in columns], rotation=30, ha="right", rotation_mode="anchor",
                  fontsize=8)
    ax.set_xlim(-0.6, len(columns) - 0.4)
    ax.grid(axis="y", alpha=0.35, zorder=0)
    ax.set_axisbelow(True)
    for side in ("top", "right"):
        ax.spines[side].set_visible(False)


def _separators(ax: Any, columns: Sequence[str], *, heatmap: bool = False) -> None:
    """A dotted line after Clean and before Avg. (they are not degradations)."""
    style = {"color": "white" if heatmap else "#808080", "linewidth": 4.0 if heatmap else 0.8,
             "linestyle": "-" if heatmap else ":", "zorder": 4}
    if columns and columns[0] == CLEAN and len(columns) > 1:
        ax.axvline(0.5, **style)
    if columns and columns[-1] == _AVG and len(columns) > 1:
        ax.axvline(len(columns) - 1.5, **style)


def _heatmap(ax: Any, values: np.ndarray, rows: Sequence[str], columns: Sequence[str], *, cmap: str, vmin: float,
             vmax: float, fmt: str) -> Any:
    from matplotlib import colormaps

    colormap = colormaps[cmap].with_extremes(bad=_GAP_FACE)
    image = ax.imshow(np.ma.masked_invalid(values), cmap=colormap, vmin=vmin, vmax=vmax, aspect="auto",
                      interpolation="nearest")
    ax.set_xticks(np.arange(len(columns)), [degradation_label(c) for c in columns], rotation=30, ha="right",
                  rotation_mode="anchor", fontsize=8)
    ax.set_yticks(np.arange(len(rows)), [str(r) for r in rows], fontsize=8 if len(rows) <= 15 else 7)
    ax.tick_params(length=0)
    for spine in ax.spines.values():
        spine.set_visible(False)
    ax.set_xticks(np.arange(len(columns) + 1) - 0.5, minor=True)
    ax.set_yticks(np.arange(len(rows) + 1) - 0.5, minor=True)
    ax.grid(which="minor", color="white", linewidth=0.8)
    ax.tick_params(which="minor", length=0)
    fontsize = 7 if len(rows) <= 15 and len(columns) <= 12 else 6
    for (i, j), v in np.ndenumerate(values):
        if math.isfinite(v):
            r, g, b, _ = colormap(image.norm(v))
            dark = 0.299 * r + 0.587 * g + 0.114 * b < 0.5
            ax.text(j, i, fmt.format(v), ha="center", va="center", fontsize=fontsize, color="white" if dark else "black")
        else:
            ax.text(j, i, _NA, ha="center", va="center", fontsize=fontsize, color=_NA_COLOR)
    return image


def _diverging(data: Mapping[str, Mapping[str, Any]], path: str | Path, what: str, title: str, label: str,
               cmap: str) -> Path:
    columns = _columns(data, what)
    values = _matrix(data, columns, 100)
    limit = float(np.nanmax(np.abs(values))) if np.isfinite(values).any() else 1.0
    limit = max(1.0, math.ceil(limit))
    rows = [str(r) for r in data]
    label_width = max((len(r) for r in rows), default=4) * 0.06
    figure = _figure(max(6.0, 0.62 * len(columns) + label_width + 2.2), max(2.4, 0.3 * len(rows) + 1.7))
    ax = figure.add_subplot()
    image = _heatmap(ax, values, rows, columns, cmap=cmap, vmin=-limit, vmax=limit, fmt="{:+.1f}")
    _separators(ax, columns, heatmap=True)
    colorbar = figure.colorbar(image, ax=ax, fraction=0.05, pad=0.02, aspect=max(10, 1.5 * len(rows)))
    colorbar.set_label(label, fontsize=8)
    colorbar.ax.tick_params(labelsize=7)
    colorbar.outline.set_visible(False)
    ax.set_title(title, fontsize=10)
    return _save(figure, path)


# ---------------------------------------------------------------- plots


def plot_degradation_bars(scores: Mapping[str, Mapping[str, float | None]], path: str | Path, *,
                          title: str = "Score per condition") -> Path:
    """Grouped bars: x = conditions (Clean first, Avg. last), one colour per model, y = score in %.

    ``scores[model][condition]`` are fractions; values are printed on the bars for up to 4 models.
    """
    columns = _columns(scores, "plot_degradation_bars")
    values = _matrix(scores, columns, 100)
    models = [str(m) for m in scores]
    n = len(models)
    figure = _figure(min(20.0, max(7.0, 2.0 + len(columns) * (0.3 + 0.17 * n))), 4.4 if n <= 6 else 5.0)
    ax = figure.add_subplot()
    _grouped_bars(ax, values, models, columns, fmt="{:.1f}" if n <= 4 else None)
    _separators(ax, columns)
    top = _nice_top(values, 100.0, 10.0)
    if n <= 4 and top < 100.0:
        top = min(100.0, top + 10.0 if n > 2 else top + 5.0)  # room for the (rotated) value labels
    ax.set_ylim(0, top)
    ax.set_ylabel("score (%)")
    above = _legend(ax, models, figure.get_figwidth())
    ax.set_title(title, fontsize=10, pad=20 if above else 6)
    return _save(figure, path)


def plot_radar(scores: Mapping[str, Mapping[str, float | None]], path: str | Path, *,
               title: str = "Per-degradation performance") -> Path:
    """Radar chart: one polygon per model over the conditions (Clean at the top, Avg. left out), in %.

    The radial axis starts a little below the lowest score so that differences stay visible; a
    missing value breaks the polygon (a gap) and the points around it are still marked.
    """
    columns = [c for c in _columns(scores, "plot_radar") if c != _AVG]
    if not columns:
        raise ValueError("plot_radar: nothing to plot (only 'avg' given)")
    values = _matrix(scores, columns, 100)
    models = [str(m) for m in scores]
    n = len(models)
    angles = np.linspace(0, 2 * np.pi, len(columns), endpoint=False)
    figure = _figure(7.6 if n > 6 else 6.4, 6.2)
    ax = figure.add_subplot(projection="polar")
    ax.set_theta_offset(np.pi / 2)
    ax.set_theta_direction(-1)
    finite = values[np.isfinite(values)]
    if finite.size:
        low, high = float(finite.min()), float(finite.max())
        top = min(100.0, max(10.0, math.ceil((high + 2) / 10) * 10))
        bottom = max(0.0, math.floor((low - 0.35 * max(high - low, 10)) / 10) * 10)
    else:
        bottom, top = 0.0, 100.0
    fill = n <= 6
    closed_angles = np.append(angles, angles[:1])
    for k, (model, color) in enumerate(zip(models, _colors(n))):
        row = np.append(values[k], values[k][:1])
        ax.plot(closed_angles, row, color=color, linewidth=1.6 if n <= 6 else 1.1, label=model,
                marker="o", markersize=3.5 if n <= 6 else 2.2, zorder=3)
        if fill and np.isfinite(row).all():
            ax.fill(closed_angles, row, color=color, alpha=0.08, zorder=2)
    ax.set_ylim(bottom, top)
    step = 10.0 if top - bottom > 30 else 5.0
    ticks = np.arange(bottom + step, top + 0.01, step)
    ax.set_yticks(ticks, [f"{t:g}%" for t in ticks], fontsize=7, color="#555555")
    for label in ax.get_yticklabels():
        label.set_bbox({"facecolor": "white", "alpha": 0.75, "edgecolor": "none", "pad": 0.6})
    ax.set_rlabel_position(180 / len(columns) if len(columns) > 1 else 22.5)
    ax.set_xticks(angles, [degradation_label(c) for c in columns], fontsize=9)
    ax.tick_params(axis="x", pad=8)
    ax.grid(color="#c8c8c8", linewidth=0.7)
    ax.spines["polar"].set_color("#9a9a9a")
    ax.set_title(title, fontsize=11, pad=22)
    if n <= 6:
        ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.08), ncols=_radar_legend_columns(models, figure.get_figwidth()), fontsize=8, frameon=False)
    else:
        ax.legend(loc="upper left", bbox_to_anchor=(1.12, 1.05), ncols=max(1, math.ceil(n / 26)), fontsize=7,
                  frameon=False, handlelength=1.4)
    return _save(figure, path)


def _radar_legend_columns(names: Sequence[str], width_in: float) -> int:
    for columns in (len(names), 3, 2):
        rows = [names[i:i + columns] for i in range(0, len(names), columns)]
        if columns <= len(names) and all(_fits_in_a_row(row, width_in) for row in rows):
            return columns
    return 1


def plot_drop(drops: Mapping[str, Mapping[str, float | None]], path: str | Path, *,
              title: str = "Drop from clean (clean − degraded, percentage points)") -> Path:
    """Annotated heatmap of ``drops[model][degradation]`` (fractions, clean − degraded) in points;
    red = worse than clean, blue = better, white = no change, grey ``n/a`` = missing."""
    return _diverging(drops, path, "plot_drop", title, "drop (pts)", "RdBu_r")


def plot_delta(deltas: Mapping[str, Mapping[str, float | None]], path: str | Path, *,
               title: str = "Change with degradation info in the prompt (percentage points)") -> Path:
    """Annotated heatmap of a prompt variant's score change ``deltas[model][condition]`` (fractions)
    in points; green = the variant helps, purple = it hurts, grey ``n/a`` = missing."""
    return _diverging(deltas, path, "plot_delta", title, "Δ score (pts)", "PRGn")


def plot_correlation(panels: Mapping[str, Mapping[str, Mapping[str, float | None]]], path: str | Path, *,
                     r_max: float | None = 1.0) -> Path:
    """The paper's degradation-wise correlation figure: one subplot per panel, in the given order.

    ``panels[title][slice][degradation]`` = |r|. A panel with up to 5 slices is grouped bars
    (x = degradation, one colour per slice); with more it is a heatmap (slices × degradations,
    annotated with 2 decimals). Missing values are blank bars / ``n/a`` cells. ``r_max`` is the top
    of the |r| axis (``None``: fitted to the data).
    """
    if not panels:
        raise ValueError("plot_correlation: nothing to plot (no panels given)")
    kept = {str(title): slices for title, slices in panels.items() if slices}
    if not kept:
        raise ValueError("plot_correlation: nothing to plot (every panel is empty)")
    layout = {title: _columns(slices, f"plot_correlation panel {title!r}") for title, slices in kept.items()}
    all_values = np.concatenate([_matrix(kept[t], layout[t]).ravel() for t in kept])
    top = r_max if r_max is not None else _nice_top(all_values, 1.0, 0.1)
    heights = [0.3 * len(s) + 1.1 if len(s) > _HEATMAP_ABOVE else 2.3 for s in kept.values()]
    widest = max(len(c) for c in layout.values())
    figure = _figure(max(8.0, 0.8 * widest + 3.5), sum(heights) + 0.4)
    axes = figure.subplots(len(kept), 1, height_ratios=heights, squeeze=False)[:, 0]
    for ax, (title, slices) in zip(axes, kept.items()):
        columns = layout[title]
        values = _matrix(slices, columns)
        names = [str(s) for s in slices]
        if len(slices) > _HEATMAP_ABOVE:
            image = _heatmap(ax, values, names, columns, cmap="Blues", vmin=0.0, vmax=top, fmt="{:.2f}")
            colorbar = figure.colorbar(image, ax=ax, fraction=0.04, pad=0.01, aspect=max(12.0, 1.0 * len(names)))
            colorbar.set_label("|r|", fontsize=8)
            colorbar.ax.tick_params(labelsize=7)
            colorbar.outline.set_visible(False)
        else:
            _grouped_bars(ax, values, names, columns, fmt="{:.2f}" if len(slices) <= 2 else None, fontsize=6.5)
            ax.set_ylim(0, top)
            ax.set_ylabel("|r|")
            if len(names) > 1:  # a lone slice (the overall panel) needs no legend
                _legend(ax, names, figure.get_figwidth() - 1.5, above="right", reserved_chars=len(title) + 4)
        ax.set_title(title, loc="left", fontsize=9, fontweight="bold")
    return _save(figure, path)
