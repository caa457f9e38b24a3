"""Fixtures shared by the SFT tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import private_copies


@pytest.fixture(scope="module")
def rooms(indexed_room_dirs, tmp_path_factory) -> Path:
    """A folder of private copies of the four session rooms, one per test module (its training
    runs do not touch the originals), with the default question index every SFT run reads
    (built once per session instead of once per module)."""
    root = tmp_path_factory.mktemp("sft_rooms")
    private_copies(indexed_room_dirs, root, indexes=True)
    return root
