"""Readers of real-capture files, each against a fixture written in its project's published layout."""

from __future__ import annotations

import gzip
import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from spacedg.errors import FileFormatError
from spacedg.render.gaussians import Gaussians, quat_to_matrix
from spacedg.scene.io import read_gaussians, read_instances, read_ply, read_transforms, write_ply
from spacedg.scene.io.embodiedscan import read_embodiedscan_boxes
from spacedg.scene.io.inria import latest_point_cloud, read_cfg_args, read_inria_cameras
from spacedg.scene.io.nerfstudio import denormalising_similarity, read_applied_transform, read_dataparser_transforms
from spacedg.scene.io.scannetpp import read_segments_anno
from spacedg.scene.io.spz import read_spz
from tests.scene import capture_layouts as cl


@pytest.fixture(scope="module")
def room():
    return cl.truth_room(seed=5, gaussians=10_000, views=9)


def _random_gaussians(n: int = 700, degree: int = 1, seed: int = 3) -> Gaussians:
    rng = np.random.default_rng(seed)
    q = rng.normal(size=(n, 4))
    sh = rng.uniform(-0.4, 0.4, size=(n, (degree + 1) ** 2, 3))
    sh[:, 0] = rng.uniform(-1.5, 1.5, size=(n, 3))
    return Gaussians(rng.uniform(-2, 3, (n, 3)), q / np.linalg.norm(q, axis=1, keepdims=True),
                     np.exp(rng.uniform(-5, -1, (n, 3))), rng.uniform(0.02, 0.98, n), sh)


def _same_rotation(a: np.ndarray, b: np.ndarray, tol: float) -> None:
    """Quaternions equal up to sign, compared as rotation matrices."""
    assert np.abs(quat_to_matrix(a.astype(np.float64)) - quat_to_matrix(b.astype(np.float64))).max() < tol


# ---------------------------------------------------------------- INRIA output folders
def test_inria_cameras_round_trip(tmp_path: Path, room) -> None:
    path = tmp_path / "cameras.json"
    path.write_text(json.dumps(cl.inria_cameras(room)))
    cams = read_inria_cameras(path)
    assert list(cams) == list(room.views)
    for name, cam in cams.items():
        ref = room.views[name]
        np.testing.assert_allclose(cam.cam_to_world, ref.cam_to_world, atol=1e-9)
        assert (cam.fx, cam.fy, cam.width, cam.height) == pytest.approx((ref.fx, ref.fy, ref.width, ref.height))
        assert (cam.cx, cam.cy) == (ref.width / 2, ref.height / 2)


def test_inria_output_pieces(tmp_path: Path, room) -> None:
    out = cl.write_inria_output(tmp_path, room)
    (out / "point_cloud" / "iteration_900").mkdir()
    (out / "point_cloud" / "iteration_900" / "point_cloud.ply").write_bytes(b"")
    assert latest_point_cloud(out).parent.name == "iteration_30000"  # numeric, not lexical
    cfg = read_cfg_args(out / "cfg_args")
    assert cfg["source_path"] == str((tmp_path / "data").resolve()) and cfg["sh_degree"] == 3 and cfg["eval"] is False
    (tmp_path / "evil").write_text("Namespace(source_path=__import__('os').getcwd())")
    assert read_cfg_args(tmp_path / "evil")["source_path"] is None  # never evaluated
    (tmp_path / "bad").write_text("print('x')")
    with pytest.raises(FileFormatError, match="Namespace"):
        read_cfg_args(tmp_path / "bad")


# ---------------------------------------------------------------- nerfstudio
def test_transforms_reads_test_frames_and_applied_transform(tmp_path: Path, room) -> None:
    path = tmp_path / "transforms.json"
    data = cl.transforms_json(room, world=cl.APPLIED)
    assert data["test_frames"], "the fixture holds test frames"
    path.write_text(json.dumps(data))
    cams = read_transforms(path)
    assert len(cams) == len(room.views) == len(data["frames"]) + len(data["test_frames"])
    assert len(read_transforms(path, include_test_frames=False)) == len(data["frames"])
    for view, ref in room.views.items():
        np.testing.assert_allclose(cams[f"images/{view}.jpg"].cam_to_world, cl.APPLIED @ ref.cam_to_world, atol=1e-9)
    np.testing.assert_allclose(read_applied_transform(path), cl.APPLIED)
    dup = dict(data, test_frames=[data["frames"][0]])
    path.write_text(json.dumps(dup))
    with pytest.raises(FileFormatError, match=r"test_frames\[0\].*appears twice"):
        read_transforms(path)


def test_dataparser_transforms_undo_the_normalisation(tmp_path: Path, room) -> None:
    ply, dataparser = cl.write_splatfacto(tmp_path, room, cl.APPLIED)
    transform, scale = read_dataparser_transforms(dataparser)
    rot, t, k = denormalising_similarity(transform, scale)
    back = read_ply(ply).transformed(rot, t, k)
    expect = room.gaussians.transformed(cl.APPLIED[:3, :3], cl.APPLIED[:3, 3])
    np.testing.assert_allclose(back.means, expect.means, atol=1e-4)
    np.testing.assert_allclose(back.scales, expect.scales, rtol=1e-4)


# ---------------------------------------------------------------- annotations
def test_holi_spatial_json_is_read(tmp_path: Path, room) -> None:
    masks = cl.render_masks(room, tmp_path / "masks" / room.id)
    path = tmp_path / "holi.json"
    path.write_text(json.dumps(cl.holi_spatial_json(room, masks)))
    # INRIA names views by stem; the masks' parent folders are those stems
    got = {i.id: i for i in read_instances(path, views=list(room.views))}
    assert set(got) == {i.id for i in room.instances}
    for inst in room.instances:
        g = got[inst.id]
        np.testing.assert_allclose(g.box.corners(), inst.box.corners(), atol=1e-6)
        assert set(g.images) == set(masks.get(inst.id, {}))
        assert set(g.attributes.get("masks", {})) == set(masks.get(inst.id, {}))
        assert g.description == inst.description  # "a ..." stripped once
    # COLMAP-style names with an extension resolve by stem as well
    named = read_instances(path, views=[f"{v}.JPG" for v in room.views])
    assert all(all(v.endswith(".JPG") for v in i.images) for i in named)
    with pytest.raises(FileFormatError, match="image reference"):
        read_instances(path, views=["elsewhere"])


def test_segments_anno_boxes(tmp_path: Path, room) -> None:
    path = tmp_path / "segments_anno.json"
    data = cl.segments_anno(room)
    data["segGroups"].append({"id": 999, "objectId": 999, "label": "wall", "segments": []})  # no obb: skipped
    path.write_text(json.dumps(data))
    with pytest.warns(UserWarning, match="1 segment group"):
        got = {i.id: i for i in read_segments_anno(path)}
    assert set(got) == {i.id for i in room.instances}
    for inst in room.instances:
        np.testing.assert_allclose(got[inst.id].box.corners(), inst.box.corners(), atol=1e-9)


def test_embodiedscan_boxes(tmp_path: Path, room) -> None:
    path = tmp_path / "embodiedscan_infos.json"
    path.write_text(json.dumps(cl.embodiedscan_infos(room)))
    with pytest.raises(FileFormatError, match="2 scans"):
        read_embodiedscan_boxes(path)
    got = {i.id: i for i in read_embodiedscan_boxes(path, scene=room.id)}
    for inst in room.instances:
        assert got[inst.id].label == inst.label
        np.testing.assert_allclose(np.sort(got[inst.id].box.corners(), axis=0), np.sort(inst.box.corners(), axis=0), atol=1e-9)


def test_euler_zxy_matches_the_pytorch3d_convention() -> None:
    from spacedg.scene.io.embodiedscan import euler_zxy_to_matrix

    a, b, c = 0.3, -0.2, 1.1
    rz = np.array([[math.cos(a), -math.sin(a), 0], [math.sin(a), math.cos(a), 0], [0, 0, 1]])
    rx = np.array([[1, 0, 0], [0, math.cos(b), -math.sin(b)], [0, math.sin(b), math.cos(b)]])
    ry = np.array([[math.cos(c), 0, math.sin(c)], [0, 1, 0], [-math.sin(c), 0, math.cos(c)]])
    np.testing.assert_allclose(euler_zxy_to_matrix(np.array([a, b, c])), rz @ rx @ ry, atol=1e-12)
    np.testing.assert_allclose(cl.zxy_angles(rz @ rx @ ry), [a, b, c], atol=1e-12)


# ---------------------------------------------------------------- Gaussian file variants
def test_compressed_ply_within_its_quantisation(tmp_path: Path) -> None:
    g = _random_gaussians(700, degree=1)
    path = tmp_path / "scene.compressed.ply"
    cl.write_compressed_ply(path, g)
    got = read_gaussians(path)
    assert len(got) == len(g) and got.sh_degree == 1
    span = g.means.max(0) - g.means.min(0)
    assert (np.abs(got.means - g.means) <= span / 1023).all()  # 10-11 bits per chunk range
    assert np.abs(np.log(got.scales) - np.log(g.scales)).max() < 4 / 1023
    assert np.abs(got.opacities - g.opacities).max() <= 0.5 / 255 + 1e-6
    _same_rotation(got.quats, g.quats, 0.01)
    assert np.abs(got.sh[:, 1:] - g.sh[:, 1:]).max() <= 4.0 / 255 + 1e-6


def test_colour_only_ply(tmp_path: Path) -> None:
    plyfile = pytest.importorskip("plyfile")
    rng = np.random.default_rng(0)
    pts = np.zeros(500, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4"), ("red", "u1"), ("green", "u1"), ("blue", "u1")])
    for a in "xyz":
        pts[a] = rng.uniform(0, 1, 500)
    pts["red"], pts["green"], pts["blue"] = 255, 128, 0
    plyfile.PlyData([plyfile.PlyElement.describe(pts, "vertex")]).write(str(tmp_path / "points.ply"))
    got = read_ply(tmp_path / "points.ply")
    np.testing.assert_allclose(got.base_colors(), np.tile([1.0, 128 / 255, 0.0], (500, 1)), atol=1e-6)
    assert (got.scales > 0).all() and np.ptp(got.scales, axis=1).max() == 0 and got.scales.max() < 0.2
    # with the 3DGS properties but red/green/blue instead of f_dc_*
    full = np.zeros(3, dtype=[(n, "f4") for n in ("x", "y", "z", "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3")]
                    + [("red", "u1"), ("green", "u1"), ("blue", "u1")])
    full["rot_0"], full["scale_0"], full["scale_1"], full["scale_2"], full["red"] = 1, -3, -3, -2, 51
    plyfile.PlyData([plyfile.PlyElement.describe(full, "vertex")]).write(str(tmp_path / "gs.ply"))
    got = read_ply(tmp_path / "gs.ply")
    np.testing.assert_allclose(got.scales[0], np.exp([-3, -3, -2]), rtol=1e-6)
    assert got.opacities[0] == pytest.approx(0.5) and got.base_colors()[0, 0] == pytest.approx(0.2)


def test_mip_splatting_filter_3d(tmp_path: Path) -> None:
    plyfile = pytest.importorskip("plyfile")
    g = _random_gaussians(50, degree=0)
    write_ply(tmp_path / "plain.ply", g)
    plain = plyfile.PlyData.read(str(tmp_path / "plain.ply"))["vertex"].data
    f = np.full(len(g), 0.01, dtype=np.float32)
    rec = np.zeros(len(g), dtype=plain.dtype.descr + [("filter_3D", "f4")])
    for name in plain.dtype.names:
        rec[name] = plain[name]
    rec["filter_3D"] = f
    plyfile.PlyData([plyfile.PlyElement.describe(rec, "vertex")]).write(str(tmp_path / "mip.ply"))
    got, base = read_ply(tmp_path / "mip.ply"), read_ply(tmp_path / "plain.ply")
    s2 = base.scales.astype(np.float64) ** 2
    np.testing.assert_allclose(got.scales, np.sqrt(s2 + 1e-4), rtol=1e-5)
    np.testing.assert_allclose(got.opacities, base.opacities * np.sqrt(np.prod(s2, 1) / np.prod(s2 + 1e-4, 1)), rtol=1e-5)


@pytest.mark.parametrize("version", [2, 3])
def test_spz_within_its_quantisation(tmp_path: Path, version: int) -> None:
    g = _random_gaussians(400, degree=1)
    g = g.subset(np.flatnonzero(np.abs(g.sh[:, 0]).max(1) < 1.5))
    cl.write_spz(tmp_path / "s.spz", g, version=version)
    got = read_spz(tmp_path / "s.spz")
    assert len(got) == len(g) and got.sh_degree == 1
    assert np.abs(got.means - g.means).max() <= 2.0**-12
    assert np.abs(got.opacities - g.opacities).max() <= 0.5 / 255 + 1e-6
    assert np.abs(np.log(got.scales) - np.log(g.scales)).max() <= 1 / 32 + 1e-6
    _same_rotation(got.quats, g.quats, 0.02 if version == 3 else 0.2)  # v2: 8-bit x, y, z, w rebuilt (coarse near w = 0)
    assert np.abs(got.sh[:, 1:] - g.sh[:, 1:]).max() <= 0.5 / 128 + 1e-6
    raw = read_spz(tmp_path / "s.spz", axes="file")  # stored RUB: y and z mirrored
    np.testing.assert_allclose(raw.means[:, 1:], -got.means[:, 1:], atol=1e-6)


def test_bad_spz_and_ksplat(tmp_path: Path) -> None:
    (tmp_path / "a.spz").write_bytes(b"not gzip")
    with pytest.raises(FileFormatError, match="gzip"):
        read_gaussians(tmp_path / "a.spz")
    (tmp_path / "b.spz").write_bytes(gzip.compress(struct.pack("<IIIBBBB", 0x5053474E, 4, 1, 0, 12, 0, 0)))
    with pytest.raises(FileFormatError, match="version 4 is not read"):
        read_gaussians(tmp_path / "b.spz")
    (tmp_path / "c.spz").write_bytes(gzip.compress(struct.pack("<IIIBBBB", 0x5053474E, 3, 10**6, 0, 12, 0, 0)))
    with pytest.raises(FileFormatError, match="truncated"):
        read_gaussians(tmp_path / "c.spz")
    (tmp_path / "d.ksplat").write_bytes(b"\0" * 64)
    with pytest.raises(FileFormatError, match=r"\.ksplat.*not read"):
        read_gaussians(tmp_path / "d.ksplat")


def test_inria_training_width_follows_its_resolution_rule() -> None:
    from spacedg.render.camera import Camera
    from spacedg.scene.io.inria import at_training_scale, training_width

    assert training_width(1752, -1) == 1600 and training_width(1200, -1) == 1200  # the default caps at 1600 px
    assert training_width(1753, 2) == 876 and training_width(1000, 8) == 125       # -r 1/2/4/8 divide (rounded)
    assert training_width(1920, 800) == 800 and training_width(1920, None) == 1920  # a width; unreadable: the image's
    assert training_width(4946, -1, "images_4") == 1236 and training_width(4946, 2, "images_2") == 1236  # -i images_N first
    assert training_width(4946, -1, "images") == 1600 and training_width(4946, -1, "/data/bicycle/images_8/") == 618
    cam = Camera(1000.0, 1000.0, 876.0, 584.0, 1752, 1168, np.eye(4))
    views, note = at_training_scale({"a": cam}, -1)
    assert views["a"].capture_focal == pytest.approx((1000.0 * 1600 / 1752,) * 2) and "1600" in note
    views, note = at_training_scale({"a": cam.resized(800, 533)}, -1)
    assert views["a"].capture_focal == (views["a"].fx, views["a"].fy) and note is None
