"""Shared fixtures: repository paths, the shared splat data, and small synthetic rooms."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
SHARED_SPLATS = REPO_ROOT.parent / "shared" / "data" / "splats"


@pytest.fixture(scope="session")
def shared_splats() -> Path:
    """The real .splat objects beside the checkout; tests using it skip cleanly without it."""
    if not SHARED_SPLATS.is_dir():
        pytest.skip(f"shared splat data not found at {SHARED_SPLATS}")
    return SHARED_SPLATS


@pytest.fixture(scope="session")
def small_room():
    """A small but complete synthetic room (30k Gaussians), generated once per session."""
    from spacedg.data.synthetic import RoomConfig, generate_room

    return generate_room(7, RoomConfig(gaussians=30_000))


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)
