"""The ``degradation_info`` preamble states the metres a scale-aware preset was rendered with."""

from __future__ import annotations

import re

import pytest

from spacedg.data.chain import Chain
from spacedg.eval.bench import BenchRow
from spacedg.eval.prompts import degradation_info
from spacedg.plugins.specs import REFERENCE_DEPTH_M, AnswerType


def _row(chain: str, scene_depth: float | None = None, provenance: bool = True) -> BenchRow:
    prov = Chain.parse(chain).provenance(7, scene_depth=scene_depth) if provenance else []
    return BenchRow(0, "Where is the chair?", "A", AnswerType.MCQ, "t", degradation_type=chain, degradation=tuple(prov))


def _range(text: str, param: str) -> tuple[float, float]:
    m = re.search(rf"{param} (?:in \[([0-9.e+-]+), ([0-9.e+-]+)\]|= ([0-9.e+-]+)) m", text)
    assert m, text
    return (float(m[1]), float(m[2])) if m[1] else (float(m[3]), float(m[3]))


@pytest.mark.parametrize(("chain", "param", "written"), [
    ("defocus", "depth", (1.0, 8.0)), ("motion_blur", "trans", (0.2, 0.35)), ("haze", "depth_ref", (12.5, 12.5)),
])
@pytest.mark.parametrize("depth", [1.0, 4.0])
def test_scale_aware_metres_are_resolved_at_the_scene_depth(chain: str, param: str, written: tuple[float, float], depth: float) -> None:
    row = _row(chain, depth)
    (step,) = row.degradation
    assert step["scene_depth_m"] == depth
    text = degradation_info(row)
    low, high = _range(text, param)
    ratio = depth / REFERENCE_DEPTH_M
    assert low == pytest.approx(written[0] * ratio, rel=1e-3) and high == pytest.approx(written[1] * ratio, rel=1e-3)
    assert low <= step["params"][param] <= high  # the rendered value lies in the stated range
    assert f"scaled to the scene depth of {depth:g} m" in text and f"at {REFERENCE_DEPTH_M:g} m" in text


def test_metres_at_the_reference_and_for_a_foreign_bench() -> None:
    at_reference = degradation_info(_row("defocus"))  # resolved without a scene depth: the ranges as written
    assert "aperture in [10, 15] px at a 1752×1168 image, scaled with its size, depth in [1, 8] m)" in at_reference
    assert "scene depth" not in at_reference  # metres as written: no depth scaling without a scene depth
    foreign = degradation_info(_row("motion_blur", provenance=False))
    assert "trans in [0.2, 0.35] m at a scene depth of 2.5 m, scaled with the scene's depth" in foreign
    assert "rot in [0.06, 0.12] rad" in foreign


def test_a_chain_scales_only_its_scale_aware_steps() -> None:
    text = degradation_info(_row("haze:3+low_res", 5.0))
    assert "depth_ref = 25 m (scaled to the scene depth of 5 m; 12.5 m at 2.5 m)" in text
    assert "low res (severity given as the rendering parameter ranges: scale in [0.02, 0.05] at a 1752×1168 image, scaled with its size)" in text
