"""The house's rules, checked in the test command: layers (import-linter contracts in
pyproject.toml) and a light front door."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]


def test_import_contracts_hold() -> None:
    """`lint-imports`: lower layers never import higher ones (lazy imports count too), render
    imports nothing above the base, plugin kinds are independent, question plugins never reach the
    renderer, and sibling modules form no import cycle."""
    lint = Path(sys.executable).with_name("lint-imports")
    if not lint.is_file():
        pytest.fail("lint-imports is missing: install the test extras (pip install -e '.[test]')")
    proc = subprocess.run([str(lint), "--no-cache"], cwd=REPO_ROOT, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stdout[-4000:] + proc.stderr[-2000:]
    assert "0 broken" in proc.stdout and "5 kept" in proc.stdout


def test_front_door_is_light() -> None:
    """`import spacedg` loads neither torch, transformers, numba, OpenCV nor pycolmap; the
    dataset (torch) loads on first access of `spacedg.SpaceDGDataset`."""
    code = (
        "import sys, spacedg\n"
        "heavy = [m for m in ('torch', 'transformers', 'numba', 'cv2', 'pycolmap') if m in sys.modules]\n"
        "print(','.join(heavy) or 'none')\n"
        "spacedg.SpaceDGDataset\n"
        "print('torch' in sys.modules)\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], cwd=REPO_ROOT, capture_output=True, text=True, check=True)
    assert proc.stdout.split() == ["none", "True"]


def test_unknown_front_door_name_is_an_attribute_error() -> None:
    import spacedg

    with pytest.raises(AttributeError, match="no attribute 'Nope'"):
        spacedg.Nope  # noqa: B018
