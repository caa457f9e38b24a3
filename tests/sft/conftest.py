"""Fixtures shared by the SFT tests."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.conftest import private_copies


@pytest.fixture(scope="module")
def rooms(qa_room_dirs, tmp_path_factory) -> Path:
    """A folder of private copies of the four session rooms, one per test module (its question
    indexes and training runs do not touch the originals)."""
    root = tmp_path_factory.mktemp("sft_rooms")
    private_copies(qa_room_dirs, root)
    return root
