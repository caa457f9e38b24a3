"""Every JSON reader of a capture or scene reports broken JSON by file, line and column, and a
missing file by its path: one :class:`~spacedg.errors.FileFormatError`, never a bare
``json.JSONDecodeError`` or ``FileNotFoundError``."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from spacedg.errors import FileFormatError
from spacedg.scene.io import load_scene
from spacedg.scene.io.embodiedscan import read_embodiedscan_boxes
from spacedg.scene.io.inria import read_inria_cameras
from spacedg.scene.io.instances import read_instances
from spacedg.scene.io.nerfstudio import read_applied_transform, read_dataparser_transforms, read_transforms
from spacedg.scene.io.scannetpp import read_segments_anno


def _scene_folder(path: Path) -> Path:
    """``load_scene`` reads ``scene.json`` inside a folder: the broken file becomes that file."""
    folder = path.parent / "scene"
    folder.mkdir(exist_ok=True)
    if path.exists():
        path.replace(folder / "scene.json")
    return folder


READERS: dict[str, tuple[Callable[[Path], Any], Callable[[Path], Path]]] = {
    "transforms.json": (read_transforms, lambda p: p),
    "nerfstudio applied transform": (read_applied_transform, lambda p: p),
    "dataparser_transforms.json": (read_dataparser_transforms, lambda p: p),
    "cameras.json": (read_inria_cameras, lambda p: p),
    "instance JSON": (read_instances, lambda p: p),
    "segments_anno.json": (read_segments_anno, lambda p: p),
    "EmbodiedScan JSON": (read_embodiedscan_boxes, lambda p: p),
    "scene.json": (load_scene, _scene_folder),
}

#: The third line's ``[,]`` is the error: line 3, column 14 (1-based).
BROKEN = '{\n  "fl_x": 400,\n  "frames": [,]\n}'


@pytest.mark.parametrize("name", list(READERS))
def test_broken_json_names_file_line_and_column(tmp_path: Path, name: str) -> None:
    reader, target = READERS[name]
    path = tmp_path / "broken.json"
    path.write_text(BROKEN)
    source = target(path)
    where = source / "scene.json" if source.is_dir() else source
    with pytest.raises(FileFormatError, match="is not valid JSON: .* at line 3, column 14") as info:
        reader(source)
    assert str(info.value).startswith(f"{where}: ")


@pytest.mark.parametrize("name", list(READERS))
def test_missing_file_names_its_path(tmp_path: Path, name: str) -> None:
    reader, target = READERS[name]
    path = tmp_path / "missing.json"
    source = target(path)
    where = source / "scene.json" if source.is_dir() else source
    with pytest.raises(FileFormatError, match="not found; check the path") as info:
        reader(source)
    assert str(info.value).startswith(f"{where}: ")
