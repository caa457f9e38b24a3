"""``spacedg gallery``: the labelled contact sheet of one view."""

from __future__ import annotations

from pathlib import Path

import cv2
import pytest

from spacedg.cli import main
from spacedg.scene.io import save_scene


@pytest.fixture(scope="module")
def room_dir(small_room, tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("gallery") / "room"
    save_scene(small_room, folder)
    return folder


def test_gallery_png_has_one_row_per_degradation(room_dir: Path, tmp_path: Path, capsys) -> None:
    out = tmp_path / "sheet.png"
    code = main(["gallery", str(room_dir), "--out", str(out), "--degradations", "haze,low_res,jpeg_compression",
                 "--thumb-width", "96"])
    assert code == 0, capsys.readouterr().err
    sheet = cv2.imread(str(out))
    assert sheet is not None
    two = tmp_path / "two.png"
    assert main(["gallery", str(room_dir), "--out", str(two), "--degradations", "haze", "--thumb-width", "96"]) == 0
    row_height = cv2.imread(str(two)).shape[0]
    assert sheet.shape[0] == pytest.approx(3 * row_height, abs=12)
    assert sheet.shape[1] == cv2.imread(str(two)).shape[1]  # columns: label, clean, 1-5, bench
    assert "wrote" in capsys.readouterr().out


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--view", "no_such_view"], "no such view"),
        (["--degradations", "hazee"], "Did you mean 'haze'"),
        (["--thumb-width", "10"], "--thumb-width"),
    ],
)
def test_gallery_bad_input(room_dir: Path, tmp_path: Path, capsys, args: list[str], message: str) -> None:
    try:
        code = main(["gallery", str(room_dir), "--out", str(tmp_path / "x.png"), *args])
    except SystemExit as exit_:  # a usage error, from the parser
        code = exit_.code
    assert code == 2 and message in capsys.readouterr().err
    assert not (tmp_path / "x.png").exists()
