"""``spacedg scenes``: synth → info → preview through the real console entry point."""

from __future__ import annotations

import json

import cv2
import pytest

from spacedg.cli import main
from spacedg.scene.io import load_scene


def test_synth_info_preview_round_trip(tmp_path, capsys):
    out = tmp_path / "scenes"
    assert main(["scenes", "synth", "--n", "2", "--out", str(out), "--seed", "4", "--num-gaussians", "12000",
                 "--min-views", "40", "--max-views", "44"]) == 0
    text = capsys.readouterr().out
    assert "room-000004" in text and "room-000005" in text and "wrote 2 scene folder(s)" in text
    scene = load_scene(out / "room-000004")
    assert 40 <= len(scene.views) <= 44 and len(scene.instances) >= 8
    assert scene.metadata["config"]["gaussians"] == 12000

    assert main(["scenes", "info", str(out), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert [s["id"] for s in info] == ["room-000004", "room-000005"]
    assert info[0]["gaussians"] == len(scene.gaussians)
    assert sum(info[0]["labels"].values()) == len(scene.instances)

    assert main(["scenes", "info", str(out / "room-000005")]) == 0
    assert "instances per label:" in capsys.readouterr().out

    png = tmp_path / "plans.png"
    assert main(["scenes", "preview", str(out), "--out", str(png)]) == 0
    image = cv2.imread(str(png))
    assert image is not None and image.shape[0] > 100 and image.shape[1] > 200

    # a second run finds the rooms and keeps them; other settings are refused, not overwritten
    assert main(["scenes", "synth", "--n", "2", "--out", str(out), "--seed", "4", "--num-gaussians", "12000",
                 "--min-views", "40", "--max-views", "44"]) == 0
    assert capsys.readouterr().out.count("exists") == 2
    assert main(["scenes", "synth", "--n", "1", "--out", str(out), "--seed", "4", "--num-gaussians", "13000"]) == 2
    assert "exists with other generation settings" in capsys.readouterr().err
    # wall rows are a generation setting: a room made with them is not the room without them
    assert scene.metadata["config"]["row_probability"] == 0.5
    assert main(["scenes", "synth", "--n", "1", "--out", str(out), "--seed", "4", "--num-gaussians", "12000",
                 "--min-views", "40", "--max-views", "44", "--row-probability", "0"]) == 2
    assert "exists with other generation settings" in capsys.readouterr().err
    flat = tmp_path / "flat"  # without rows the record has no row key: folders made before rows existed stay valid
    assert main(["scenes", "synth", "--n", "1", "--out", str(flat), "--seed", "4", "--num-gaussians", "12000",
                 "--min-views", "40", "--max-views", "44", "--row-probability", "0"]) == 0
    assert "row_probability" not in load_scene(flat / "room-000004").metadata["config"]


@pytest.mark.parametrize(
    "argv, message",
    [
        (["scenes", "info", "/nonexistent/scene"], "no such scene folder"),
        (["scenes", "synth", "--n", "0", "--out", "x"], "argument --n: must be a whole number >= 1"),
        (["scenes", "synth", "--n", "1", "--out", "x", "--num-gaussians", "5"], "must be a whole number from 10000 to 5000000"),
    ],
)
def test_bad_input_gives_one_clear_error(argv, message, capsys):
    try:
        code = main(argv)
    except SystemExit as exit_:  # a usage error, from the parser
        code = exit_.code
    assert code == 2
    err = capsys.readouterr().err
    assert message in err and "Traceback" not in err
