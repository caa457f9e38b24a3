"""The real .splat files beside the checkout (../shared/data/splats) all load sensibly."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from spacedg.scene.io import read_splat

SPLATS = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "splats"
FILES = sorted(SPLATS.glob("*/*.splat")) if SPLATS.is_dir() else []


def expected_count(path: Path) -> int | None:
    """The count meta.json gives for this very file (top level or one of its LODs), if any."""
    meta_path = path.parent / "meta.json"
    if not meta_path.is_file():
        return None
    meta = json.loads(meta_path.read_text(encoding="utf-8"))
    entries = [meta, *meta.get("lods", [])]
    for entry in entries:
        if entry.get("file") == path.name and isinstance(entry.get("splats"), int):
            return int(entry["splats"])
    return None


def test_shared_folder_present_or_skip() -> None:
    if not FILES:
        pytest.skip(f"shared splat data not found at {SPLATS}")
    assert any(p.name == "plant.splat" for p in FILES)


@pytest.mark.parametrize("path", FILES, ids=[p.name for p in FILES])
def test_shared_splat_loads(path: Path) -> None:
    g = read_splat(path)
    want = expected_count(path)
    assert want is not None, f"{path.parent / 'meta.json'} names no count for {path.name}"
    assert len(g) == want
    lo, hi = g.bounds()
    assert np.isfinite(lo).all() and np.isfinite(hi).all() and (hi > lo).all()
    assert float(np.abs(np.concatenate([lo, hi])).max()) < 100.0
    assert g.opacities.min() >= 0.0 and g.opacities.max() <= 1.0
    assert (g.scales > 0).all()
    np.testing.assert_allclose(np.linalg.norm(g.quats, axis=1), 1.0, atol=1e-6)
    colours = g.base_colors()
    assert colours.min() >= -1e-6 and colours.max() <= 1.0 + 1e-6
