"""Native scene folder (scene.json + gaussians.ply) and scene_from_files."""

from __future__ import annotations

import json
import math
import os
import pickle
from pathlib import Path

import numpy as np
import pytest
from tests.helpers_io import assert_gaussians_identical, random_gaussians

from spacedg.scene.box import OrientedBox
from spacedg.scene.io import (
    FileValueError,
    load_scene,
    quantize_for_ply,
    save_scene,
    scene_from_files,
    write_instances,
    write_ply,
    write_splat,
)
from spacedg.scene.io import native as native_io
from spacedg.scene.model import Instance, InstanceVisibility, Scene
from spacedg.errors import FileFormatError, InvalidDataError, ParameterError
from spacedg.render.camera import Camera, FisheyeLens, look_at
from spacedg.render.gaussians import Gaussians


def make_scene(gaussians_degree: int = 1, quantize: bool = True) -> Scene:
    g = random_gaussians(300, gaussians_degree, seed=4, instance_ids=True)
    g = g.with_instance_ids(np.where(np.arange(300) % 3 == 0, -1, np.arange(300) % 2))
    if quantize:
        g = quantize_for_ply(g)
    up = np.array([0.0, 0.0, 1.0])
    views = {
        "front": Camera(500.0, 510.0, 320.5, 240.25, 640, 480, look_at([3.0, 0.1, 1.5], [0, 0, 0.5], up)),
        "fish/eye": Camera(300.0, 300.0, 320.0, 240.0, 640, 480, look_at([-2.0, 2.0, 1.0], [0, 0, 0.5], up), FisheyeLens(0.01, 0.0, 0.0, 0.0, 1.4)),
    }
    instances = [
        Instance(0, "chair", "a wooden chair", OrientedBox([0.1, 0.2, 0.4], [0.5, 0.5, 0.9]), ("front",), {"front": InstanceVisibility(100, 0.5)}),
        Instance(1, "lamp", "", OrientedBox([1.0, -1.0, 0.8], [0.3, 0.3, 1.6]), (), {}, {"colour": "white"}),
    ]
    return Scene("room-1", g, views, instances, up=(0.0, 0.0, 1.0), vocabulary=["chair", "lamp", "sofa"], metadata={"seed": 7, "note": "ünïcode"})


def assert_scenes_equal(a: Scene, b: Scene) -> None:
    assert a.id == b.id and list(a.views) == list(b.views)
    for name in a.views:
        assert a.views[name].to_dict() == b.views[name].to_dict()
    assert [i.to_dict() for i in a.instances] == [i.to_dict() for i in b.instances]
    np.testing.assert_array_equal(a.up, b.up)
    assert a.vocabulary == b.vocabulary and a.metadata == b.metadata


def test_round_trip_exact(tmp_path: Path) -> None:
    scene = make_scene()
    json_path = save_scene(scene, tmp_path / "scene")
    assert json_path == tmp_path / "scene" / "scene.json"
    assert sorted(p.name for p in (tmp_path / "scene").iterdir()) == ["gaussians.ply", "scene.json"]
    back = load_scene(tmp_path / "scene")
    assert not back.gaussians_loaded
    assert_scenes_equal(scene, back)
    assert_gaussians_identical(scene.gaussians, back.gaussians)
    record = json.loads(json_path.read_text(encoding="utf-8"))
    assert record["format"] == "spacedg-scene" and record["version"] == 1 and record["units"] == "m"
    assert record["gaussians"]["bytes"] == (tmp_path / "scene" / "gaussians.ply").stat().st_size
    assert load_scene(json_path).id == "room-1"  # the scene.json path works too


def test_float64_round_trip_of_unquantized_gaussians(tmp_path: Path) -> None:
    scene = make_scene(quantize=False)
    save_scene(scene, tmp_path, precision="float64")
    assert_gaussians_identical(scene.gaussians, load_scene(tmp_path).gaussians)


def test_pickles_without_gaussians_and_reloads(tmp_path: Path) -> None:
    save_scene(make_scene(), tmp_path)
    scene = load_scene(tmp_path)
    _ = scene.gaussians
    blob = pickle.dumps(scene)
    assert len(blob) < 20_000  # the 300 Gaussians (~22 kB with SH) are not inside
    clone = pickle.loads(blob)
    assert not clone.gaussians_loaded
    assert_gaussians_identical(clone.gaussians, scene.gaussians)


def test_crash_between_renames_is_detected(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    save_scene(make_scene(), tmp_path)
    old = load_scene(tmp_path)
    real_replace = os.replace
    calls: list[str] = []

    def crash_after_ply(src: os.PathLike[str] | str, dst: os.PathLike[str] | str) -> None:
        calls.append(Path(dst).name)
        if Path(dst).name == "scene.json":
            raise OSError("power cut")
        real_replace(src, dst)

    monkeypatch.setattr(native_io.os, "replace", crash_after_ply)
    new_g = quantize_for_ply(random_gaussians(123, 0, seed=99))
    with pytest.raises(OSError, match="power cut"):
        save_scene(Scene("room-1", new_g, old.views, (), up=(0, 0, 1)), tmp_path)
    assert [c for c in calls if not c.startswith(".")] == ["gaussians.ply", "scene.json"]  # ply first, json last
    assert sorted(p.name for p in tmp_path.iterdir()) == ["gaussians.ply", "scene.json"]  # temporaries removed
    with pytest.raises(FileFormatError, match="half-written"):
        load_scene(tmp_path)  # size differs from what scene.json records


def test_crash_before_any_rename_keeps_old_scene(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    scene = make_scene()
    save_scene(scene, tmp_path)

    def crash(*args: object) -> None:
        raise OSError("disk full")

    monkeypatch.setattr(native_io.os, "replace", crash)
    with pytest.raises(OSError):
        save_scene(Scene("other", random_gaussians(10), {}, (), up=(0, 0, 1)), tmp_path)
    monkeypatch.undo()
    back = load_scene(tmp_path)
    assert back.id == "room-1"
    assert_gaussians_identical(scene.gaussians, back.gaussians)


def test_tampered_ply_detected_at_gaussian_load(tmp_path: Path) -> None:
    save_scene(make_scene(), tmp_path)
    ply = tmp_path / "gaussians.ply"
    data = bytearray(ply.read_bytes())
    data[-10] ^= 0xFF  # same size, different content
    ply.write_bytes(bytes(data))
    scene = load_scene(tmp_path)
    with pytest.raises(FileFormatError, match="SHA-256.*half-written .*or the PLY was edited"):
        _ = scene.gaussians


def test_missing_ply_and_bad_records(tmp_path: Path) -> None:
    save_scene(make_scene(), tmp_path)
    json_path = tmp_path / "scene.json"
    record = json.loads(json_path.read_text(encoding="utf-8"))

    def variant(**changes: object) -> Path:
        folder = tmp_path / f"v{len(list(tmp_path.iterdir()))}"
        folder.mkdir()
        (folder / "gaussians.ply").write_bytes((tmp_path / "gaussians.ply").read_bytes())
        (folder / "scene.json").write_text(json.dumps({**record, **changes}), encoding="utf-8")
        return folder

    with pytest.raises(FileFormatError, match=r"version 2 is newer.*upgrade spacedg"):
        load_scene(variant(version=2))
    with pytest.raises(FileFormatError, match="not a spacedg scene"):
        load_scene(variant(format="something-else"))
    with pytest.raises(FileFormatError, match="metres"):
        load_scene(variant(units="ft"))
    with pytest.raises(FileFormatError, match="plain file name"):
        load_scene(variant(gaussians={**record["gaussians"], "file": "../gaussians.ply"}))
    with pytest.raises(FileFormatError, match="missing 'id'"):
        load_scene(_without(variant(), "id"))
    with pytest.raises(FileValueError, match="view 'front'.*fx"):
        load_scene(variant(views={"front": {**record["views"]["front"], "fx": -1.0}}))
    with pytest.raises(FileValueError, match=r"instances\[0\]"):
        load_scene(variant(instances=[{"id": 0, "label": "x"}]))
    with pytest.raises(FileValueError, match="refers to view"):
        load_scene(variant(instances=[{**record["instances"][0], "images": ["nowhere"]}]))
    (tmp_path / "gaussians.ply").unlink()
    with pytest.raises(FileFormatError, match="missing; the scene folder is incomplete"):
        load_scene(tmp_path)
    with pytest.raises(FileFormatError, match="scene not found"):
        load_scene(tmp_path / "nothing")


def _without(folder: Path, key: str) -> Path:
    path = folder / "scene.json"
    record = json.loads(path.read_text(encoding="utf-8"))
    del record[key]
    path.write_text(json.dumps(record), encoding="utf-8")
    return folder


# ------------------------------------------------------------------ scene_from_files
def _transforms(path: Path, centres: list[list[float]]) -> Path:
    frames = []
    for i, c in enumerate(centres):
        pose = np.eye(4)  # OpenGL: camera y axis = world +y; so image up = world +y
        pose[:3, 3] = c
        frames.append({"file_path": f"img_{i}.png", "transform_matrix": pose.tolist()})
    data = {"fl_x": 300.0, "fl_y": 300.0, "cx": 160.0, "cy": 120.0, "w": 320, "h": 240, "camera_model": "PINHOLE", "frames": frames}
    path.write_text(json.dumps(data))
    return path


def test_scene_from_files_scales_once_and_estimates_up(tmp_path: Path) -> None:
    g = quantize_for_ply(random_gaussians(40, 0, seed=1))
    write_ply(tmp_path / "g.ply", g)
    views = _transforms(tmp_path / "transforms.json", [[0.0, 0.0, 5.0], [1.0, 0.5, 4.0]])
    box = OrientedBox([1.0, 1.0, 0.0], [0.5, 0.2, 0.3])
    write_instances(tmp_path / "inst.json", [Instance(0, "cup", "", box, ("img_1.png",))])
    scene = scene_from_files("s1", tmp_path / "g.ply", views, tmp_path / "inst.json", metres_per_unit=0.5, frame_check="warn")
    np.testing.assert_allclose(scene.up, [0.0, 1.0, 0.0], atol=1e-12)
    assert scene.metadata["up_source"].startswith("estimated") and scene.metadata["scale_to_metres"] == 0.5
    np.testing.assert_allclose(scene.views["img_1.png"].center, [0.5, 0.25, 2.0])
    np.testing.assert_array_equal(scene.views["img_1.png"].rotation, np.diag([1.0, -1.0, -1.0]))
    np.testing.assert_allclose(scene.instances[0].box.center, [0.5, 0.5, 0.0])
    np.testing.assert_allclose(scene.instances[0].box.extents, [0.25, 0.1, 0.15])
    assert scene.gaussians_loaded  # with boxes the Gaussians are read at once: the box checks need their centres
    np.testing.assert_allclose(scene.gaussians.means, g.means * 0.5, rtol=1e-6)
    np.testing.assert_allclose(scene.gaussians.scales, g.scales * 0.5, rtol=1e-6)
    clone = pickle.loads(pickle.dumps(scene))
    np.testing.assert_array_equal(clone.gaussians.means, scene.gaussians.means)
    # the assembled scene saves and loads natively
    save_scene(scene, tmp_path / "native")
    assert_scenes_equal(scene, load_scene(tmp_path / "native"))


def test_scene_from_files_splat_and_given_up(tmp_path: Path) -> None:
    write_splat(tmp_path / "g.splat", _grey_gaussians())
    (tmp_path / "ns").mkdir()
    _transforms(tmp_path / "ns" / "transforms.json", [[0.0, 0.0, 3.0]])
    scene = scene_from_files("s2", tmp_path / "g.splat", tmp_path / "ns", up=(0.0, 1.0, 0.0))  # a nerfstudio folder
    assert scene.metadata["up_source"] == "given" and len(scene.gaussians) == 10 and scene.instances == ()
    np.testing.assert_array_equal(scene.up, [0.0, 1.0, 0.0])


def _grey_gaussians() -> Gaussians:
    g = random_gaussians(10, 0, seed=2)
    return Gaussians.from_colors(g.means, g.quats, g.scales, g.opacities, np.full((10, 3), 0.5))


def test_scene_from_files_errors(tmp_path: Path) -> None:
    views = _transforms(tmp_path / "t.json", [[0.0, 0.0, 3.0]])
    write_ply(tmp_path / "g.ply", random_gaussians(5))
    with pytest.raises(ParameterError, match="metres-per-unit"):
        scene_from_files("s", tmp_path / "g.ply", views, metres_per_unit=-1.0)
    with pytest.raises(ParameterError, match="metres-per-unit"):
        scene_from_files("s", tmp_path / "g.ply", views, metres_per_unit=math.nan)
    with pytest.raises(FileFormatError, match="not found"):
        scene_from_files("s", tmp_path / "missing.ply", views)
    (tmp_path / "g.obj").write_text("v 0 0 0")
    with pytest.raises(FileFormatError, match="unknown Gaussians file type"):
        scene_from_files("s", tmp_path / "g.obj", views)
    with pytest.raises(FileFormatError, match="views"):
        scene_from_files("s", tmp_path / "g.ply", tmp_path / "cams.txt")
    down = {"a": Camera(100, 100, 50, 50, 100, 100, np.diag([1.0, 1.0, 1.0, 1.0])),
            "b": Camera(100, 100, 50, 50, 100, 100, np.diag([1.0, -1.0, -1.0, 1.0]))}
    with pytest.raises(InvalidDataError, match="cannot decide up"):
        scene_from_files("s", tmp_path / "g.ply", down)


def test_written_files_get_the_usual_permissions(tmp_path) -> None:
    """Atomic writes go through mkstemp (0600); the result must be readable like a plain open()."""
    import os

    from spacedg.files import atomic_write_bytes

    umask = os.umask(0o022)
    try:
        atomic_write_bytes(tmp_path / "a.bin", b"x")
    finally:
        os.umask(umask)
    assert (tmp_path / "a.bin").stat().st_mode & 0o777 == 0o644


def test_a_capture_saved_without_capture_focal_loads_as_captured(tmp_path: Path) -> None:
    """Scenes imported before ``Camera.capture_focal`` existed: their views are the capture's own
    (metadata ``source.cameras``/``views`` a path), so they load marked; built-in or in-memory views do not."""
    imported = make_scene()
    imported.metadata["source"] = {"cameras": "/data/capture/sparse/0", "gaussians": "/data/capture/point_cloud.ply"}
    save_scene(imported, tmp_path / "imported")
    assert "capture_focal" not in json.loads((tmp_path / "imported" / "scene.json").read_text())["views"]["front"]
    back = load_scene(tmp_path / "imported")
    assert all(v.capture_focal == (v.fx, v.fy) for v in back.views.values())
    save_scene(make_scene(), tmp_path / "plain")
    assert all(v.capture_focal is None for v in load_scene(tmp_path / "plain").views.values())
