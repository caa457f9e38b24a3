"""spacedg's native scene folder: ``scene.json`` + ``gaussians.ply``.

``scene.json`` (UTF-8, :data:`FORMAT` = ``"spacedg-scene"``, :data:`VERSION` = 1)::

    {
      "format": "spacedg-scene", "version": 1, "id": "...", "units": "m",
      "up": [x, y, z], "vocabulary": [...], "metadata": {...},
      "gaussians": {"file": "gaussians.ply", "bytes": 123, "sha256": "...", "count": N, "sh_degree": 0},
      "views": {"name": Camera.to_dict(), ...},
      "instances": [Instance.to_dict(), ...]
    }

``units`` is always ``"m"``. An imported scene's ``metadata`` records where it came from
(``source``, ``scale_to_metres``, ``up_source``) and how its scale was decided (``units``:
:meth:`spacedg.scene.units.UnitDecision.to_dict`); scenes made by spacedg carry none of these.

``gaussians.ply`` is an INRIA 3DGS PLY (:func:`~spacedg.scene.io.ply.write_ply`) with an
``instance_id`` property when the Gaussians carry instance ids.

Crash safety: :func:`save_scene` writes both files under temporary names first, then
renames the PLY into place and ``scene.json`` last. ``scene.json`` is the commit record: it
names the PLY's byte size and SHA-256, so a folder left half-written (a crash between the
two renames) or a PLY edited by hand is detected: the size at :func:`load_scene`, the
checksum when the Gaussians are first loaded.
"""

from __future__ import annotations

import functools
import os
from pathlib import Path
from typing import Any, Literal

from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.files import (
    FileValueError,
    PathLike,
    as_path,
    dump_json,
    read_json,
    sha256_of,
    write_temp_sibling,
)
from spacedg.render.camera import Camera
from spacedg.render.gaussians import Gaussians
from spacedg.scene.io.ply import read_ply, write_ply
from spacedg.scene.io.annotation_limits import check_box_size
from spacedg.scene.model import Instance, Scene

FORMAT = "spacedg-scene"
#: Newest scene.json version this code reads and the one it writes.
VERSION = 1
SCENE_FILE = "scene.json"
GAUSSIANS_FILE = "gaussians.ply"


def _scene_record(scene: Scene, gaussians: Gaussians, ply_bytes: int, ply_sha: str) -> dict[str, Any]:
    return {
        "format": FORMAT,
        "version": VERSION,
        "id": scene.id,
        "units": "m",
        "up": scene.up.tolist(),
        "vocabulary": list(scene.vocabulary),
        "metadata": scene.metadata,
        "gaussians": {
            "file": GAUSSIANS_FILE,
            "bytes": ply_bytes,
            "sha256": ply_sha,
            "count": len(gaussians),
            "sh_degree": gaussians.sh_degree,
        },
        "views": {name: cam.to_dict() for name, cam in scene.views.items()},
        "instances": [inst.to_dict() for inst in scene.instances],
    }


def save_scene(scene: Scene, folder: PathLike, *, precision: Literal["float32", "float64"] = "float32") -> Path:
    """Write ``scene`` to ``folder`` (created if needed) as ``scene.json`` + ``gaussians.ply``.

    Both files are written under temporary names, then the PLY is renamed into place and
    ``scene.json`` last (see the module docstring). Views, instances, up, vocabulary and
    metadata round-trip exactly; the Gaussians follow :func:`write_ply`'s exactness contract
    (pass ``precision="float64"``, or save Gaussians that went through
    :func:`~spacedg.scene.io.ply.quantize_for_ply`, for a bit-exact round trip).

    Returns:
        The path of the written ``scene.json``.
    """
    if not isinstance(scene, Scene):
        raise InvalidDataError(f"save_scene: expected a Scene, got {type(scene).__name__}")
    out = as_path(folder, "scene folder")
    out.mkdir(parents=True, exist_ok=True)
    gaussians = scene.gaussians
    ply_tmp = write_temp_sibling(out / GAUSSIANS_FILE, lambda tmp: write_ply(tmp, gaussians, precision=precision))
    json_tmp: Path | None = None
    try:
        record = _scene_record(scene, gaussians, ply_tmp.stat().st_size, sha256_of(ply_tmp))
        text = dump_json(record)
        json_tmp = write_temp_sibling(out / SCENE_FILE, lambda tmp: tmp.write_text(text, encoding="utf-8"))
        os.replace(ply_tmp, out / GAUSSIANS_FILE)
        os.replace(json_tmp, out / SCENE_FILE)
    except BaseException:
        ply_tmp.unlink(missing_ok=True)
        if json_tmp is not None:
            json_tmp.unlink(missing_ok=True)
        raise
    return out / SCENE_FILE


def _half_written(ply: Path, what: str) -> FileFormatError:
    return FileFormatError(
        f"{ply}: {what} does not match what {SCENE_FILE} records; the scene folder is half-written "
        "(a save was interrupted) or the PLY was edited. Save the scene again (or restore both files)"
    )


def load_verified_ply(path: str, size: int, sha256: str) -> Gaussians:
    """Read a scene's PLY after checking its byte size and SHA-256 against ``scene.json``.

    Module-level so that ``functools.partial(load_verified_ply, ...)`` pickles.
    """
    ply = Path(path)
    if not ply.is_file():
        raise FileFormatError(f"{ply}: the scene's Gaussians file is missing; the scene folder is incomplete")
    if ply.stat().st_size != size:
        raise _half_written(ply, f"its size ({ply.stat().st_size} bytes, recorded {size})")
    if sha256_of(ply) != sha256:
        raise _half_written(ply, "its SHA-256 checksum")
    return read_ply(ply)


def _scene_json_path(path: Path) -> Path:
    if path.is_dir():
        return path / SCENE_FILE
    if not path.exists():
        raise FileFormatError(f"{path}: scene not found; pass a scene folder or its {SCENE_FILE}")
    return path


def _require(record: dict[str, Any], key: str, kind: type | tuple[type, ...], where: str) -> Any:
    if key not in record:
        raise FileFormatError(f"{where}: missing '{key}'")
    value = record[key]
    if not isinstance(value, kind) or isinstance(value, bool) and kind is not bool:
        names = kind.__name__ if isinstance(kind, type) else " or ".join(k.__name__ for k in kind)
        raise FileFormatError(f"{where}: '{key}' must be {names}, got {type(value).__name__}")
    return value


def _check_header(record: Any, where: str) -> None:
    if not isinstance(record, dict):
        raise FileFormatError(f"{where}: expected a JSON object, got {type(record).__name__}")
    if record.get("format") != FORMAT:
        raise FileFormatError(f"{where}: 'format' is {record.get('format')!r}, not {FORMAT!r}; this is not a spacedg scene file")
    version = _require(record, "version", int, where)
    if version > VERSION:
        raise FileFormatError(
            f"{where}: scene format version {version} is newer than this spacedg reads (≤ {VERSION}); upgrade spacedg"
        )
    if version < 1:
        raise FileFormatError(f"{where}: scene format version {version} is invalid (versions start at 1)")
    if record.get("units", "m") != "m":
        raise FileFormatError(f"{where}: 'units' is {record.get('units')!r}; spacedg scenes are in metres ('m')")


def _gaussians_source(record: dict[str, Any], folder: Path, where: str) -> functools.partial[Gaussians]:
    info = _require(record, "gaussians", dict, where)
    gwhere = f"{where}: 'gaussians'"
    name = _require(info, "file", str, gwhere)
    size = _require(info, "bytes", int, gwhere)
    sha = _require(info, "sha256", str, gwhere)
    if Path(name).name != name or name in ("", ".", ".."):
        raise FileFormatError(f"{gwhere}: 'file' must be a plain file name inside the scene folder, got {name!r}")
    ply = folder / name
    if not ply.is_file():
        raise FileFormatError(f"{ply}: the Gaussians file named in {SCENE_FILE} is missing; the scene folder is incomplete")
    if ply.stat().st_size != size:
        raise _half_written(ply, f"its size ({ply.stat().st_size} bytes, recorded {size})")
    return functools.partial(load_verified_ply, str(ply), size, sha)


def _views(record: dict[str, Any], where: str) -> dict[str, Camera]:
    views = _require(record, "views", dict, where)
    out = {}
    for name, data in views.items():
        if not isinstance(data, dict):
            raise FileFormatError(f"{where}: view {name!r} must be an object, got {type(data).__name__}")
        try:
            out[name] = Camera.from_dict(data)
        except (InvalidDataError, TypeError, ValueError) as err:
            raise FileValueError(f"{where}: view {name!r}: {err}") from err
    return out


def _instances(record: dict[str, Any], where: str) -> list[Instance]:
    items = record.get("instances", [])
    if not isinstance(items, list):
        raise FileFormatError(f"{where}: 'instances' must be a list")
    out = []
    for i, data in enumerate(items):
        if not isinstance(data, dict):
            raise FileFormatError(f"{where}: instances[{i}] must be an object, got {type(data).__name__}")
        try:
            inst = Instance.from_dict(data)
        except (InvalidDataError, TypeError, ValueError, AttributeError) as err:
            raise FileValueError(f"{where}: instances[{i}]: {err}") from err
        out.append(inst)
        check_box_size(f"{where}: instances[{i}] (id {inst.id})", inst.box)
    return out


def _imported_from_capture_files(metadata: dict) -> bool:
    """Whether the scene's views were read from a capture's camera files (``metadata.source.cameras``
    of ``spacedg scenes import``, or ``.views`` of ``scene_from_files``, a path): their cameras are then
    the capture's own, which scenes saved before ``Camera.capture_focal`` existed did not record
    (:meth:`Camera.as_captured` keeps a recorded one)."""
    source = metadata.get("source")
    if not isinstance(source, dict):
        return False
    files = source.get("cameras", source.get("views"))
    return isinstance(files, str) and files not in ("", "<memory>")


def load_scene(path: PathLike) -> Scene:
    """Load a native scene folder (or its ``scene.json``); the Gaussians load lazily.

    The PLY's size is checked now; its SHA-256 when the Gaussians are first accessed (the
    loader is a picklable ``functools.partial``, so the scene pickles without them).

    Raises:
        FileFormatError: missing or malformed ``scene.json``, a newer format version, a
            missing PLY or one whose size/checksum differs from the record.
    """
    json_path = _scene_json_path(as_path(path, "scene folder"))
    where = str(json_path)
    record = read_json(json_path, SCENE_FILE)
    _check_header(record, where)
    scene_id = _require(record, "id", str, where)
    source = _gaussians_source(record, json_path.parent, where)
    views = _views(record, where)
    instances = _instances(record, where)
    up = _require(record, "up", list, where)
    vocabulary = record.get("vocabulary")
    if vocabulary is not None and (not isinstance(vocabulary, list) or not all(isinstance(v, str) for v in vocabulary)):
        raise FileFormatError(f"{where}: 'vocabulary' must be a list of strings")
    metadata = record.get("metadata", {})
    if not isinstance(metadata, dict):
        raise FileFormatError(f"{where}: 'metadata' must be an object")
    if _imported_from_capture_files(metadata):
        views = {name: camera.as_captured() for name, camera in views.items()}
    try:
        return Scene(scene_id, source, views, instances, up, vocabulary, metadata)
    except (InvalidDataError, TypeError, ValueError) as err:
        raise FileValueError(f"{where}: {err}") from err
