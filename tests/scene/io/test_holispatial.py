"""Holi-Spatial's released scenes: the layout detected, imported in one command, RLE masks labelling Gaussians."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from spacedg.cli import main
from spacedg.errors import FileFormatError
from spacedg.files import FileValueError
from spacedg.scene.importer import detect_layout, import_scene
from spacedg.scene.io import load_scene
from spacedg.scene.io.holispatial import decode_rle, find_release_boxes, read_mask_encodings, rle_run_lengths
from tests.scene import holi_release as hr


@pytest.fixture(scope="module")
def truth():
    return hr.tiny_scene()


@pytest.fixture(scope="module")
def files(truth):
    """The truth in the files' frame (ScanNet++'s nerfstudio JSON world), as PGSR and the box step wrote it."""
    return hr.released(truth)


@pytest.fixture(scope="module")
def records(files):
    return hr.box_records(files)


# ---------------------------------------------------------------- COCO RLE
def test_rle_round_trips_pycocotools_encodings() -> None:
    rng = np.random.default_rng(4)
    for k in range(60):
        h, w = (int(v) for v in rng.integers(1, 50, 2))
        mask = rng.random((h, w)) < rng.random()
        mask[:] = False if k % 7 == 0 else mask
        mask[:] = True if k % 11 == 0 else mask
        enc = hr.rle(mask)
        (hh, ww), runs = rle_run_lengths(enc)
        assert (hh, ww) == (h, w) and sum(runs) == h * w
        assert runs[0] == (0 if mask[0, 0] else runs[0])  # the first run counts zeros
        np.testing.assert_array_equal(decode_rle(enc), mask)
    # uncompressed counts (a list of runs, column-major, zeros first)
    np.testing.assert_array_equal(decode_rle({"size": [2, 3], "counts": [1, 2, 3]}), [[False, True, False], [True, False, False]])


@pytest.mark.parametrize(("enc", "reason"), [
    ({"size": [120, 160], "counts": "PPYo1"}, "cover 2073600 pixels"),  # a 1920×1080 mask labelled 160×120
    ({"size": [4, 5], "counts": "!!"}, "outside COCO's alphabet"),
    ({"size": [4, 5], "counts": "0"}, "cover 0 pixels"),
    ({"size": [4, 5]}, "'size': \\[height, width\\], 'counts'"),
    ({"size": [0, 5], "counts": ""}, "positive integers"),
    ({"size": [4, 5], "counts": [3, -1, 18]}, "negative"),
    ({"size": [4, 5], "counts": 7}, "compressed string or a list"),
])
def test_malformed_rle_is_refused_with_the_reason(enc, reason) -> None:
    with pytest.raises(ValueError, match=reason):
        rle_run_lengths(enc)


# ---------------------------------------------------------------- the release layout
def test_release_scene_imports_in_one_command_and_masks_label_gaussians(tmp_path: Path, truth, files, records, capsys) -> None:
    folder = hr.write_release(tmp_path / "ScanNetPP", files, records)
    assert detect_layout(folder) == "holi-spatial"
    assert find_release_boxes(folder) == (tmp_path / "ScanNetPP" / "3d_bounding_box_pp" / f"{truth.id}.json").resolve()
    assert main(["scenes", "import", str(folder), "--out", str(tmp_path / "scene"), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert report["layout"] == "holi-spatial" and report["up"] == [0.0, 0.0, 1.0] and report["metres_per_unit"] == 1.0
    assert "z up" in report["up_source"] and any("metres by construction" in n for n in report["notes"])
    assert report["assignment"]["method"] == "masks" and report["frame_check"]["ok"]
    scene = load_scene(tmp_path / "scene")
    # back in ScanNet++'s scan frame: metres, z up, where the truth is
    np.testing.assert_allclose(scene.gaussians.means, truth.gaussians.means, atol=1e-5)
    for inst, ref in zip(scene.instances, truth.instances):
        np.testing.assert_allclose(inst.box.corners(), ref.box.corners(), atol=1e-5)
    assert any("back to its scan frame" in n for n in report["notes"])
    assert [i.label for i in scene.instances] == ["chair", "table", "trash can"]
    assert {i.attributes["best_image"] for i in scene.instances} <= set(scene.views)
    want, got = truth.gaussians.instance_ids, scene.gaussians.instance_ids
    voted = got >= 0
    # every object's visible shell takes its id from the RLE masks; the floor stays unlabelled
    assert (got[voted] == want[voted]).mean() > 0.97
    for inst in truth.instances:
        assert ((got == inst.id) & (want == inst.id)).sum() >= 0.5 * (want == inst.id).sum()
    assert (got[want < 0] >= 0).sum() <= 2
    assert all(row["mask_iou"] > 0.8 for row in report["assignment"]["instances"])


def test_malformed_rle_names_the_file_and_the_instance(tmp_path: Path, truth, files, records, capsys) -> None:
    bad = json.loads(json.dumps(records))
    bad[1]["mask_encodings"][1]["counts"] = bad[1]["mask_encodings"][1]["counts"][:-3]
    folder = hr.write_release(tmp_path / "ScanNetPP", files, bad)
    assert main(["scenes", "import", str(folder), "--out", str(tmp_path / "scene")]) == 2
    err = capsys.readouterr().err
    boxes = tmp_path / "ScanNetPP" / "3d_bounding_box_pp" / f"{truth.id}.json"
    assert str(boxes) in err and "ins_id '1'" in err and "mask_encodings[1]" in err and bad[1]["images"][1] in err
    assert "not a valid COCO RLE" in err and not (tmp_path / "scene").exists()


def test_rle_and_image_counts_must_match(tmp_path: Path, records) -> None:
    bad = json.loads(json.dumps(records))
    bad[2]["mask_encodings"].pop()
    path = tmp_path / "boxes.json"
    path.write_text(json.dumps(bad))
    with pytest.raises(FileValueError, match=r"instance \[2\] \(ins_id '2'\): 3 'mask_encodings' for 4 'images'"):
        read_mask_encodings(path)


def test_mask_of_another_aspect_ratio_is_refused(tmp_path: Path, truth, files, records) -> None:
    bad = json.loads(json.dumps(records))
    for rec in bad:
        rec["mask_encodings"] = [hr.rle(np.zeros((120, 120), bool)) for _ in rec["images"]]
    folder = hr.write_release(tmp_path / "ScanNetPP", files, bad)
    with pytest.raises(FileValueError, match=r"is 120×120 but the view is 160×120"):
        import_scene(folder, None, progress=False)


def test_release_scene_without_its_boxes_says_where_it_looked(tmp_path: Path, truth, files, records) -> None:
    folder = hr.write_release(tmp_path / "ScanNetPP", files, records)
    shutil.rmtree(tmp_path / "ScanNetPP" / "3d_bounding_box_pp")
    assert detect_layout(folder) == "holi-spatial"  # the mesh says so
    with pytest.raises(FileFormatError, match=r"3d_bounding_box_pp/0a5c013435\.json.*--instances"):
        import_scene(folder, None, progress=False)
    kitchen = folder.rename(folder.parent / "kitchen")
    assert detect_layout(kitchen) == "inria"  # someone's own PGSR output with a mesh stays an INRIA folder
    shutil.rmtree(kitchen / "mesh")
    assert detect_layout(kitchen.rename(folder)) == "inria"  # a plain PGSR/INRIA output stays one
