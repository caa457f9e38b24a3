""".splat: exact layout, round trips, quantisation, truncation and lossy-write refusal."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from tests.helpers_io import random_gaussians

from spacedg.scene.io import FileValueError, read_splat, write_splat
from spacedg.errors import FileFormatError, InvalidDataError
from spacedg.render.gaussians import SH_C0, Gaussians


def handmade_splat(path: Path) -> None:
    """Two records written byte by byte from the format description."""
    rec0 = struct.pack("<3f3f4B4B", 1.0, -2.0, 3.5, 0.1, 0.2, 0.3, 255, 0, 128, 51, 255, 128, 128, 128)
    rec1 = struct.pack("<3f3f4B4B", 0.0, 0.0, 0.0, 1e-3, 1e-3, 1e-3, 10, 20, 30, 255, 128, 128, 128, 0)
    path.write_bytes(rec0 + rec1)


def test_reads_the_documented_layout(tmp_path: Path) -> None:
    path = tmp_path / "two.splat"
    handmade_splat(path)
    g = read_splat(path)
    assert len(g) == 2 and g.sh_degree == 0 and g.instance_ids is None
    np.testing.assert_array_equal(g.means[0], np.float32([1.0, -2.0, 3.5]))
    np.testing.assert_array_equal(g.scales[0], np.float32([0.1, 0.2, 0.3]))
    np.testing.assert_allclose(g.base_colors()[0], [1.0, 0.0, 128 / 255], atol=1e-6)
    np.testing.assert_allclose(g.opacities, [51 / 255, 1.0], atol=1e-7)
    np.testing.assert_allclose(g.quats[0], [1.0, 0.0, 0.0, 0.0], atol=1e-7)  # (255-128)/128 normalised
    np.testing.assert_allclose(g.quats[1], [0.0, 0.0, 0.0, -1.0], atol=1e-7)  # (0-128)/128 = -1
    np.testing.assert_allclose(g.sh[1, 0], (np.array([10, 20, 30]) / 255 - 0.5) / SH_C0, rtol=1e-6)


def test_round_trip_from_file_is_byte_exact_except_rotation(tmp_path: Path) -> None:
    rng = np.random.default_rng(0)
    n = 500
    raw = np.zeros(n, dtype=[("p", "<f4", 3), ("s", "<f4", 3), ("c", "u1", 4), ("q", "u1", 4)])
    raw["p"] = rng.normal(size=(n, 3))
    raw["s"] = rng.uniform(1e-4, 0.1, (n, 3))
    raw["c"] = rng.integers(0, 256, (n, 4))
    q = rng.normal(size=(n, 4))
    raw["q"] = np.clip(np.rint(q / np.linalg.norm(q, axis=1, keepdims=True) * 128 + 128), 0, 255)
    (tmp_path / "a.splat").write_bytes(raw.tobytes())
    g = read_splat(tmp_path / "a.splat")
    write_splat(tmp_path / "b.splat", g)
    back = np.frombuffer((tmp_path / "b.splat").read_bytes(), dtype=raw.dtype)
    np.testing.assert_array_equal(back["p"], raw["p"])
    np.testing.assert_array_equal(back["s"], raw["s"])
    np.testing.assert_array_equal(back["c"], raw["c"])  # colour and opacity bytes exact
    assert np.abs(back["q"].astype(int) - raw["q"].astype(int)).max() <= 2
    g2 = read_splat(tmp_path / "b.splat")
    dots = np.abs(np.sum(g.quats.astype(np.float64) * g2.quats, axis=1))
    assert dots.min() > 1 - 1e-3  # same rotation within 8-bit quantisation


def test_round_trip_from_memory(tmp_path: Path) -> None:
    g = random_gaussians(300, 0, seed=3)
    colours = np.random.default_rng(1).uniform(0, 1, (300, 3))
    g = Gaussians.from_colors(g.means, g.quats, g.scales, g.opacities, colours)
    write_splat(tmp_path / "m.splat", g)
    assert (tmp_path / "m.splat").stat().st_size == 300 * 32
    back = read_splat(tmp_path / "m.splat")
    np.testing.assert_array_equal(back.means, g.means)
    np.testing.assert_array_equal(back.scales, g.scales)
    np.testing.assert_allclose(back.base_colors(), np.rint(colours * 255) / 255, atol=1e-6)
    np.testing.assert_allclose(back.opacities, np.rint(g.opacities * 255) / 255, atol=1e-7)
    dots = np.abs(np.sum(back.quats.astype(np.float64) * g.quats, axis=1))
    assert dots.min() > 1 - 1e-3


@pytest.mark.parametrize("extra", [1, 31, 33])
def test_size_not_multiple_of_32(tmp_path: Path, extra: int) -> None:
    path = tmp_path / "t.splat"
    path.write_bytes(b"\0" * (64 + extra))
    with pytest.raises(FileFormatError, match=f"size {64 + extra} bytes is not a multiple of 32"):
        read_splat(path)


def test_truncated_real_file(tmp_path: Path) -> None:
    write_splat(tmp_path / "g.splat", random_gaussians(10, 0))
    data = (tmp_path / "g.splat").read_bytes()
    (tmp_path / "cut.splat").write_bytes(data[:-5])
    with pytest.raises(FileFormatError, match="truncated"):
        read_splat(tmp_path / "cut.splat")


def test_zero_quaternion_policy(tmp_path: Path) -> None:
    path = tmp_path / "z.splat"
    rec = struct.pack("<3f3f4B4B", 0, 0, 0, 1, 1, 1, 1, 2, 3, 4, 128, 128, 128, 128)
    path.write_bytes(rec * 3)
    with pytest.raises(FileValueError, match=r"3 of 3 .*zero rotation.*zero_quaternions='identity'"):
        read_splat(path)
    g = read_splat(path, zero_quaternions="identity")
    np.testing.assert_array_equal(g.quats, np.tile(np.float32([1, 0, 0, 0]), (3, 1)))
    with pytest.raises(InvalidDataError, match="zero_quaternions"):
        read_splat(path, zero_quaternions="drop")  # type: ignore[arg-type]


def test_nan_position_is_invalid_data(tmp_path: Path) -> None:
    path = tmp_path / "n.splat"
    path.write_bytes(struct.pack("<3f3f4B4B", float("nan"), 0, 0, 1, 1, 1, 1, 2, 3, 4, 255, 128, 128, 128))
    with pytest.raises(InvalidDataError, match="means"):
        read_splat(path)


def test_writer_refuses_lossy_writes_unless_allowed(tmp_path: Path) -> None:
    g = random_gaussians(20, 2, seed=4)
    with pytest.raises(InvalidDataError, match="SH degree 2.*allow_lossy=True"):
        write_splat(tmp_path / "x.splat", g)
    assert not (tmp_path / "x.splat").exists()
    write_splat(tmp_path / "x.splat", g, allow_lossy=True)
    back = read_splat(tmp_path / "x.splat")
    np.testing.assert_allclose(back.base_colors(), np.clip(g.base_colors(), 0, 1), atol=0.5 / 255 + 1e-6)
    bright = Gaussians.from_colors(g.means, g.quats, g.scales, g.opacities, np.full((20, 3), 1.2))
    with pytest.raises(InvalidDataError, match="outside \\[0, 1\\].*clamped"):
        write_splat(tmp_path / "y.splat", bright)
    write_splat(tmp_path / "y.splat", bright, allow_lossy=True)
    np.testing.assert_allclose(read_splat(tmp_path / "y.splat").base_colors(), 1.0, atol=1e-6)


def test_empty_and_missing(tmp_path: Path) -> None:
    (tmp_path / "e.splat").write_bytes(b"")
    assert len(read_splat(tmp_path / "e.splat")) == 0
    with pytest.raises(FileFormatError, match="not found"):
        read_splat(tmp_path / "missing.splat")
