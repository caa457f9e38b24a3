"""Visibility from rendered instance-id maps (spacedg.scene.visibility), covisibility from rendered depth and its cache (spacedg.scene.covisibility)."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.scene.box import OrientedBox
from spacedg.scene.model import Instance, Scene
import spacedg.scene.covisibility as covisibility
from spacedg.scene.covisibility import covisibility_cache_path, covisibility_matrix, load_or_compute_covisibility, symmetrize
from spacedg.scene.visibility_classes import VisibilityClass, VisibilityThresholds, classify
from spacedg.scene.visibility import compute_visibility, reduced_camera, unbounded_canvas, with_visibility
from spacedg.errors import ParameterError
from spacedg.render.camera import Camera, FisheyeLens
from spacedg.render.gaussians import Gaussians

# 160×120 pinhole camera at the origin looking down +z (OpenCV axes), f = 200 px: at z = 3 m
# the frame spans x in [-1.2, 1.2] m and y in [-0.9, 0.9] m.
W, H, F = 160, 120, 200.0
FRONT, BACK, HALF_OUT, BEHIND = 1, 2, 3, 4


def _plate(center: tuple[float, float, float], size: float, spacing: float = 0.02) -> np.ndarray:
    """Means of a square, camera-facing plate of Gaussians (side ``size`` metres)."""
    ticks = np.arange(-size / 2 + spacing / 2, size / 2, spacing)
    xs, ys = np.meshgrid(ticks, ticks)
    return np.stack([xs.ravel() + center[0], ys.ravel() + center[1], np.full(xs.size, center[2])], axis=1)


def _camera(pose: np.ndarray | None = None, lens: FisheyeLens | None = None) -> Camera:
    return Camera(F, F, W / 2, H / 2, W, H, np.eye(4) if pose is None else pose, lens)


@pytest.fixture(scope="module")
def plates() -> Scene:
    """Four opaque plates: one in front, one half hidden behind it, one half outside the frame, one behind the camera."""
    parts = {
        FRONT: _plate((-0.4, 0.0, 3.0), 0.6),  # u ∈ [33, 73], v ∈ [40, 80]
        BACK: _plate((-0.4, 0.0, 5.0), 1.2),  # u ∈ [40, 88], v ∈ [36, 84]; ~57 % behind FRONT
        HALF_OUT: _plate((1.2, 0.0, 3.0), 0.6),  # centred on the right border (u = 160)
        BEHIND: _plate((0.0, 0.0, -3.0), 0.6),
    }
    means = np.concatenate(list(parts.values()))
    ids = np.concatenate([np.full(len(m), i, np.int32) for i, m in parts.items()])
    n = len(means)
    quats = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    scales = np.tile([0.012, 0.012, 0.002], (n, 1))
    gaussians = Gaussians.from_colors(means, quats, scales, np.full(n, 0.95), np.full((n, 3), 0.5), instance_ids=ids)
    instances = [Instance(i, f"plate{i}", "", OrientedBox.fit_points(m)) for i, m in parts.items()]
    return Scene("plates", gaussians, {"v0": _camera()}, instances)


# ----------------------------------------------------------------------- visibility
def test_front_back_truncated_behind(plates: Scene) -> None:
    vis = compute_visibility(plates, progress=False)["v0"]
    front, back, half, behind = vis[FRONT], vis[BACK], vis[HALF_OUT], vis[BEHIND]
    assert front.visible_fraction > 0.95
    assert 1500 < front.visible_pixels < 1800  # 40 × 40 px, plus the Gaussians' soft edge
    assert 0.25 < back.visible_fraction < 0.6  # 33 × 40 of 48 × 48 px hidden
    assert back.visible_pixels < 0.7 * 48 * 48
    assert 0.4 < half.visible_fraction < 0.6  # truncation by the border counts
    assert behind.visible_pixels == 0 and behind.visible_fraction == 0.0
    assert sum(v.visible_pixels for v in vis.values()) <= W * H

    strict = VisibilityThresholds(min_fraction=0.6)
    area = W * H
    assert classify(front, strict, area) is VisibilityClass.VISIBLE
    assert classify(back, strict, area) is VisibilityClass.PARTIAL
    assert classify(half, strict, area) is VisibilityClass.PARTIAL
    assert classify(behind, strict, area) is VisibilityClass.HIDDEN


def test_pixels_are_full_resolution(plates: Scene) -> None:
    """Rendering at half size estimates the same full-resolution pixel count and fraction."""
    full = compute_visibility(plates, progress=False)["v0"][FRONT]
    half = compute_visibility(plates, image_size=(80, 60), progress=False)["v0"][FRONT]
    assert abs(half.visible_pixels - full.visible_pixels) <= 0.1 * full.visible_pixels
    assert abs(half.visible_fraction - full.visible_fraction) < 0.05


def test_reduced_renders_keep_the_view_aspect(plates: Scene) -> None:
    """A 16:9 view reduced into the default 160×120 box renders at 160×90 (never squeezed to 4:3); a 4:3 view at exactly
    160×120, as before; the visibility of the wide view is that of the same view fitted beforehand."""
    wide = Camera(F, F, 160.0, 90.0, 320, 180, np.eye(4))
    small = reduced_camera(wide, (160, 120))
    assert (small.width, small.height) == (160, 90) and small.fx == small.fy == F / 2 and (small.cx, small.cy) == (80.0, 45.0)
    four_three = Camera(2 * F, 2 * F, W, H, 2 * W, 2 * H, np.eye(4))
    assert reduced_camera(four_three, (W, H)).K.tolist() == four_three.resized(W, H).K.tolist()
    assert reduced_camera(plates.views["v0"], (W, H)) is plates.views["v0"]
    scene = Scene("wide", plates.gaussians, {"wide": wide, "fitted": small}, plates.instances)
    vis = compute_visibility(scene, progress=False)
    for iid in (FRONT, BACK, HALF_OUT):
        assert vis["wide"][iid].visible_fraction == pytest.approx(vis["fitted"][iid].visible_fraction, abs=1e-9)


def test_with_visibility_fills_instances(plates: Scene) -> None:
    filled = with_visibility(plates, progress=False)
    assert filled is not plates and filled.gaussians is plates.gaussians
    assert filled.instance(FRONT).visibility["v0"].visible_fraction > 0.95
    assert not plates.instance(FRONT).visibility  # the input is unchanged


def test_unbounded_canvas_keeps_the_frame_in_the_centre() -> None:
    cam = _camera()
    big = unbounded_canvas(cam, 3)
    assert (big.width, big.height, big.fx) == (3 * W, 3 * H, F)
    point = np.array([[0.3, -0.2, 2.0]])
    assert np.allclose(big.project(point)[0], cam.project(point)[0] + [W, H])
    with pytest.raises(ParameterError, match="odd"):
        unbounded_canvas(cam, 2)


def test_small_room_visibility(small_room: Scene) -> None:
    names = list(small_room.views)[:3]
    vis = compute_visibility(small_room, names, progress=False)
    ids = {inst.id for inst in small_room.instances}
    assert list(vis) == names
    for name, row in vis.items():
        cam = small_room.views[name]
        assert set(row) <= ids
        assert all(0.0 <= v.visible_fraction <= 1.0 for v in row.values())
        assert sum(v.visible_pixels for v in row.values()) <= cam.width * cam.height
        assert any(v.visible_pixels > 0 for v in row.values())


def test_unknown_view_is_named(plates: Scene) -> None:
    with pytest.raises(ParameterError, match="nope"):
        compute_visibility(plates, ["v0", "nope"], progress=False)
    with pytest.raises(ParameterError, match="nope"):
        covisibility_matrix(plates, ["nope"], progress=False)
    with pytest.raises(ParameterError, match="rel_threshold"):
        covisibility_matrix(plates, rel_threshold=0.0, progress=False)


# --------------------------------------------------------------------- covisibility
def _turned(pose: np.ndarray) -> np.ndarray:
    """The same camera centre, turned 180° about its own down (y) axis."""
    out = pose.copy()
    out[:3, :3] = pose[:3, :3] @ np.diag([-1.0, 1.0, -1.0])
    return out


@pytest.fixture(scope="module")
def room_views(small_room: Scene) -> Scene:
    first = list(small_room.views)[0]
    cam = small_room.views[first]
    views = {"a": cam, "a_copy": cam, "a_turned": cam.with_pose(_turned(cam.cam_to_world))}
    views.update({name: small_room.views[name] for name in list(small_room.views)[5:20:5]})
    return Scene(small_room.id, small_room.gaussians, views, small_room.instances, small_room.up)


def test_covisibility_identities(room_views: Scene) -> None:
    names, m = covisibility_matrix(room_views, progress=False)
    a, copy, turned = names.index("a"), names.index("a_copy"), names.index("a_turned")
    assert m.dtype == np.float32 and m.shape == (len(names), len(names))
    assert np.all(np.diag(m) == 1.0)
    assert m[a, copy] > 0.99 and m[copy, a] > 0.99
    assert m[a, turned] < 0.02 and m[turned, a] < 0.02
    assert np.all((m >= 0.0) & (m <= 1.0))
    sym = symmetrize(m)
    assert np.array_equal(sym, sym.T)
    assert np.all(sym <= m) and np.all(sym <= m.T)
    assert np.allclose(symmetrize(m, "mean"), (m + m.T) / 2)


def test_covisibility_fisheye_identical_views() -> None:
    wall = _plate((0.0, 0.0, 2.0), 4.0, spacing=0.05)
    n = len(wall)
    gaussians = Gaussians.from_colors(
        wall, np.tile([1.0, 0, 0, 0], (n, 1)), np.tile([0.03, 0.03, 0.003], (n, 1)), np.full(n, 0.95), np.full((n, 3), 0.5)
    )
    pose = np.eye(4)
    shifted = np.eye(4)
    shifted[0, 3] = 0.1
    lens = FisheyeLens(k1=-0.02)
    views = {"f": _camera(pose, lens), "f2": _camera(pose, lens), "pin": _camera(shifted)}
    scene = Scene("wall", gaussians, views)
    names, m = covisibility_matrix(scene, image_size=(80, 60), progress=False)
    assert m[0, 1] > 0.99 and m[1, 0] > 0.99
    assert m[2, 0] > 0.5  # a slightly shifted pinhole sees the same wall


def test_small_room_matrix_finite(small_room: Scene) -> None:
    names = list(small_room.views)[:6]
    got, m = covisibility_matrix(small_room, names, progress=False)
    assert got == names and np.isfinite(m).all()
    assert m[0, 1] > 0.3  # consecutive views of the trajectory overlap


def test_cache_round_trip_and_invalidation(room_views: Scene, tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    calls = []
    real = covisibility._compute_matrix  # the computation behind the cache

    def counting(*args, **kwargs):
        calls.append(1)
        return real(*args, **kwargs)

    monkeypatch.setattr(covisibility, "_compute_matrix", counting)
    names, m = load_or_compute_covisibility(room_views, tmp_path, progress=False)
    assert covisibility_cache_path(room_views, tmp_path).is_file() and len(calls) == 1
    names2, m2 = load_or_compute_covisibility(room_views, tmp_path, progress=False)
    assert len(calls) == 1 and names2 == names and np.array_equal(m2, m)

    moved_pose = room_views.views["a_turned"].cam_to_world.copy()
    moved_pose[:3, 3] += [0.05, 0.0, 0.0]
    moved_views = dict(room_views.views, a_turned=room_views.views["a_turned"].with_pose(moved_pose))
    moved = Scene(room_views.id, room_views.gaussians, moved_views, room_views.instances, room_views.up)
    load_or_compute_covisibility(moved, tmp_path, progress=False)
    assert len(calls) == 2
    load_or_compute_covisibility(room_views, tmp_path, rel_threshold=0.1, progress=False)
    assert len(calls) == 3

    covisibility_cache_path(room_views, tmp_path).write_bytes(b"not an npz")
    _, m3 = load_or_compute_covisibility(room_views, tmp_path, progress=False)
    assert len(calls) == 4 and np.array_equal(m3, m)


def test_torch_backend_agrees_with_compiled(small_room: Scene) -> None:
    """The readable torch path (what runs on CUDA) gives the same visibility and covisibility
    as the compiled CPU path, up to pixels on object edges."""
    names = list(small_room.views)[:3]
    cpu = compute_visibility(small_room, names, image_size=(80, 60), backend="cpu", progress=False)
    tch = compute_visibility(small_room, names, image_size=(80, 60), backend="torch", progress=False)
    for name in names:
        for iid, v in cpu[name].items():
            w = tch[name][iid]
            assert abs(v.visible_pixels - w.visible_pixels) <= max(0.05 * v.visible_pixels, 2 * 64)  # 64 full-res px per 80×60 px
            assert (v.visible_pixels == 0) == (w.visible_pixels == 0) or max(v.visible_pixels, w.visible_pixels) <= 2 * 64
    _, m_cpu = covisibility_matrix(small_room, names, image_size=(40, 30), backend="cpu", progress=False)
    _, m_tch = covisibility_matrix(small_room, names, image_size=(40, 30), backend="torch", progress=False)
    assert np.abs(m_cpu - m_tch).max() < 0.03


def test_visibility_cache_round_trip(small_room: Scene, tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    from spacedg.scene import visibility as vis_mod

    views = {name: small_room.views[name] for name in list(small_room.views)[:2]}
    scene = Scene(small_room.id, small_room.gaussians, views, small_room.instances, small_room.up)
    first = vis_mod.load_or_compute_visibility(scene, tmp_path, image_size=(40, 30), progress=False)
    monkeypatch.setattr(vis_mod, "compute_visibility", lambda *a, **k: pytest.fail("cache not used"))
    assert vis_mod.load_or_compute_visibility(scene, tmp_path, image_size=(40, 30), progress=False) == first
    moved = dict(views)
    first_view = next(iter(moved))
    pose = np.array(moved[first_view].cam_to_world, dtype=np.float64)
    pose[0, 3] += 0.1
    moved[first_view] = moved[first_view].with_pose(pose)
    with pytest.raises(pytest.fail.Exception, match="cache not used"):  # a moved view invalidates the entry
        vis_mod.load_or_compute_visibility(Scene(scene.id, scene.gaussians, moved, scene.instances, scene.up), tmp_path,
                                           image_size=(40, 30), progress=False)
