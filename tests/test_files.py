"""spacedg.files: file messages, the one-writer lock, and the removal of a killed writer's temporary files."""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from spacedg.errors import FileFormatError, ParameterError
from spacedg.files import atomic_write_bytes, exclusive_lock, read_rgb, remove_stale_temps, require_file, temp_target, write_png
from tests.conftest import REPO_ROOT


def test_require_file_names_the_kind_once(tmp_path: Path) -> None:
    """The finding: "expected a PLY file file"."""
    for what, expected in (("PLY file", "expected a PLY file, found"), (".splat file", "expected a .splat file, found"),
                           ("Gaussians file", "expected a Gaussians file, found"), ("scene.json", "expected a scene.json file, found")):
        with pytest.raises(FileFormatError) as info:
            require_file(tmp_path, what)
        assert expected in str(info.value) and "file file" not in str(info.value)
    with pytest.raises(FileFormatError, match="PLY file not found"):
        require_file(tmp_path / "x.ply", "PLY file")


def test_ply_reader_message(tmp_path: Path) -> None:
    from spacedg.scene.io import read_ply

    with pytest.raises(FileFormatError, match=r"expected a PLY file, found a directory") as info:
        read_ply(tmp_path)
    assert "file file" not in str(info.value)


def test_exclusive_lock_one_holder(tmp_path: Path) -> None:
    path = tmp_path / "out.jsonl.lock"
    with exclusive_lock(path, "out.jsonl is busy") as held:
        assert held.held and path.read_text().strip() == str(os.getpid())
        with pytest.raises(ParameterError, match=rf"out.jsonl is busy \(pid {os.getpid()}, lock file {path}\)"):
            exclusive_lock(path, "out.jsonl is busy")
    assert not path.exists()
    path.write_text("12345\n")  # a stale file from a killed holder: not locked, so taken over
    with exclusive_lock(path, "busy") as again:
        assert again.held and path.read_text().strip() == str(os.getpid())


def test_exclusive_lock_across_processes(tmp_path: Path) -> None:
    path = tmp_path / "x.lock"
    code = ("import sys, time; from spacedg.files import exclusive_lock; lock = exclusive_lock(sys.argv[1], 'busy'); "
            "print('held', flush=True); time.sleep(30)")
    child = subprocess.Popen([sys.executable, "-c", code, str(path)], stdout=subprocess.PIPE, text=True,
                             env={**os.environ, "PYTHONPATH": str(REPO_ROOT)})
    try:
        assert child.stdout.readline().strip() == "held"
        with pytest.raises(ParameterError, match=rf"pid {child.pid}"):
            exclusive_lock(path, "busy")
    finally:
        child.kill()
        child.wait()
    deadline = time.monotonic() + 5
    while True:  # kill -9 frees the lock (the file stays, with the dead pid)
        try:
            lock = exclusive_lock(path, "busy")
            break
        except ParameterError:
            assert time.monotonic() < deadline
            time.sleep(0.05)
    lock.release()


def test_exclusive_lock_in_an_unwritable_place() -> None:
    with pytest.raises(ParameterError, match="cannot create the lock file"):
        exclusive_lock("/proc/spacedg-no/x.lock", "busy")


def test_remove_stale_temps_touches_only_our_pattern(tmp_path: Path) -> None:
    fd, name = tempfile.mkstemp(prefix=".0000007_0.png.", suffix=".tmp", dir=tmp_path)  # what atomic_write makes
    os.close(fd)
    ours = Path(name)
    others = [tmp_path / n for n in (".0000007_0.png.tmp", ".0000007_0.png.ABCDEFGH.tmp", "0000007_0.png.abcdefgh.tmp",
                                     ".notes.abcdefgh.tmp", ".0000008_0.png.abcdefgh.tmp", "0000007_0.png")]
    for path in others:
        path.write_text("x")
    assert temp_target(ours.name) == "0000007_0.png" and temp_target("plain.png") is None
    removed = remove_stale_temps(tmp_path, ["0000007_0.png"])
    assert removed == [ours] and not ours.exists() and all(p.exists() for p in others)
    assert remove_stale_temps(tmp_path, lambda target: target.startswith("0000008")) == [tmp_path / ".0000008_0.png.abcdefgh.tmp"]
    atomic_write_bytes(tmp_path / "a.bin", b"1")  # a completed write leaves no temporary file
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".a.bin.")]


def test_write_png_round_trips_rgb_and_refuses_other_arrays(tmp_path: Path) -> None:
    """The one PNG writer takes RGB (it reorders to OpenCV's BGR), 16-bit single channel too, and
    leaves no temporary file; a float image or a bad compression level is refused naming the argument."""
    import cv2
    import numpy as np

    rgb = np.random.default_rng(0).integers(0, 256, (9, 13, 3), dtype=np.uint8)
    write_png(tmp_path / "sub" / "a.png", rgb, "--out", compression=9)
    assert np.array_equal(read_rgb(tmp_path / "sub" / "a.png"), rgb)
    depth = np.arange(9 * 13, dtype=np.uint16).reshape(9, 13) * 500
    write_png(tmp_path / "d.png", depth, "--depth-out")
    assert np.array_equal(cv2.imread(str(tmp_path / "d.png"), cv2.IMREAD_UNCHANGED), depth)
    assert sorted(p.name for p in tmp_path.rglob("*") if p.is_file()) == ["a.png", "d.png"]
    with pytest.raises(ParameterError, match=r"--out .*uint8/uint16 array, got float32"):
        write_png(tmp_path / "f.png", rgb.astype(np.float32), "--out")
    with pytest.raises(ParameterError, match="compression must be an integer 0-9, got 10"):
        write_png(tmp_path / "f.png", rgb, "--out", compression=10)
    assert not (tmp_path / "f.png").exists()
