"""Images are never squeezed: every entry point that takes an image size (``spacedg render``,
``spacedg export``, ``SpaceDGDataset``, the gallery's pipeline, the QA preview and judge renders)
asked for 320×240 renders a 16:9 capture at 320×180 and a 4:3 one at 320×240, and a 3D point
lands on the same place of the picture as in the view's own-size render."""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

import spacedg
from spacedg.cli import main
from spacedg.data.dataset import SpaceDGDataset
from spacedg.data.gallery import gallery_sheet
from spacedg.data.pipeline import PipelineOptions, degrade_variants
from spacedg.errors import InvalidDataError
from spacedg.qa.index import QABuildConfig
from spacedg.qa.preview import render_thumbnail
from spacedg.qa.views import render_clean_view
from spacedg.scene.io import load_scene
from spacedg.scene.model import Scene
from spacedg.scene.synthetic import CaptureConfig

BOX = (320, 240)
#: capture size -> the size a 320x240 request renders at
CAPTURES = {"wide": ((192, 108), (320, 180)), "four_three": ((160, 120), (320, 240))}


@pytest.fixture(scope="module")
def rooms(tmp_path_factory) -> dict[str, Path]:
    """One small room captured 16:9 (192×108) and one 4:3 (160×120), as native scene folders."""
    root = tmp_path_factory.mktemp("aspect")
    out = {}
    for name, ((w, h), _) in CAPTURES.items():
        room = spacedg.generate_room(3, spacedg.RoomConfig(gaussians=10_000, capture=CaptureConfig(w, h, 6, 6)), scene_id=f"room-{name}")
        spacedg.save_scene(room, root / name)
        out[name] = root / name
    return out


def _aspect_kept(shape: tuple[int, ...], view: tuple[int, int]) -> bool:
    """``shape`` (H, W, ...) has the view's aspect ratio within one pixel."""
    return abs(shape[1] * view[1] / view[0] - shape[0]) <= 1.0


@pytest.mark.parametrize("name", CAPTURES)
def test_render_command_fits_the_size(rooms, name, tmp_path, capsys):
    view_size, expected = CAPTURES[name]
    out = tmp_path / "view.png"
    assert main(["render", str(rooms[name]), "--view", "frame_0001", "--image-size", "320x240", "--backend", "cpu", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    image = cv2.imread(str(out), cv2.IMREAD_UNCHANGED)
    assert image.shape[:2] == expected[::-1] and _aspect_kept(image.shape, view_size)
    assert f"{expected[0]}x{expected[1]}" in text
    assert ("the largest size of its aspect ratio within 320x240" in text) == (expected != BOX)


def test_fitted_render_is_the_full_view_scaled(rooms):
    """Object box corners project to the same place of the picture at both sizes (one scale on both
    axes), and the fitted render shrunk to the view's own size is the own-size render."""
    scene = load_scene(rooms["wide"])
    full = render_clean_view(scene, "frame_0001", None, "cpu")
    small = render_clean_view(scene, "frame_0001", BOX, "cpu")
    assert small.shape == (180, 320, 3) and full.shape == (108, 192, 3)
    shrunk = cv2.resize(small, (192, 108), interpolation=cv2.INTER_AREA).astype(float)
    assert np.median(np.abs(shrunk - full)) < 8  # the same picture, only finer
    cam = scene.camera("frame_0001")
    points = np.concatenate([inst.box.corners() for inst in scene.instances])
    uv_full, _, ok = cam.project(points)
    uv_fit, _, ok_fit = cam.fitted(*BOX).project(points)
    assert ok.any() and np.array_equal(ok, ok_fit)
    np.testing.assert_allclose(uv_fit[ok], uv_full[ok] * (320 / 192), atol=1e-6)  # one scale: 320/192 = 180/108


@pytest.mark.parametrize("name", CAPTURES)
def test_pipeline_gallery_preview_fit(rooms, name):
    view_size, expected = CAPTURES[name]
    scene = load_scene(rooms[name])
    options = PipelineOptions(image_size=BOX, backend="cpu")
    (result,) = degrade_variants(scene, ["frame_0001", "frame_0002"], ["clean"], 0, options)
    assert result.images.shape[1:3] == expected[::-1]
    sheet = gallery_sheet(scene, "frame_0001", ["haze"], thumb_width=160, options=options)
    assert sheet.ndim == 3 and sheet.shape[1] > 160
    image, cam = render_thumbnail(scene, "frame_0001", 96, "cpu")
    assert image.shape[:2] == (cam.height, cam.width) and _aspect_kept(image.shape, view_size)


def test_views_of_different_aspects_in_one_sample_are_an_error(rooms):
    scene = load_scene(rooms["wide"])
    views = dict(scene.views)
    views["frame_0002"] = views["frame_0002"].resized(160, 120)  # another camera, 4:3
    mixed = Scene(scene.id, scene.gaussians, views, scene.instances, scene.up)
    with pytest.raises(InvalidDataError, match="share an aspect ratio"):
        degrade_variants(mixed, ["frame_0001", "frame_0002"], ["clean"], 0, PipelineOptions(image_size=BOX, backend="cpu"))


@pytest.fixture(scope="module")
def indexed(rooms, tmp_path_factory) -> dict[str, SpaceDGDataset]:
    config = QABuildConfig(seed=0, per_sub_type=1, families=("object_counting", "camera_rotation"))
    return {
        name: SpaceDGDataset("bench", ["haze"], scenes=[folder], image_size=BOX, qa_config=config, split_fractions=(0.0, 1.0),
                             backend="cpu", max_questions=2)
        for name, folder in rooms.items()
    }


@pytest.mark.parametrize("name", CAPTURES)
def test_dataset_items_keep_the_aspect(indexed, name):
    view_size, expected = CAPTURES[name]
    dataset = indexed[name]
    assert len(dataset) > 0
    for index in range(min(len(dataset), 4)):
        images = dataset[index]["images"]  # (views, 3, H, W)
        assert tuple(images.shape[-2:]) == expected[::-1] and _aspect_kept(tuple(images.shape[-2:]), view_size)


@pytest.mark.parametrize("name", CAPTURES)
def test_export_command_keeps_the_aspect(rooms, indexed, name, tmp_path):
    view_size, expected = CAPTURES[name]
    out = tmp_path / "bench"
    assert main(["export", "--split", "bench", "--all-bench", "--scenes", str(rooms[name]), "--out", str(out), "--image-size", "320x240",
                 "--degradations", "haze", "--families", "object_counting", "--per-sub-type", "1", "--max-questions", "1",
                 "--backend", "cpu", "--no-progress"]) == 0
    pngs = sorted((out / "images").glob("*.png"))
    assert pngs
    for png in pngs:
        image = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
        assert image.shape[:2] == expected[::-1] and _aspect_kept(image.shape, view_size)
    summary = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else {}
    assert summary.get("image_size", list(BOX)) == list(BOX)


def test_imported_wide_capture_renders_unsqueezed(tmp_path, capsys):
    """A 16:9 capture in its published layout (INRIA output folder + COLMAP text model), imported
    with ``scenes import``, renders at 320×180 when asked for 320x240, as its own-size view scaled."""
    from tests.scene import capture_layouts as cl

    room = spacedg.generate_room(5, spacedg.RoomConfig(gaussians=12_000, capture=CaptureConfig(192, 108, 4, 4), world_frame="z_up"))
    out = cl.write_inria_output(tmp_path / "capture", room)
    scene_dir = tmp_path / "scenes" / "wide"
    assert main(["scenes", "import", str(out), "--out", str(scene_dir), "--name", "wide", "--metres-per-unit", "1"]) == 0
    view = next(iter(load_scene(scene_dir).views))
    png = tmp_path / "view.png"
    assert main(["render", str(scene_dir), "--view", view, "--image-size", "320x240", "--backend", "cpu", "--out", str(png)]) == 0
    assert "rendered at 320x180" in capsys.readouterr().out
    image = cv2.imread(str(png), cv2.IMREAD_UNCHANGED)
    assert image.shape == (180, 320, 3)
    own = render_clean_view(load_scene(scene_dir), view, None, "cpu")
    shrunk = cv2.resize(image[:, :, ::-1], (192, 108), interpolation=cv2.INTER_AREA).astype(float)
    assert np.median(np.abs(shrunk - own)) < 8
