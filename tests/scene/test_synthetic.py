"""Procedural rooms: determinism, sizes, non-intersection, boxes, descriptions, cameras."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from spacedg.scene.synthetic import CaptureConfig, ExternalObject, RoomConfig, generate_room
from spacedg.errors import InvalidDataError
from spacedg.render.gaussians import Gaussians


@pytest.fixture(scope="module")
def default_rooms():
    """Two rooms with the default settings (the built-in scenes as users get them)."""
    return [generate_room(seed) for seed in (0, 1)]


def _all_rooms(default_rooms, small_room):
    return [*default_rooms, small_room]


def test_same_seed_same_bytes_other_seed_differs(small_room):
    again = generate_room(7, RoomConfig(gaussians=30_000, row_probability=0.0))  # as the small_room fixture
    for field in ("means", "quats", "scales", "opacities", "sh", "instance_ids"):
        assert getattr(again.gaussians, field).tobytes() == getattr(small_room.gaussians, field).tobytes()
    assert [i.to_dict() for i in again.instances] == [i.to_dict() for i in small_room.instances]
    assert all(np.array_equal(again.views[k].cam_to_world, small_room.views[k].cam_to_world) for k in small_room.views)
    other = generate_room(8, RoomConfig(gaussians=30_000, row_probability=0.0))
    assert other.gaussians.means.shape != small_room.gaussians.means.shape or not np.array_equal(
        other.gaussians.means, small_room.gaussians.means
    )


def test_budget_changes_sampling_not_layout():
    a = generate_room(3, RoomConfig(gaussians=20_000))
    b = generate_room(3, RoomConfig(gaussians=40_000))
    assert [i.label for i in a.instances] == [i.label for i in b.instances]
    assert [i.description for i in a.instances] == [i.description for i in b.instances]
    for ia, ib in zip(a.instances, b.instances):
        np.testing.assert_allclose(ia.box.center, ib.box.center, atol=0.05)


def test_default_rooms_have_the_promised_sizes(default_rooms):
    for scene in default_rooms:
        assert 100_000 <= len(scene.gaussians) <= 400_000
        assert 8 <= len(scene.instances) <= 25
        assert 40 <= len(scene.views) <= 150
        sizes = np.array([inst.box.extents.max() for inst in scene.instances])
        assert sizes.min() >= 0.08 and sizes.max() <= 2.5
        assert len({inst.label for inst in scene.instances}) >= 4
        target = scene.metadata["target_gaussians"]
        assert abs(len(scene.gaussians) - target) / target < 0.1


def test_labels_are_shared_somewhere(default_rooms, small_room):
    shared = [label for s in _all_rooms(default_rooms, small_room) for label, items in s.instances_by_label().items() if len(items) > 1]
    assert shared, "counting and ambiguity questions need rooms with repeated labels"


def test_objects_do_not_intersect(default_rooms, small_room):
    for scene in _all_rooms(default_rooms, small_room):
        for a, b in itertools.combinations(scene.instances, 2):
            assert not a.box.intersects(b.box, tol=1e-3), (scene.id, a.id, a.label, b.id, b.label)


def test_boxes_contain_their_gaussian_centres_and_are_tight(default_rooms, small_room):
    for scene in _all_rooms(default_rooms, small_room):
        g = scene.gaussians
        for inst in scene.instances:
            centres = g.means[g.instance_ids == inst.id]
            assert len(centres) > 0
            assert inst.box.contains(centres, tol=1e-5).all(), (scene.id, inst.id)
            local = np.abs(inst.box.to_local(centres))
            np.testing.assert_allclose(local.max(axis=0), inst.box.half_extents, atol=1e-4)  # tight on every axis


def test_objects_stand_on_the_floor_or_on_their_support(default_rooms):
    for scene in default_rooms:
        floor = (scene.gaussians.means[scene.gaussians.instance_ids == -1] @ scene.up).min()
        by_id = {inst.id: inst for inst in scene.instances}
        for inst in scene.instances:
            bottom, _ = inst.box.extent_along(scene.up)
            support = inst.attributes["support"]
            expected = floor if support is None else by_id[support].box.extent_along(scene.up)[1]
            assert bottom == pytest.approx(expected, abs=0.03), (inst.label, bottom, expected)


def test_descriptions_unique_within_label_except_intended_twins(default_rooms, small_room):
    twins = 0
    for scene in _all_rooms(default_rooms, small_room):
        for label, items in scene.instances_by_label().items():
            seen: dict[str, int] = {}
            for inst in items:
                assert label in inst.description
                assert not any(w in inst.description for w in ("left", "right", "near", "behind"))
                if inst.description in seen:
                    assert inst.attributes.get("twin_of") in {i.id for i in items if i.description == inst.description}
                    twins += 1
                seen[inst.description] = inst.id
    no_twins = generate_room(0, RoomConfig(gaussians=20_000, twin_probability=0.0))
    for label, items in no_twins.instances_by_label().items():
        assert len({i.description for i in items}) == len(items), label


def test_surfaces_are_textured(small_room):
    g = small_room.gaussians
    colors = g.base_colors()
    stds = [colors[g.instance_ids == inst.id].std(axis=0).mean() for inst in small_room.instances]
    assert np.median(stds) > 0.02  # not flat colour
    assert colors[g.instance_ids == -1].std(axis=0).mean() > 0.02
    assert g.sh_degree == 1 and np.abs(g.sh[:, 1:]).max() > 0  # view-dependent sheen present


def test_cameras_walk_a_plausible_handheld_path(default_rooms, small_room):
    for scene in _all_rooms(default_rooms, small_room):
        floor = (scene.gaussians.means @ scene.up).min()
        cams = list(scene.views.values())
        centres = np.array([c.center for c in cams])
        heights = centres @ scene.up - floor
        assert heights.min() > 1.35 and heights.max() < 1.8
        for c in cams:
            assert not any(inst.box.contains(c.center[None], tol=0.2)[0] for inst in scene.instances)
            hfov = np.degrees(2 * np.arctan(c.width / 2 / c.fx))
            assert 55 < hfov < 80
            tilt = np.degrees(np.arcsin(c.forward @ scene.up))
            assert -35 < tilt < 5
        steps = np.linalg.norm(np.diff(centres, axis=0), axis=1)
        turn = np.degrees(np.arccos(np.clip([a.forward @ b.forward for a, b in zip(cams, cams[1:])], -1, 1)))
        assert steps.max() < 0.45 and turn.max() < 25  # neighbours overlap strongly


def test_world_frames_vary_and_up_is_consistent():
    frames = set()
    for seed in range(6):
        scene = generate_room(seed, RoomConfig(gaussians=10_000, max_objects=10))
        frames.add(scene.metadata["world_frame"])
        h = scene.gaussians.means @ scene.up
        floor_ids = scene.gaussians.instance_ids == -1
        # the floor is the lowest surface along up and the cameras look slightly down
        assert h[floor_ids].min() == pytest.approx(h.min(), abs=1e-4)
    assert len(frames) >= 2


def test_explicit_frame_and_capture_settings():
    scene = generate_room(5, RoomConfig(gaussians=10_000, world_frame="y_down", capture=CaptureConfig(320, 240, 40, 40)))
    np.testing.assert_allclose(scene.up, [0, -1, 0], atol=1e-12)
    assert len(scene.views) == 40 and {(c.width, c.height) for c in scene.views.values()} == {(320, 240)}


def _blob(n: int = 2000, seed: int = 0) -> Gaussians:
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(n, 3)) * [1.0, 2.0, 0.5]  # long axis along y: "up" = +y after up_axis="+y"
    return Gaussians.from_colors(pts, np.tile([1.0, 0, 0, 0], (n, 1)), np.full((n, 3), 0.02), np.full(n, 0.9),
                                 np.tile([0.1, 0.2, 0.8], (n, 1)))


def test_external_object_is_placed_as_an_instance():
    ext = ExternalObject(_blob(), "statue", None, up_axis="+y", size_m=0.6, placement="floor")
    scene = generate_room(11, RoomConfig(gaussians=15_000, external=(ext,)))
    statue = [i for i in scene.instances if i.label == "statue"]
    assert len(statue) == 1
    inst = statue[0]
    assert inst.description == "blue statue" and inst.attributes["external"]
    assert inst.box.extents.max() == pytest.approx(0.6, rel=1e-4)
    lo, hi = inst.box.extent_along(scene.up)
    assert hi - lo == pytest.approx(0.6, rel=1e-4)  # the object's +y became the room's up
    assert (scene.gaussians.instance_ids == inst.id).sum() == 2000
    for other in scene.instances:
        if other.id != inst.id:
            assert not inst.box.intersects(other.box, tol=1e-3)


def test_real_splat_object_in_a_room(shared_splats):
    ext = ExternalObject.from_splat(shared_splats / "teapot" / "teapot_10k.splat", size_m=0.3)
    scene = generate_room(12, RoomConfig(gaussians=15_000, external=(ext,)))
    teapot = [i for i in scene.instances if i.label == "teapot"]
    assert len(teapot) == 1 and teapot[0].attributes["license"]
    assert teapot[0].attributes["support"] is not None  # stands on a top


def test_invalid_configs_are_rejected():
    with pytest.raises(InvalidDataError, match="gaussians must be in"):
        RoomConfig(gaussians=10)
    with pytest.raises(InvalidDataError, match="world_frame"):
        RoomConfig(world_frame="x_up")
    with pytest.raises(InvalidDataError, match="size_m must be in"):
        ExternalObject(_blob(), "statue", size_m=5.0)
    with pytest.raises(InvalidDataError, match="up_axis must be one of"):
        ExternalObject(_blob(), "statue", up_axis="up")


def test_wall_rows_stand_identical_objects_side_by_side():
    """``row_probability=1``: a row of 4–6 chairs or boxes of one model (one shape and size, each its own colour) along a wall (for counting),
    one model, evenly spaced on a line, never intersecting anything; 0 draws no row."""
    rows_seen = 0
    for seed in range(6):
        scene = generate_room(seed, RoomConfig(gaussians=10_000, row_probability=1.0))
        rows: dict[int, list] = {}
        for inst in scene.instances:
            if "row" in inst.attributes:
                rows.setdefault(int(inst.attributes["row"]), []).append(inst)
        for first, members in rows.items():
            rows_seen += 1
            assert 4 <= len(members) <= 6 and members[0].id == first
            assert len({m.label for m in members}) == 1 and members[0].label in ("chair", "box")
            ext = np.array([m.box.extents for m in members])
            np.testing.assert_allclose(ext, np.broadcast_to(ext[0], ext.shape), atol=0.02)  # one model (boxes are fitted to its surfels)
            centres = np.array([m.box.center for m in members])
            steps = np.diff(centres, axis=0)
            np.testing.assert_allclose(steps, np.broadcast_to(steps[0], steps.shape), atol=0.03)  # evenly spaced on a line
            assert np.abs(steps[0] @ scene.up) < 1e-6 + 0.02  # on the floor, not stacked
        for a, b in itertools.combinations(scene.instances, 2):
            if a.attributes.get("support") in (b.id,) or b.attributes.get("support") in (a.id,):
                continue
            assert not a.box.intersects(b.box, tol=1e-3), (seed, a.id, b.id)
    assert rows_seen >= 4
    for seed in range(3):
        assert not any("row" in i.attributes for i in generate_room(seed, RoomConfig(gaussians=10_000, row_probability=0.0)).instances)
    with pytest.raises(InvalidDataError, match="row_probability must be in"):
        RoomConfig(row_probability=1.5)
