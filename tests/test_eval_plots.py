"""Report plots (spacedg.eval.plots): written, readable, not blank, deterministic, robust to gaps."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from spacedg.eval import plots
from spacedg.eval.labels import degradation_label

NINE = ["defocus", "distortion", "haze", "jpeg_compression", "low_light", "low_res", "motion_blur", "over_exposure", "water_droplets"]
#: two rows of the paper's Table 1 (fractions)
PAPER = {
    "GPT-5.4": dict(zip(["ori", *NINE, "avg"], [0.503, 0.433, 0.499, 0.456, 0.482, 0.425, 0.428, 0.462, 0.499, 0.472, 0.462])),
    "Gemini-3.1-Pro": dict(zip(["ori", *NINE, "avg"], [0.631, 0.518, 0.636, 0.572, 0.604, 0.512, 0.531, 0.56, 0.633, 0.538, 0.567])),
}


def _check(path: Path) -> np.ndarray:
    image = np.asarray(Image.open(path).convert("RGB"))
    assert image.shape[0] > 200 and image.shape[1] > 300
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 20  # not blank
    return image


def _many(models: int, columns: int) -> dict[str, dict[str, float | None]]:
    rng = np.random.default_rng(0)
    keys = ["ori", *NINE, "vignetting"][:columns]
    return {f"model-{m:02d}": {k: (None if (m + j) % 17 == 0 else float(rng.random())) for j, k in enumerate(keys)}
            for m in range(models)}


def test_every_plot_writes_a_deterministic_png(tmp_path: Path) -> None:
    drops = {m: {d: v["ori"] - v[d] for d in NINE} for m, v in PAPER.items()}
    panels = {"(a) Overall": {"all": {d: 0.1 * i for i, d in enumerate(NINE)}},
              "(d) Question type": {f"type_{k}": {d: (k * 0.07 + i * 0.01) % 1 for i, d in enumerate(NINE)} for k in range(11)}}
    calls = {
        "bars": lambda p: plots.plot_degradation_bars(PAPER, p),
        "radar": lambda p: plots.plot_radar(PAPER, p),
        "drop": lambda p: plots.plot_drop(drops, p),
        "delta": lambda p: plots.plot_delta(drops, p),
        "corr": lambda p: plots.plot_correlation(panels, p),
    }
    for name, call in calls.items():
        first, second = call(tmp_path / f"{name}.png"), call(tmp_path / "again" / f"{name}.png")
        _check(first)
        assert first.read_bytes() == second.read_bytes(), name


def test_gaps_single_model_and_many_models(tmp_path: Path) -> None:
    gappy = {"only": {"ori": 0.5, "haze": None, "low_light": math.nan, "avg": 0.2}}
    _check(plots.plot_degradation_bars(gappy, tmp_path / "gap.png"))
    _check(plots.plot_radar(gappy, tmp_path / "gap_radar.png"))
    _check(plots.plot_drop({"only": {"haze": None, "low_light": 0.1}}, tmp_path / "gap_drop.png"))
    many = _many(25, 11)
    _check(plots.plot_degradation_bars(many, tmp_path / "many.png"))
    _check(plots.plot_radar(many, tmp_path / "many_radar.png"))
    _check(plots.plot_correlation({"(d)": many}, tmp_path / "many_corr.png"))


def test_empty_input_is_a_clear_error(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="nothing to plot"):
        plots.plot_degradation_bars({}, tmp_path / "x.png")
    with pytest.raises(ValueError, match="nothing to plot"):
        plots.plot_correlation({"(a)": {}}, tmp_path / "x.png")
    with pytest.raises(ValueError, match="nothing to plot"):
        plots.plot_drop({"m": {}}, tmp_path / "x.png")


def test_labels() -> None:
    assert degradation_label("ori") == "Clean" and degradation_label("jpeg_compression") == "JPEG-com."
    assert degradation_label("haze+low_res") == "Haze+Low-res."
    assert degradation_label("lens_flare") == "Lens Flare"
