"""Hostile numbers in files: 5,000-digit integers, huge SH coefficients, decompression bombs."""

from __future__ import annotations

import gzip
import json
import struct
from pathlib import Path

import numpy as np
import pytest

from spacedg.errors import FileFormatError, FileValueError, InvalidDataError
from spacedg.render.gaussians import SH_MAX, Gaussians

DIGITS = "9" * 5000


@pytest.mark.parametrize("what", ["scene.json", "transforms.json", "cameras.json", "instance JSON"])
def test_a_5000_digit_integer_in_json_names_the_file_and_field(tmp_path: Path, what: str) -> None:
    from spacedg.files import read_json

    path = tmp_path / "f.json"
    path.write_text('{"frames": [{"w": ' + DIGITS + "}]}")
    with pytest.raises(FileFormatError, match=rf"f.json: {what}: field 'w', line 1: an integer of 5,000 digits"):
        read_json(path, what)


def test_readers_refuse_5000_digit_integers(tmp_path: Path) -> None:
    from tests.fuzz_cases import Assets
    from spacedg.scene.io import load_scene
    from spacedg.scene.io.inria import read_inria_cameras
    from spacedg.scene.io.instances import read_instances
    from spacedg.scene.io.nerfstudio import read_transforms

    assets = Assets(tmp_path / "assets")
    scene_text = json.dumps(assets.scene_json).replace('"width": 32', f'"width": {DIGITS}', 1)
    folder = tmp_path / "scene"
    folder.mkdir()
    for name in ("gaussians.ply",):
        (folder / name).write_bytes((assets.scene_dir / name).read_bytes())
    (folder / "scene.json").write_text(scene_text)
    with pytest.raises(FileFormatError, match="field 'width'.*5,000 digits"):
        load_scene(folder)
    for reader, data, key in (
        (read_transforms, assets.transforms, '"fl_x": '),
        (read_inria_cameras, assets.inria, '"fx": '),
        (read_instances, {"instances": assets.instances}, '"id": '),
    ):
        text = json.dumps(data)
        start = text.index(key) + len(key)
        end = start + len(text[start:].split(",")[0].split("}")[0])
        path = tmp_path / f"{reader.__name__}.json"
        path.write_text(text[:start] + DIGITS + text[end:])
        with pytest.raises(FileFormatError, match=rf"field '{key.strip(': ').strip(chr(34))}'.*5,000 digits"):
            reader(path)


@pytest.mark.parametrize("count", [DIGITS, "1" + "0" * 18])
def test_ply_header_counts_are_bounded(tmp_path: Path, count: str) -> None:
    from spacedg.scene.io.ply import read_ply

    path = tmp_path / "p.ply"
    path.write_bytes(f"ply\nformat binary_little_endian 1.0\nelement vertex {count}\nproperty float x\nend_header\n".encode())
    with pytest.raises(FileFormatError, match="header line 3: element 'vertex' declares a count of"):
        read_ply(path)


def test_ply_long_f_rest_index_is_a_clear_error(tmp_path: Path) -> None:
    from tests.fuzz_cases import Assets
    from spacedg.scene.io.ply import read_ply

    data = Assets(tmp_path / "a").ply.replace(b"property float f_dc_0\n", b"property float f_dc_0\nproperty float f_rest_" + b"1" * 5000 + b"\n", 1)
    (tmp_path / "p.ply").write_bytes(data)
    with pytest.raises(FileFormatError, match="is not an f_rest_<0..44> name"):
        read_ply(tmp_path / "p.ply")


@pytest.mark.parametrize("value", [3e38, 1e20, -SH_MAX * 1.01])
def test_huge_sh_coefficients_are_refused_with_file_and_field(tmp_path: Path, value: float) -> None:
    from spacedg.scene.io.ply import read_ply, write_ply

    g = Gaussians([[0.0, 0.0, 2.0]] * 3, [[1.0, 0, 0, 0]] * 3, [[0.1] * 3] * 3, [0.5] * 3, np.zeros((3, 1, 3)))
    write_ply(tmp_path / "g.ply", g)
    data = bytearray((tmp_path / "g.ply").read_bytes())
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    record = 17 * 4  # x y z nx ny nz f_dc_0..2 opacity scale_0..2 rot_0..3 (float32)
    struct.pack_into("<f", data, header_end + record + 6 * 4, value)  # f_dc_0 of vertex 1
    (tmp_path / "g.ply").write_bytes(bytes(data))
    with pytest.raises(FileValueError, match=r"g.ply: field 'sh': 1 of 3 entries outside \[-10000, 10000\] \(first at index 1"):
        read_ply(tmp_path / "g.ply")
    with pytest.raises(InvalidDataError, match="f_dc_\\*, f_rest_\\* in a 3DGS PLY"):
        Gaussians([[0.0, 0.0, 2.0]], [[1.0, 0, 0, 0]], [[0.1] * 3], [0.5], np.full((1, 1, 3), value))


def test_sh_at_the_bound_renders_finite_on_both_backends() -> None:
    from spacedg.render import Camera, render

    rng = np.random.default_rng(0)
    sh = np.clip(rng.choice([-SH_MAX, SH_MAX], (20, 16, 3)), -SH_MAX, SH_MAX)
    g = Gaussians(rng.normal(0, 0.3, (20, 3)) + [0, 0, 2], np.tile([1.0, 0, 0, 0], (20, 1)), np.full((20, 3), 0.05), np.ones(20), sh)
    cam = Camera(30.0, 30.0, 16.0, 12.0, 32, 24, np.eye(4))
    for backend in ("cpu", "torch"):
        frame = render(g, cam, outputs="all", backend=backend)
        assert np.isfinite(frame.rgb).all() and frame.rgb.max() > 1e6  # light, bright and finite


def test_spz_decompression_bomb_is_refused_without_inflating_it(tmp_path: Path) -> None:
    from spacedg.scene.io.spz import read_spz

    header = struct.pack("<IIIBBBB", 0x5053474E, 3, 2**31, 0, 12, 0, 0)
    (tmp_path / "bomb.spz").write_bytes(gzip.compress(header + bytes(10**7), compresslevel=9))
    with pytest.raises(FileFormatError, match="cannot hold them"):
        read_spz(tmp_path / "bomb.spz")
