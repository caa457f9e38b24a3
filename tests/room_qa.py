"""The question-index calls the shared room fixtures of ``tests/conftest.py`` make, in one place
(the fixtures import them lazily, so collecting the tests imports no question code)."""

from __future__ import annotations

from pathlib import Path

from spacedg.qa.build import generate_records, prepare_scene
from spacedg.qa.index import QABuildConfig
from spacedg.plugins.qa_record import QARecord
from spacedg.scene.model import Scene

#: The records of ``room_records``: every family, 15 per sub type, seed 7 (what
#: ``tests/plugins/questions/test_families.py`` asserts coverage, balance and invariance on, and
#: ``test_recompute.py`` re-derives every answer of).
ROOM_CONFIG = QABuildConfig(seed=7, per_sub_type=15)


def prepare_room(scene: Scene, cache: Path) -> Scene:
    """``scene`` with visibility and covisibility at the default sizes, read from (or computed into) ``cache``."""
    return prepare_scene(scene, cache, QABuildConfig(), progress=False)


def generate(scene: Scene, config: QABuildConfig) -> list[QARecord]:
    """Every family's selected records of a prepared ``scene``."""
    return generate_records(scene, config)
