"""``spacedg scenes import`` → ``qa build`` → ``export --all-bench`` through the real console entry point,
and the commands that must not succeed on empty frames."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest

from spacedg.cli import main
from spacedg.scene.io import load_scene, save_scene
from spacedg.scene.model import Scene
from tests.scene import capture_layouts as cl


@pytest.fixture(scope="module")
def capture(tmp_path_factory) -> tuple[Path, Path, Scene]:
    """An INRIA output folder + its COLMAP model + Holi-Spatial instance JSON and masks."""
    root = tmp_path_factory.mktemp("capture")
    room = cl.truth_room(seed=8, gaussians=15_000, views=10)
    out = cl.write_inria_output(root, room)
    masks = cl.render_masks(room, root / "sam_masks" / room.id)
    (root / "holi.json").write_text(json.dumps(cl.holi_spatial_json(room, masks)))
    return out, root / "holi.json", room


def test_import_then_qa_build_then_bench_export(capture, tmp_path: Path, capsys) -> None:
    out, holi, room = capture
    scene_dir = tmp_path / "scenes" / "tarot"
    assert main(["scenes", "import", str(out), "--out", str(scene_dir), "--instances", str(holi), "--name", "tarot"]) == 0
    text = capsys.readouterr().out
    for fact in ("layout       inria", f"views        {len(room.views)}", f"instances    {len(room.instances)}",
                 "frame check  ok", "assigned by boxes", "mean rendered-mask IoU", "wrote"):
        assert fact in text, fact
    assert main(["scenes", "info", str(scene_dir)]) == 0
    info = capsys.readouterr().out
    assert "frame check: ok" in info and "warning" not in info
    assert main(["qa", "build", str(tmp_path / "scenes"), "--per-sub-type", "2"]) == 0
    capsys.readouterr()
    bench = tmp_path / "bench"
    assert main(["export", "--split", "bench", "--all-bench", "--scenes", str(tmp_path / "scenes"), "--out", str(bench),
                 "--degradations", "jpeg_compression", "--image-size", "80x60", "--max-questions", "6", "--no-progress"]) == 0
    text = capsys.readouterr().out
    assert "scenes: 1 bench, 0 val, 0 train" in text
    with open(bench / "bench.tsv", newline="", encoding="utf-8") as handle:
        rows = list(csv.DictReader(handle, delimiter="\t"))
    assert len(rows) == 12 and {r["degradation_type"] for r in rows} == {"ori", "jpeg_compression"}
    assert not any("the a " in r["question"].lower() or "the an " in r["question"].lower() for r in rows)
    # a single scene without --all-bench says how to make a bench
    assert main(["export", "--split", "bench", "--scenes", str(tmp_path / "scenes"), "--out", str(tmp_path / "b2")]) == 2
    assert "--all-bench" in capsys.readouterr().err


def test_frame_mismatch_exits_non_zero_with_the_cause(tmp_path: Path, capsys) -> None:
    room = cl.truth_room(seed=6, gaussians=10_000, views=12, shift=(12.0, -9.0, 0.0))
    data = tmp_path / "data"
    data.mkdir()
    (data / "transforms.json").write_text(json.dumps(cl.transforms_json(room, world=cl.APPLIED)))
    ply, dataparser = cl.write_splatfacto(tmp_path / "outputs" / "r" / "splatfacto" / "t", room, cl.APPLIED)
    lone = tmp_path / "splat.ply"
    lone.write_bytes(ply.read_bytes())
    assert main(["scenes", "import", str(data), "--gaussians-file", str(lone), "--out", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err
    assert "the Gaussians and the cameras disagree" in err and "normalised frame" in err and "--dataparser-transforms" in err
    assert not (tmp_path / "bad" / "scene.json").exists()
    assert main(["scenes", "import", str(data), "--gaussians-file", str(lone), "--dataparser-transforms", str(dataparser),
                 "--out", str(tmp_path / "good")]) == 0


def test_render_of_an_empty_view_fails_unless_allowed(tmp_path: Path, capsys) -> None:
    room = cl.truth_room(seed=9, gaussians=10_000, views=6)
    view, cam = next(iter(room.views.items()))
    away = np.asarray(cam.cam_to_world).copy()
    away[:3, 3] += 500.0 * away[:3, 2]  # far beyond the room, looking further away
    views = dict(room.views)
    views[view] = cam.with_pose(away)
    save_scene(Scene(room.id, room.gaussians, views, room.instances, room.up), tmp_path / "s")
    png = tmp_path / "v.png"
    assert main(["render", str(tmp_path / "s"), "--view", view, "--out", str(png)]) == 2
    assert "renders empty" in capsys.readouterr().err and not png.exists()
    assert main(["render", str(tmp_path / "s"), "--view", view, "--out", str(png), "--allow-empty"]) == 0 and png.exists()


def test_scene_without_ids_warns_and_still_builds(tmp_path: Path, capsys) -> None:
    room = cl.truth_room(seed=10, gaussians=10_000, views=8)
    folder = tmp_path / "scenes" / room.id
    save_scene(Scene(room.id, cl.without_ids(room.gaussians), room.views, room.instances, room.up), folder)
    assert main(["scenes", "info", str(folder)]) == 0
    assert "carry no instance ids" in capsys.readouterr().out
    with pytest.warns(UserWarning, match="assigned .* by box"):
        from spacedg.qa.build import build_scene_index
        from spacedg.qa.index import QABuildConfig

        qa = build_scene_index(folder, QABuildConfig(per_sub_type=2), progress=False)
    assert qa.counts().get("object_counting", 0) + qa.counts().get("inter_object_distance", 0) > 0
    assert load_scene(folder).gaussians.instance_ids is None  # the folder itself is not rewritten
