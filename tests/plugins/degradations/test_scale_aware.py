"""Scale-aware presets: metre ranges follow the sample's scene depth; provenance keeps the metres."""

from __future__ import annotations

import numpy as np
import pytest

from spacedg.data.chain import Chain
from spacedg.data.pipeline import degrade, degrade_image, sample_scene_depth, view_depth
from spacedg.errors import PluginError
from spacedg.plugins import DegradationSpec, ParamRange, ParamSpec, get_degradation
from spacedg.plugins.specs import REFERENCE_DEPTH_M
from spacedg.plugins.degradations.haze import SCALED_DEPTH_REF_M
from spacedg.render import render


def test_bench_is_the_paper_table_at_the_reference_depth() -> None:
    for name, param, paper in [("defocus", "depth", (1.0, 8.0)), ("motion_blur", "trans", (0.2, 0.35))]:
        spec = get_degradation(name)
        assert spec.presets["bench"][param].per_depth and spec.presets["bench"][param].to_list() == list(paper)
        for seed in range(20):
            at_ref = spec.sample_params("bench", np.random.default_rng(seed), REFERENCE_DEPTH_M)
            plain = spec.sample_params("bench", np.random.default_rng(seed))
            assert at_ref == plain and paper[0] <= at_ref[param] <= paper[1]
            small = spec.sample_params("bench", np.random.default_rng(seed), REFERENCE_DEPTH_M / 5)
            assert small[param] == pytest.approx(plain[param] / 5)
            assert {k: v for k, v in small.items() if k != param} == {k: v for k, v in plain.items() if k != param}
    haze = get_degradation("haze")
    assert haze.presets["bench"]["density"].to_list() == [3.5, 6.0] and not haze.presets["fog_20m"]["depth_ref"].per_depth
    assert haze.sample_params("fog_20m", np.random.default_rng(0), 0.3)["depth_ref"] == 20.0  # physical presets never scale


def test_only_metres_may_scale() -> None:
    with pytest.raises(PluginError, match="only a parameter in metres"):
        DegradationSpec(
            name="bad_scale", category="digital", stage="display", params=(ParamSpec("q", "1", "quality", low=0, high=100),),
            presets={p: {"q": ParamRange(1, 2, per_depth=True)} for p in ("bench", "1", "2", "3", "4", "5")},
            apply=lambda image, params, rng: image,
        )


def test_scene_depth_resolves_records_and_reproduces(small_room) -> None:
    scene = small_room
    view = next(iter(scene.views))
    depth = sample_scene_depth(scene, [view])
    # the Gaussian-based depth agrees with the rendered median depth within a few per cent
    frame = render(scene.gaussians, scene.camera(view).resized(80, 60), outputs=("depth", "alpha"), backend="cpu")
    rendered = float(np.median(frame.depth[(frame.alpha > 0.5) & np.isfinite(frame.depth)]))
    assert depth == view_depth(scene, scene.camera(view)) and abs(depth / rendered - 1) < 0.1
    chain = Chain.parse("defocus+motion_blur+haze+jpeg_compression")
    assert chain.scales_with_depth() and not Chain.parse("jpeg_compression+low_light").scales_with_depth()
    out = degrade(scene, [view], "defocus+haze", seed=3)
    by_name = {p["name"]: p for p in out.degradations}
    assert by_name["defocus"]["scene_depth_m"] == pytest.approx(depth) and by_name["haze"]["scene_depth_m"] == pytest.approx(depth)
    reference = {p["name"]: p for p in chain.provenance(3)}
    assert by_name["defocus"]["params"]["depth"] == pytest.approx(reference["defocus"]["params"]["depth"] * depth / REFERENCE_DEPTH_M)
    # the recorded absolute metres reproduce the bytes without measuring the scene
    explicit = [{"name": p["name"], "params": p["params"]} for p in out.degradations]
    again = degrade(scene, [view], explicit, seed=3)
    assert np.array_equal(again.images, out.images) and all("scene_depth_m" not in p for p in again.degradations)
    # a photo with a depth map: its median depth
    photo = out.images[0]
    _, prov = degrade_image(photo, "haze", seed=1, depth=np.full(photo.shape[:2], 0.5, np.float32))
    assert prov[0]["scene_depth_m"] == pytest.approx(0.5) and prov[0]["params"]["depth_ref"] == pytest.approx(SCALED_DEPTH_REF_M * 0.5 / REFERENCE_DEPTH_M)


def _depth_by_definition(means: np.ndarray, opacities: np.ndarray, camera) -> float | None:  # type: ignore[no-untyped-def]
    """view_depth's docstring written out point by point: nearest opaque centre per grid cell, median over cells."""
    from spacedg.data.pipeline import DEPTH_GRID, DEPTH_MIN_OPACITY

    pose = np.asarray(camera.cam_to_world, dtype=np.float64)
    cols, rows = DEPTH_GRID
    nearest: dict[int, float] = {}
    for p, o in zip(np.asarray(means, np.float64), opacities):
        x, y, z = (p - pose[:3, 3]) @ pose[:3, :3]
        if o < DEPTH_MIN_OPACITY or not z > 1e-3:
            continue
        u, v = camera.fx * x / z + camera.cx, camera.fy * y / z + camera.cy
        if 0 <= u < camera.width and 0 <= v < camera.height:
            cell = int(v * rows // camera.height) * cols + int(u * cols // camera.width)
            nearest[cell] = min(nearest.get(cell, np.inf), z)
    return float(np.median(list(nearest.values()))) if nearest else None


def test_view_depth_is_its_definition_whatever_the_opacities(small_room) -> None:
    """Partly opaque Gaussians, a camera turned away from the room (nothing in front of it) and two
    Gaussian sets sharing one ``means`` array (the per-set cache of opaque centres must not mix them)."""
    from types import SimpleNamespace

    from spacedg.render.gaussians import Gaussians

    full = small_room.gaussians
    g = Gaussians(*(np.ascontiguousarray(a[::4]) for a in (full.means, full.quats, full.scales, full.opacities, full.sh)))
    rng = np.random.default_rng(7)
    camera = small_room.camera(next(iter(small_room.views))).resized(64, 48)
    away = camera.__class__(**{**camera.__dict__, "cam_to_world": camera.cam_to_world @ np.diag([1.0, -1.0, -1.0, 1.0])})
    first = Gaussians(g.means, g.quats, g.scales, rng.uniform(0, 1, len(g)).astype(g.opacities.dtype), g.sh)
    second = Gaussians(g.means, g.quats, g.scales, np.where(first.opacities >= 0.5, 0.1, 0.9).astype(g.opacities.dtype), g.sh)
    seen = []
    for k, gaussians in enumerate((first, second, first)):
        scene = SimpleNamespace(id=f"opacity-{k}", gaussians=gaussians)
        for cam in (camera, away):
            expected = _depth_by_definition(gaussians.means, gaussians.opacities, cam)
            got = view_depth(scene, cam)  # type: ignore[arg-type]
            assert got == expected or (got is not None and expected is not None and got == pytest.approx(expected, rel=1e-12))
            seen.append(got)
    assert seen[0] is not None and seen[0] != seen[2] and seen[4] == seen[0]
    nothing = SimpleNamespace(id="transparent", gaussians=Gaussians(g.means, g.quats, g.scales, np.full(len(g), 0.2, g.opacities.dtype), g.sh))
    assert view_depth(nothing, camera) is None  # type: ignore[arg-type]


def test_the_opaque_centres_kept_for_view_depth_stay_within_their_budget(small_room, monkeypatch) -> None:
    """At most _OPAQUE_MEANS_SIZE sets and _OPAQUE_MEANS_BYTES bytes of centres; a set over the budget is used but
    not kept, and an entry holds its arrays weakly (a set the caller dropped leaves nothing alive)."""
    import gc
    from types import SimpleNamespace

    from spacedg.data import pipeline
    from spacedg.render.gaussians import Gaussians

    g = small_room.gaussians
    camera = small_room.camera(next(iter(small_room.views))).resized(64, 48)
    monkeypatch.setattr(pipeline, "_OPAQUE_MEANS", None)  # made afresh on first use, with the module's budget
    sets = [Gaussians(g.means[k::5].copy(), g.quats[k::5], g.scales[k::5], g.opacities[k::5].copy(), g.sh[k::5]) for k in range(5)]
    for k, gaussians in enumerate(sets):
        view_depth(SimpleNamespace(id=f"budget-{k}", gaussians=gaussians), camera)  # type: ignore[arg-type]
    assert len(pipeline._OPAQUE_MEANS) == pipeline._OPAQUE_MEANS_SIZE  # the oldest set left
    monkeypatch.setattr(pipeline, "_OPAQUE_MEANS_BYTES", sets[0].means.shape[0] * 24 - 1)  # one set's centres, less a byte
    monkeypatch.setattr(pipeline, "_OPAQUE_MEANS", None)
    expected = _depth_by_definition(sets[0].means, sets[0].opacities, camera)
    assert view_depth(SimpleNamespace(id="over-budget", gaussians=sets[0]), camera) == pytest.approx(expected, rel=1e-12)  # type: ignore[arg-type]
    assert len(pipeline._OPAQUE_MEANS) == 0
    monkeypatch.setattr(pipeline, "_OPAQUE_MEANS_BYTES", 256 << 20)
    monkeypatch.setattr(pipeline, "_OPAQUE_MEANS", None)
    view_depth(SimpleNamespace(id="weak", gaussians=sets[1]), camera)  # type: ignore[arg-type]
    (refs,) = [(entry[0], entry[1]) for entry in pipeline._OPAQUE_MEANS.values()]
    del sets, gaussians  # nothing else holds the sets
    gc.collect()
    assert refs[0]() is None and refs[1]() is None


def test_the_compiled_cells_are_the_numpy_forms_bytes() -> None:
    """view_depth's compiled pass (nearest centre per cell) against the numpy form it replaced, byte for byte:
    random camera-frame points, points behind and at the near limit, exactly on the image's edges and cell
    borders, non-finite coordinates, odd image sizes."""
    from spacedg.data.pipeline import DEPTH_GRID
    from spacedg.data.view_depth_cpu import nearest_per_cell

    def numpy_form(pc, fx, fy, cx, cy, width, height):  # type: ignore[no-untyped-def]
        z = pc[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u = fx * pc[:, 0] / z + cx
            v = fy * pc[:, 1] / z + cy
        inside = (z > 1e-3) & (u >= 0) & (u < width) & (v >= 0) & (v < height)
        cols, rows = DEPTH_GRID
        cell = (v[inside] * rows // height).astype(np.int64) * cols + (u[inside] * cols // width).astype(np.int64)
        nearest = np.full(cols * rows, np.inf)
        np.minimum.at(nearest, cell, z[inside])
        return nearest

    rng = np.random.default_rng(4848)
    for width, height, fx, fy in ((640, 480, 500.0, 500.0), (97, 61, 73.3, 80.1), (1752, 1168, 1500.0, 1499.5)):
        cx, cy = width / 2 + 0.25, height / 2 - 0.5
        z = rng.uniform(-1.0, 8.0, 20000)
        pc = np.stack([rng.uniform(-1.2, 1.2, z.size) * np.abs(z) * width / fx / 2, rng.uniform(-1.2, 1.2, z.size) * np.abs(z) * height / fy / 2, z], 1)
        edges = np.array([0.0, width, width - 1e-9, width / DEPTH_GRID[0] * 3, height, height / DEPTH_GRID[1] * 5])
        for k, edge in enumerate(edges):  # points landing exactly on an edge or a cell border
            pc[k, :] = ((edge - cx) * 2.0 / fx, (edge * height / width - cy) * 2.0 / fy, 2.0)
        pc[10:14] = 0.0  # on the axis: in the image wherever z is taken in front
        pc[10:14, 2] = (1e-3, 0.0, -0.0, np.nextafter(1e-3, 1.0))
        pc[14:18] = ((np.nan, 0.0, 2.0), (np.inf, 0.0, 2.0), (0.0, 0.0, np.inf), (0.0, 0.0, np.nan))
        got = nearest_per_cell(pc, fx, fy, cx, cy, width, height, *DEPTH_GRID)
        want = numpy_form(pc, fx, fy, cx, cy, width, height)
        assert np.array_equal(got.view(np.uint64), want.view(np.uint64)) and np.isfinite(got).sum() > 100
