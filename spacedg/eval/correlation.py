"""The paper's degradation-wise correlation analysis (its Figure 5): point-biserial |r|.

For one analysis slice (all items, an answer format, a task group or a question type) and one
degradation ``d``, take the ``M`` models that have both a clean and a ``d`` score on the slice::

    x = [0, …, 0, 1, …, 1]                      (M clean, then M degraded)
    y = [s_clean(1), …, s_clean(M), s_d(1), …, s_d(M)]
    r = corr(x, y)                              (Pearson; x binary → point-biserial)

and report ``|r|``: the larger, the more consistently the degradation shifts scores across
models. :func:`point_biserial` agrees with ``scipy.stats.pointbiserialr`` (tested). ``r`` is
undefined (NaN) when every ``y`` is equal or fewer than two models take part: with one model,
``|r|`` would be 1 whenever its two scores differ at all, which says nothing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np

from spacedg.eval.aggregate import AVG, Cell
from spacedg.eval.bench import CLEAN

__all__ = ["MIN_MODELS", "degradation_correlation", "point_biserial"]

#: Fewest models a correlation is computed over.
MIN_MODELS = 2


def point_biserial(x: Sequence[float], y: Sequence[float]) -> float:
    """Pearson correlation of a binary ``x`` (0/1) with ``y``; NaN when undefined.

    Computed as ``(mean(y | x=1) − mean(y | x=0)) / std(y) · sqrt(p (1 − p))`` with the
    population std and ``p`` the share of ones, in float64 on centred values (no cancellation
    for scores near 1). Undefined: ``x`` not both 0 and 1, ``y`` constant, or a non-finite ``y``.
    """
    xs = np.asarray(x, dtype=np.float64)
    ys = np.asarray(y, dtype=np.float64)
    if xs.shape != ys.shape or xs.ndim != 1:
        raise ValueError(f"point_biserial: x and y must be 1-D of equal length, got {xs.shape} and {ys.shape}")
    if not np.all((xs == 0) | (xs == 1)):
        raise ValueError("point_biserial: x must hold only 0 and 1")
    if not np.all(np.isfinite(ys)):
        return math.nan
    ones = xs == 1
    n1, n = int(ones.sum()), xs.size
    if n1 == 0 or n1 == n:
        return math.nan
    centred = ys - ys.mean()
    std = math.sqrt(float(np.dot(centred, centred)) / n)
    if std <= 1e-15 * max(1.0, float(np.abs(ys).max())):
        return math.nan
    p = n1 / n
    r = (float(centred[ones].mean()) - float(centred[~ones].mean())) / std * math.sqrt(p * (1 - p))
    return max(-1.0, min(1.0, r))


def degradation_correlation(
    tables: Mapping[str, Mapping[str, Mapping[str, Cell]]],
    degradations: Sequence[str],
) -> dict[str, dict[str, tuple[float, int]]]:
    """``slice → degradation (and "avg") → (r, models used)`` across models.

    ``tables`` is ``model → slice → condition → Cell`` (:func:`~spacedg.eval.aggregate.slice_table`
    of each model for one slice kind). A model takes part in a (slice, degradation) pair when it
    has a finite score under both clean and that degradation. ``r`` is signed (negative: the
    degradation lowers scores); report ``abs(r)``.
    """
    slices = sorted({label for table in tables.values() for label in table})
    out: dict[str, dict[str, tuple[float, int]]] = {}
    for label in slices:
        row: dict[str, tuple[float, int]] = {}
        for condition in [*degradations, AVG]:
            clean, degraded = [], []
            for table in tables.values():
                cells = table.get(label, {})
                a, b = cells.get(CLEAN), cells.get(condition)
                if a is not None and b is not None and math.isfinite(a.score) and math.isfinite(b.score):
                    clean.append(a.score)
                    degraded.append(b.score)
            m = len(clean)
            r = point_biserial([0] * m + [1] * m, clean + degraded) if m >= MIN_MODELS else math.nan
            row[condition] = (r, m)
        out[label] = row
    return out
