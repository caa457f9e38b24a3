"""Report plots (spacedg.eval.plots): written, readable, not blank, deterministic, robust to gaps."""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from spacedg.eval import plots
from spacedg.eval.labels import degradation_label

NINE = ["defocus", "distortion", "haze", "jpeg_compression", "low_light", "low_res", "motion_blur", "over_exposure",
        "water_droplets"]
#: two rows of the paper's Table 1 (fractions)
PAPER = {
    "GPT-5.4": dict(zip(["ori", *NINE, "avg"], [0.503, 0.433, 0.499, 0.456, 0.482, 0.425, 0.428, 0.462, 0.499, 0.472, 0.462])),
    "Gemini-3.1-Pro": dict(zip(["ori", *NINE, "avg"], [0.631, 0.518, 0.636, 0.572, 0.604, 0.512, 0.531, 0.56, 0.633, 0.538, 0.567])),
}
DROPS = {m: {d: v["ori"] - v[d] for d in NINE} for m, v in PAPER.items()}
PANELS = {
    "(a) Overall": {"overall": {d: 0.02 * i for i, d in enumerate(NINE)}},
    "(b) Answer format": {"MCQ": {d: 0.1 for d in NINE}, "NA": {d: 0.2 for d in NINE}},
    "(d) Question type": {f"type_{k}": {d: (k * 0.07 + i * 0.01) % 1 for i, d in enumerate(NINE)} for k in range(11)},
}


def _check(path: Path) -> None:
    assert path.suffix == ".png" and path.is_file()
    with Image.open(path) as image:
        assert image.format == "PNG"
        pixels = np.asarray(image.convert("RGB"))
    assert pixels.shape[1] > 300 and pixels.shape[0] > 200, pixels.shape
    packed = pixels.astype(np.uint32) @ np.array([1 << 16, 1 << 8, 1], dtype=np.uint32)
    assert len(np.unique(packed)) > 20  # not a single colour / blank


def _table(models: int, columns: int, *, clean: bool = True, avg: bool = True) -> dict[str, dict[str, float | None]]:
    """``models`` rows × ``columns`` conditions (a third-party one past the nine), some gaps."""
    rng = np.random.default_rng(0)
    keys = ([*(["ori"] if clean else []), *NINE, "vignetting", "lens_flare"])[:columns] + (["avg"] if avg else [])
    return {f"model-{m:02d}-{'x' * (m % 9)}": {k: (None if (m + j) % 17 == 0 else float(rng.random())) for j, k in enumerate(keys)}
            for m in range(models)}


def _corr_panels(rows: dict[str, dict[str, Any]]) -> dict[str, dict[str, dict[str, Any]]]:
    return {"(a) Overall": dict(list(rows.items())[:1]), "(b) Few": dict(list(rows.items())[:3]), "(d) Many": rows}


#: name → (function, example input, a one-model input with gaps, a 25-model × 11-column input)
CASES: dict[str, tuple[Callable[..., Path], Any, Any, Any]] = {
    "bars": (plots.plot_degradation_bars, PAPER,
             {"only": {"ori": 0.5, "haze": None, "low_light": math.nan, "avg": 0.2}}, _table(25, 11)),
    "radar": (plots.plot_radar, PAPER,
              {"only": {"ori": 0.5, "haze": None, "low_light": math.nan, "low_res": np.float32(0.4), "avg": None}},
              _table(25, 11)),
    "drop": (plots.plot_drop, DROPS, {"only": {"haze": None, "low_light": -0.1, "low_res": math.nan}},
             _table(25, 11, clean=False, avg=False)),
    "delta": (plots.plot_delta, DROPS, {"only": {"haze": 0.02, "low_light": None, "avg": math.nan}},
              _table(25, 11, clean=False)),
    "correlation": (plots.plot_correlation, PANELS,
                    {"(a) Overall": {"overall": {"haze": None, "low_light": math.nan, "defocus": 0.3}}},
                    _corr_panels(_table(25, 11, clean=False, avg=False))),
}


@pytest.mark.parametrize("name", list(CASES))
def test_writes_a_readable_deterministic_png(tmp_path: Path, name: str) -> None:
    function, example, _, _ = CASES[name]
    first = function(example, tmp_path / "deep" / "er" / f"{name}.png")  # parent folders are made
    assert first == tmp_path / "deep" / "er" / f"{name}.png"
    _check(first)
    second = function(example, str(tmp_path / f"{name}_again.png"))  # str paths work too
    assert isinstance(second, Path)
    assert first.read_bytes() == second.read_bytes(), f"{name}: output differs between two runs"


@pytest.mark.parametrize("name", list(CASES))
def test_single_model_with_gaps(tmp_path: Path, name: str) -> None:
    function, _, single, _ = CASES[name]
    _check(function(single, tmp_path / f"{name}.png"))


@pytest.mark.parametrize("name", list(CASES))
def test_many_models_and_columns(tmp_path: Path, name: str) -> None:
    function, _, _, many = CASES[name]
    _check(function(many, tmp_path / f"{name}.png"))


@pytest.mark.parametrize("name", list(CASES))
def test_all_missing_values_do_not_crash(tmp_path: Path, name: str) -> None:
    function = CASES[name][0]
    row = {"ori": None, "haze": math.nan, "avg": None} if name in ("bars", "radar") else {"haze": None, "low_res": math.nan}
    data = {"(a) Overall": {"overall": row}} if name == "correlation" else {"m1": row, "m2": dict(row)}
    _check(function(data, tmp_path / f"{name}.png"))


@pytest.mark.parametrize("name", list(CASES))
def test_empty_input_is_a_clear_error(tmp_path: Path, name: str) -> None:
    function = CASES[name][0]
    with pytest.raises(ValueError, match="nothing to plot"):
        function({}, tmp_path / "x.png")
    empty_row = {"(a) Overall": {}} if name == "correlation" else {"m": {}}
    with pytest.raises(ValueError, match="nothing to plot"):
        function(empty_row, tmp_path / "y.png")
    assert not (tmp_path / "x.png").exists() and not (tmp_path / "y.png").exists()


def test_radar_with_only_avg_is_an_error(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="nothing to plot"):
        plots.plot_radar({"m": {"avg": 0.5}}, tmp_path / "r.png")


def test_column_order_clean_first_then_first_model_then_avg() -> None:
    data = {"a": {"avg": 0.1, "haze": 0.2, "ori": 0.3, "defocus": 0.4}, "b": {"vignetting": 0.5, "haze": 0.1}}
    assert plots._columns(data, "t") == ["ori", "haze", "defocus", "vignetting", "avg"]


def test_labels() -> None:
    assert plots.DEGRADATION_LABELS["ori"] == "Clean"
    expected = ["Defocus", "Distortion", "Haze", "JPEG-com.", "Low-light", "Low-res.", "Motion-blur", "Over-exp.",
                "Water-droplets"]
    assert [plots.degradation_label(d) for d in NINE] == expected
    assert degradation_label("avg") == "Avg."
    assert degradation_label("haze+low_res") == "Haze+Low-res."
    assert degradation_label("lens_flare") == "Lens Flare"
